"""The windows of a training run: the training set and the held-out-lighting validation set.

Both come from folders written by ``alcn data phos`` (``data.path``, ``data.val_path``) or are
rendered by :func:`alcn_cv.data.phos.render_windows` in parts of 4096 windows, part ``p``
seeded by ``[seed, p]`` so the windows do not depend on the number of ``run.workers``.
Rendered windows are cached in the run folder under a key of the settings that make them.
With ``optim.objective = "meta"`` a fraction ``data.anchor_fraction`` of the training windows
is rendered under the anchor lighting (:mod:`alcn_cv.train.trainer`).
"""

from __future__ import annotations

import hashlib
import json
import logging
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from alcn_cv.data.phos import PhosBatch, load, render_windows
from alcn_cv.errors import InputError
from alcn_cv.io import atomic_write
from alcn_cv.train import distributed
from alcn_cv.train.config import TrainConfig

__all__ = ["check_windows", "load_windows"]

logger = logging.getLogger(__name__)

_PART = 4096  # windows rendered per part (parts are independent of the worker count)


def _render_part(args: tuple) -> PhosBatch:
    n, seed, kwargs = args
    return render_windows(n, seed, **kwargs)


def _render(n: int, seed: int, lighting: list[str], cfg: TrainConfig, desc: str, progress: bool) -> PhosBatch:
    """Render ``n`` windows in parts of 4096 (part ``p`` seeded by ``[seed, p]``), on ``run.workers`` processes."""
    kwargs = {
        "n_objects": cfg.data.n_objects,
        "object_seed": cfg.data.object_seed,
        "lighting": lighting,
        "background_fraction": cfg.data.background_fraction,
    }
    jobs = [
        (min(_PART, n - s), int(np.random.SeedSequence([seed, p]).generate_state(1)[0]), kwargs)
        for p, s in enumerate(range(0, n, _PART))
    ]
    if cfg.run.workers > 0 and len(jobs) > 1:
        import multiprocessing

        with multiprocessing.get_context("spawn").Pool(cfg.run.workers) as pool:
            parts = list(tqdm(pool.imap(_render_part, jobs), total=len(jobs), desc=desc, disable=not progress))
    else:
        parts = [_render_part(j) for j in tqdm(jobs, desc=desc, disable=not progress)]
    first = parts[0]
    cat = {k: np.concatenate([getattr(p, k) for p in parts]) for k in PhosBatch.ARRAYS}
    return PhosBatch(**cat, n_objects=first.n_objects, object_seed=first.object_seed, seed=seed)


def _data_key(cfg: TrainConfig) -> str:
    """The key of the cached windows: the settings that render them and, when a set is read from a folder (the
    cache holds it too), the folders (so a run that renders never takes another's read windows for its own)."""
    d = cfg.data
    anchor = [d.anchor_lighting, d.anchor_fraction] if cfg.optim.objective == "meta" else None
    settings = [
        d.n_train,
        d.n_val,
        cfg.data_seed,
        d.n_objects,
        d.object_seed,
        d.train_lighting,
        d.val_lighting,
        d.background_fraction,
        _PART,
        anchor,
    ]
    if d.path or d.val_path:  # appended only then: the key of rendered windows stays that of earlier caches
        settings.append(
            [str(Path(d.path).resolve()) if d.path else "", str(Path(d.val_path).resolve()) if d.val_path else ""]
        )
    return hashlib.sha256(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:16]


def load_windows(cfg: TrainConfig, out_dir: Path, progress: bool) -> tuple[PhosBatch, PhosBatch]:
    """Training and held-out-lighting validation windows, from folders or rendered (cached in the run folder)."""
    train_set = load(cfg.data.path) if cfg.data.path else None
    val_set = load(cfg.data.val_path) if cfg.data.val_path else None
    cache = out_dir / f"windows-{_data_key(cfg)}.npz"
    if (train_set is None or val_set is None) and cache.is_file():
        with np.load(cache) as z:
            cached = {k: z[k] for k in z.files}
        meta = json.loads(str(cached.pop("meta")))
        sets = [
            PhosBatch(
                *[cached[f"{name}_{k}"] for k in PhosBatch.ARRAYS],
                n_objects=meta["n_objects"],
                object_seed=meta["object_seed"],
                seed=meta[f"{name}_seed"],
            )
            for name in ("train", "val")
        ]
        logger.info("windows read from the cache %s", cache.name)
        return train_set if train_set is not None else sets[0], val_set if val_set is not None else sets[1]
    if train_set is None and cfg.optim.objective == "meta":
        n_anchor = round(cfg.data.n_train * cfg.data.anchor_fraction)
        others = [f for f in cfg.data.train_lighting if f != cfg.data.anchor_lighting]
        parts = [
            _render(n_anchor, cfg.data_seed, [cfg.data.anchor_lighting], cfg, "anchor windows", progress),
            _render(cfg.data.n_train - n_anchor, cfg.data_seed + 7, others, cfg, "training windows", progress),
        ]
        train_set = PhosBatch(
            *[np.concatenate([getattr(p, k) for p in parts]) for k in PhosBatch.ARRAYS],
            n_objects=parts[0].n_objects,
            object_seed=parts[0].object_seed,
            seed=cfg.data_seed,
        )
    if train_set is None:
        train_set = _render(cfg.data.n_train, cfg.data_seed, cfg.data.train_lighting, cfg, "training windows", progress)
    if val_set is None:
        val_set = _render(
            cfg.data.n_val, cfg.data_seed + 1_000_003, cfg.data.val_lighting, cfg, "validation windows", progress
        )
    if not (cfg.data.path and cfg.data.val_path) and distributed.is_main():
        arrays = {
            f"{name}_{k}": getattr(s, k)
            for name, s in (("train", train_set), ("val", val_set))
            for k in PhosBatch.ARRAYS
        }
        meta = {
            "n_objects": train_set.n_objects,
            "object_seed": train_set.object_seed,
            "train_seed": train_set.seed,
            "val_seed": val_set.seed,
        }
        atomic_write(cache, lambda f: np.savez(f, meta=np.array(json.dumps(meta)), **arrays))
    return train_set, val_set


def check_windows(train_set: PhosBatch, val_set: PhosBatch) -> int:
    """The number of classes (background + objects) of two compatible sets.

    Raises:
        InputError: an empty set, different object catalogues, or validation windows under a
            training lighting (validation must hold lightings out).
    """
    if len(train_set) == 0 or len(val_set) == 0:
        raise InputError("training and validation windows must not be empty")
    if train_set.n_objects != val_set.n_objects:
        raise InputError(
            f"training windows have {train_set.n_objects} objects, validation {val_set.n_objects}: render both with "
            f"one catalogue (data.n_objects, or `alcn data phos --objects`), or give data.val_path of the same"
        )
    shared = set(np.unique(train_set.light_ids)) & set(np.unique(val_set.light_ids))
    if shared:
        names = sorted(train_set.light_families[i] for i in shared)
        raise InputError(
            f"validation windows share the training lightings {names}; hold some lightings out (data.train_lighting "
            "and data.val_lighting, or `alcn data phos --lighting` for each of data.path and data.val_path)"
        )
    return train_set.n_objects + 1
