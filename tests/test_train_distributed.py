"""Multi-process training: 2 CPU processes under torchrun (gloo) keep equal replicas."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap

import numpy as np
import torch

from alcn_cv.data import phos
from alcn_cv.train import distributed


def test_single_process_helpers():
    assert (distributed.rank(), distributed.world_size(), distributed.is_main()) == (0, 1, True)
    assert distributed.init("cpu") is False


def test_replicas_are_compared_on_their_device(monkeypatch):
    """nccl reduces CUDA tensors only: the parameters are compared where they are (they were copied to the CPU)."""
    seen = []
    monkeypatch.setattr(distributed, "world_size", lambda: 2)
    monkeypatch.setattr(distributed.dist, "all_reduce", lambda tensor, op: seen.append(tensor.device))
    monkeypatch.setattr(distributed.torch, "equal", lambda a, b: a.device == b.device)  # meta tensors hold no values
    model = torch.nn.Linear(3, 2, device="meta")  # a device of its own, as a GPU's would be
    assert distributed.replicas_equal(model) is True
    assert seen == [torch.device("meta")] * 2


def test_two_cpu_processes_hold_equal_weights(tmp_path):
    train_dir = phos.generate(tmp_path / "train", 64, 0, n_objects=2, lighting="ambient,bright", progress=False)
    val_dir = phos.generate(tmp_path / "val", 16, 1, n_objects=2, lighting="side", progress=False)
    script = tmp_path / "run.py"
    script.write_text(
        textwrap.dedent(f"""
        import sys
        import numpy as np
        import torch
        from alcn_cv.train import distributed
        from alcn_cv.train.trainer import train

        cfg = {{"data": {{"path": {str(train_dir)!r}, "val_path": {str(val_dir)!r}}},
               "model": {{"channels": [4, 8], "hidden": 16, "detector_channels": [4, 8], "detector_hidden": 16}},
               "optim": {{"epochs": 1, "batch_size": 8, "warmup_steps": 0}},
               "fewshot": {{"enabled": False}}, "run": {{"threads": 1}}}}
        result = train(cfg, {str(tmp_path / "run")!r}, progress=False)
        assert distributed.world_size() == 2, distributed.world_size()
        flat = torch.cat([p.detach().flatten() for p in result.model.parameters()]).numpy()
        np.save({str(tmp_path)!r} + f"/rank{{distributed.rank()}}.npy", flat)
        distributed.shutdown()
    """)
    )
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2", str(script)]
    # The launch itself (rendezvous on a free local port, under a loaded CI machine) failed once
    # in about a dozen runs without a trace of our code in it: relaunch once, into an empty run
    # folder (a launch that failed after training left its run there, which the relaunch's training
    # refused as an earlier run). What is tested, equal replicas after training, is asserted on the
    # run that completes.
    failures = []
    for _ in range(2):
        shutil.rmtree(tmp_path / "run", ignore_errors=True)
        proc = subprocess.run(
            cmd, capture_output=True, text=True, timeout=300, env={**os.environ, "OMP_NUM_THREADS": "1"}
        )
        if proc.returncode == 0 or "alcn_cv" in proc.stderr:
            break
        failures.append(proc.stderr[-1500:])
    assert proc.returncode == 0, "\n---\n".join([*failures, proc.stderr[-3000:]])
    a, b = np.load(tmp_path / "rank0.npy"), np.load(tmp_path / "rank1.npy")
    np.testing.assert_array_equal(a, b)
    # Rank 0 wrote the run's files.
    assert (tmp_path / "run" / "checkpoint.pt").is_file() and (tmp_path / "run" / "alcn_normalizer.npz").is_file()
