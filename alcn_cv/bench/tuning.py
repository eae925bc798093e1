"""Parameter search for DoG, SLCN and DLCN on the training windows (Rad et al. 2017, Sec. 4.3).

The paper tunes the parameters of these baselines on the training set. Training images are
taken under one lighting, where every setting separates the classes perfectly, so the search
scores each setting by how well the classes stay apart under *synthetic* changes of light
applied to the training windows (nothing from the test set is used):

1. ``relight_windows`` draws, for every window, a gain (log-uniform 0.15-3), a gamma (0.5-2), a linear
   brightness gradient across the window (up to a factor 3 end to end), an offset and noise.
2. Each setting normalizes the original windows (the references) and the relit ones (the
   queries); the 32x32 centres are standardized per window.
3. The score is the leave-one-out 1-nearest-neighbour accuracy of the queries against the
   references (cosine similarity): a query's own unrelit window is excluded, so the score
   rewards settings under which *other* windows of the same class stay closest.

The detection benchmark also asks for localization (IoU 0.8 with 36-pixel boxes leaves about
4 pixels), so every object window also gives a *shifted* copy, 6 to 10 pixels off centre,
labelled background (:func:`shifted_negatives`), meant to penalize settings that keep only
coarse structure (large sigmas).

It is quick (no network is trained) and deterministic for a seed. It is only a proxy of detection, so the
benchmark runs it only on request (``alcn bench detect --tune``).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from typing import Any

import numpy as np

from alcn_cv.bench.detect_settings import CROP
from alcn_cv.enhance.registry import create
from alcn_cv.errors import InputError
from alcn_cv.filters.standardize import standardize_windows

__all__ = ["BENCH_STANDARDIZE_EPS", "GRIDS", "centre_windows", "relight_windows", "tune", "tune_all"]

logger = logging.getLogger(__name__)

#: The searched settings of each method. Kernels stay within the context that the benchmark's
#: 64x64 training windows give around the detector's 32x32 input (16 pixels; a Gaussian reaches
#: 3 sigma): a larger kernel sees reflected window borders at training time and the real
#: surroundings at test time, which the window-level score cannot see but the detector pays for.
GRIDS: dict[str, list[dict[str, float]]] = {
    "dog": [{"sigma1": s1, "sigma2": s2} for s1 in (0.5, 1.0, 1.5, 2.0) for s2 in (1.5, 2.0, 3.0, 4.0, 5.0) if s2 > s1],
    "slcn": [{"sigma": s} for s in (1.0, 1.5, 2.0, 3.0, 4.0, 5.0)],
    "dlcn": [{"sigma": s} for s in (1.0, 1.5, 2.0, 3.0, 4.0, 5.0)],
}

#: Added to the standard deviation by the per-window standardizations of the benchmark (the features here, the
#: detector's ``standardize`` and ``local`` input policies): smaller than training's
#: :data:`~alcn_cv.filters.standardize.STANDARDIZE_EPS`, because the benchmark standardizes the raw output of every
#: method, some of them (a DoG of [0, 1] intensities) of a far smaller amplitude than ALCN's.
BENCH_STANDARDIZE_EPS = 1e-6

#: The range of the larger offset (pixels) of a :func:`shifted_negatives` window.
SHIFT = (6, 10)


def centre_windows(windows: np.ndarray, size: int = CROP) -> np.ndarray:
    """The ``size x size`` centres of ``(n, S, S)`` windows."""
    s = windows.shape[-1]
    o = (s - size) // 2
    return windows[:, o : o + size, o : o + size]


def relight_windows(windows: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Synthetic changes of light of float windows in [0, 1] (see the module docstring).

    Args:
        windows: ``(n, S, S)`` float32 in [0, 1].
        rng: random generator.

    Returns:
        ``(n, S, S)`` float32 in [0, 1], quantized to 8 bits like a camera image.
    """
    n, h, w = windows.shape
    gain = np.exp(rng.uniform(np.log(0.15), np.log(3.0), n))[:, None, None]
    gamma = np.exp(rng.uniform(np.log(0.5), np.log(2.0), n))[:, None, None]
    angle = rng.uniform(0, 2 * np.pi, n)
    strength = np.log(rng.uniform(1.0, 3.0, n))
    y, x = np.mgrid[0:h, 0:w]
    t = ((x - w / 2)[None] * np.cos(angle)[:, None, None] + (y - h / 2)[None] * np.sin(angle)[:, None, None]) / max(
        h, w
    )
    gradient = np.exp(strength[:, None, None] * t)
    offset = rng.uniform(-0.03, 0.03, n)[:, None, None]
    out = gain * np.power(np.clip(windows, 0, 1), gamma) * gradient + offset
    out += rng.normal(0, 0.01, out.shape)
    return (np.rint(np.clip(out, 0, 1) * 255) / 255).astype(np.float32)


