"""Multi-process training with :mod:`torch.distributed` (DistributedDataParallel).

Run ``alcn train`` under ``torchrun`` to train on several processes::

    torchrun --nproc_per_node 2 -m alcn_cv.cli train --conf paper-full --out out/paper

Each process reads its rank from the environment that torchrun sets (``RANK``, ``WORLD_SIZE``,
``LOCAL_RANK``, ``MASTER_ADDR``, ``MASTER_PORT``); the process group uses ``gloo`` on the CPU and
``nccl`` on CUDA. Every process trains on its own shard of each epoch's order
(``order[rank::world_size]``) with ``optim.batch_size`` windows per step, so the effective batch
is ``world_size * batch_size``; gradients are averaged by DDP so the replicas stay equal. Only
rank 0 writes the checkpoint, the log, the curves and the weights. Without torchrun the helpers
below describe a single process and :func:`wrap` returns the model unchanged.
"""

from __future__ import annotations

import logging
import os

import torch
import torch.distributed as dist
from torch import nn

__all__ = ["init", "is_main", "local_rank", "rank", "replicas_equal", "shutdown", "world_size", "wrap"]

logger = logging.getLogger(__name__)


def _launched() -> bool:
    return int(os.environ.get("WORLD_SIZE", "1")) > 1


def init(device: str = "cpu") -> bool:
    """Join the process group torchrun describes (gloo for ``"cpu"``, nccl for ``"cuda"``).

    Returns:
        True when this is one of several processes (and the group is now initialised).
    """
    if not _launched():
        return False
    if not dist.is_initialized():
        backend = "nccl" if device.startswith("cuda") else "gloo"
        if backend == "nccl":
            torch.cuda.set_device(local_rank())
        dist.init_process_group(backend)
        logger.info("process %d of %d joined the %s group", rank(), world_size(), backend)
    return True


def shutdown() -> None:
    """Leave the process group, if one was joined."""
    if dist.is_available() and dist.is_initialized():
        dist.destroy_process_group()


def rank() -> int:
    return dist.get_rank() if dist.is_available() and dist.is_initialized() else 0


def world_size() -> int:
    return dist.get_world_size() if dist.is_available() and dist.is_initialized() else 1


def local_rank() -> int:
    return int(os.environ.get("LOCAL_RANK", "0"))


def is_main() -> bool:
    """True on rank 0 (and in a single process): the process that writes files."""
    return rank() == 0


def wrap(model: nn.Module, device: torch.device) -> nn.Module:
    """``DistributedDataParallel(model)`` in a multi-process run, else ``model`` itself."""
    if world_size() == 1:
        return model
    ids = [device.index] if device.type == "cuda" else None
    return nn.parallel.DistributedDataParallel(model, device_ids=ids)


@torch.no_grad()
def replicas_equal(model: nn.Module) -> bool:
    """True when every process holds the same parameters (compared with an all-reduce of max and min).

    The parameters stay on their device: nccl (``"cuda"``) reduces CUDA tensors only, gloo (``"cpu"``) CPU ones."""
    flat = torch.cat([p.detach().flatten().float() for p in model.parameters()])
    if world_size() == 1:
        return True
    hi, lo = flat.clone(), flat.clone()
    dist.all_reduce(hi, op=dist.ReduceOp.MAX)
    dist.all_reduce(lo, op=dist.ReduceOp.MIN)
    return bool(torch.equal(hi, lo))