def shifted_negatives(
    windows: np.ndarray, labels: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Object windows moved off centre, as background: the localization negatives of the search. The larger of
    the x and y offsets is drawn in :data:`SHIFT` (pixels).

    Args:
        windows: ``(n, S, S)`` windows (``S >= 32 + 2 * SHIFT[1]`` keeps the shifted 32x32
            centre inside the window; borders wrap otherwise).
        labels: ``(n,)``, 0 = background.
        rng: random generator.

    Returns:
        ``(windows, labels)`` with every object window appended once, shifted, labelled 0.
    """
    objects = windows[labels > 0]
    moved = np.empty_like(objects)
    for k, w in enumerate(objects):
        size = int(rng.integers(SHIFT[0], SHIFT[1] + 1))
        big, small = size * int(rng.choice([-1, 1])), int(rng.integers(-size, size + 1))
        dy, dx = (big, small) if rng.random() < 0.5 else (small, big)
        moved[k] = np.roll(w, (dy, dx), axis=(0, 1))
    return np.concatenate([windows, moved]), np.concatenate([labels, np.zeros(len(moved), labels.dtype)])


def _score(
    method: str, params: dict[str, Any], references: np.ndarray, queries: np.ndarray, labels: np.ndarray
) -> float:
    norm = create(method, **params)

    def features(windows: np.ndarray) -> np.ndarray:
        out = norm.normalize_windows(windows)
        f = standardize_windows(centre_windows(out), eps=BENCH_STANDARDIZE_EPS).reshape(len(out), -1)
        return f / (np.linalg.norm(f, axis=1, keepdims=True) + 1e-12)

    sim = features(queries) @ features(references).T
    np.fill_diagonal(sim, -np.inf)  # never match a window with its own unrelit self
    return float(np.mean(labels[np.argmax(sim, axis=1)] == labels))


def tune(
    method: str,
    windows: np.ndarray,
    labels: np.ndarray,
    rng: np.random.Generator,
    grid: Iterable[dict[str, Any]] | None = None,
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Search the parameters of one method.

    Args:
        method: ``"dog"``, ``"slcn"``, ``"dlcn"`` (or any registered name with a ``grid``).
        windows: ``(n, S, S)`` float32 training windows in [0, 1] (``S >= 32``), uint8 accepted.
        labels: ``(n,)`` class of each window (0 = background).
        rng: random generator of the relighting.
        grid: settings to try; default :data:`GRIDS` ``[method]``.

    Returns:
        ``(best_params, trials)`` where trials lists ``{"params", "score"}`` for every setting.
    """
    grid = list(grid) if grid is not None else GRIDS.get(method, [])
    if not grid:
        raise InputError(f"no parameter grid for {method!r}; tunable: {', '.join(GRIDS)}")
    if windows.dtype == np.uint8:
        windows = windows.astype(np.float32) / np.float32(255)
    if windows.ndim != 3 or windows.shape[1] < CROP or windows.shape[2] < CROP or len(windows) != len(labels):
        raise InputError(f"windows must be (n, S>={CROP}, S>={CROP}) with one label each, got {windows.shape}")
    windows, labels = shifted_negatives(windows, np.asarray(labels), rng)
    queries = relight_windows(windows, rng)
    trials = []
    for params in grid:
        score = _score(method, params, windows, queries, np.asarray(labels))
        trials.append({"params": params, "score": score})
        logger.debug("tuning %s %s: %.4f", method, params, score)
    best = max(trials, key=lambda t: t["score"])  # first of equal scores: grid order
    logger.info("tuned %s: %s (relit 1-NN accuracy %.3f)", method, best["params"], best["score"])
    return dict(best["params"]), trials


def tune_all(
    windows: np.ndarray, labels: np.ndarray, seed: int, methods: Iterable[str] = tuple(GRIDS)
) -> dict[str, dict[str, Any]]:
    """:func:`tune` every method of ``methods`` on the same windows and relighting.

    Returns:
        ``{method: {"params": best, "trials": [...]}}``.
    """
    out = {}
    for method in methods:
        best, trials = tune(method, windows, labels, np.random.default_rng(seed))
        out[method] = {"params": best, "trials": trials}
    return out
