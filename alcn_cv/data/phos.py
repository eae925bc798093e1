"""Phos-like training windows for the Normalizer (paper Sec. 4.1).

The paper trains the Normalizer jointly with a detector on Phos: real objects photographed
under many lightings. Here the objects are rendered: ``n_objects`` textured relief objects
(:mod:`alcn_cv.data.objects`; albedos from photographs and procedural textures, random height
maps, matte/plastic/velvet/metal) under lightings drawn from :data:`LIGHT_FAMILIES`.

Windows are 64x64 grayscale: the Normalizer sees the centre 48x48, the Gaussian mixture (sigmas
up to 5 px, radius 15) is computed on the 64x64 so that its centre 32x32, what the detector
sees, has no border effect. Object windows show object ``k`` (label ``k`` in 1..K) centred to
within +-3 px, with an extent of ``object_size`` pixels (most of the 32x32 centre), rotated by
up to +-15 degrees, on a random textured ground. Background windows (label 0) are plain
ground (natural-photograph crops and procedural textures), relief *distractors* that are not
in the catalogue, and catalogue objects far off-centre (14-26 px), so that the detector learns
identity and centring rather than "there is a relief".

Lighting families (``light_ids`` index :data:`LIGHT_FAMILIES`): ``ambient`` (training-like),
``dark`` (gain 0.05-0.3), ``bright`` (gain 2-4, saturated), ``side`` (15-35 degrees elevation),
``shadow`` (hard cast shadows and a strong gradient), ``spot``, ``point``, ``colour``, ``mixed``;
hold some out for validation.

Generation is chunked (256 windows); chunk ``c`` draws from ``numpy.random.default_rng([seed, c])``
so the output is deterministic for ``(n, seed, parameters)``, and the first ``m`` windows of ``n``
equal the ``m`` windows of a run with the same seed. Objects depend only on ``object_seed``,
so runs with different seeds (training and validation) share the same objects.
"""

from __future__ import annotations

import functools
import inspect
import os
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np

from alcn_cv.data.lighting import LIGHT_FAMILIES, sample_lighting
from alcn_cv.data.manifest import atomic_output_dir, make_manifest, read_manifest, save_npz
from alcn_cv.data.objects import ReliefObject, background_surface, make_catalog, make_object, paste, to_surface
from alcn_cv.data.parallel import parallel_map
from alcn_cv.data.render import render_surfaces
from alcn_cv.data.textures import random_texture
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.io import write_json

__all__ = ["WINDOW", "KIND_NAMES", "PhosBatch", "render_windows", "generate", "load"]

#: Side of the rendered windows in pixels.
WINDOW = 64
#: Names of the window kinds in :attr:`PhosBatch.kinds`.
KIND_NAMES: tuple[str, ...] = ("object", "ground", "distractor", "off_centre")
_CHUNK = 256
_CANONICAL = 96
_POOL = 16


@dataclass
class PhosBatch:
    """Rendered Normalizer training windows.

    Attributes:
        windows: uint8 (n, 64, 64) grayscale windows.
        labels: int64 (n,): 0 = background, 1..n_objects = object id.
        light_ids: int64 (n,): index into ``light_families`` of each window's lighting family.
        kinds: int64 (n,): index into :data:`KIND_NAMES` (object, plain ground, distractor,
            off-centre object).
        offsets: float32 (n, 2): (dx, dy) in pixels of the object's centre from the window's
            centre (for off-centre negatives too), NaN for windows without a catalogue object.
        extents: float32 (n,): object extent in pixels, NaN without a catalogue object.
        n_objects: number of catalogue objects K.
        object_seed: seed of the catalogue.
        seed: seed of the windows.
        light_families: names of the lighting families.
    """

    windows: np.ndarray
    labels: np.ndarray
    light_ids: np.ndarray
    kinds: np.ndarray
    offsets: np.ndarray
    extents: np.ndarray
    n_objects: int
    object_seed: int
    seed: int
    light_families: tuple[str, ...] = field(default=LIGHT_FAMILIES)
    #: The names of the per-window arrays, in the order of the fields.
    ARRAYS: ClassVar[tuple[str, ...]] = ("windows", "labels", "light_ids", "kinds", "offsets", "extents")

    def __len__(self) -> int:
        return len(self.labels)

    def subset(self, index: np.ndarray | slice) -> PhosBatch:
        """The windows selected by ``index`` (a slice, integer or boolean array)."""
        return PhosBatch(
            self.windows[index],
            self.labels[index],
            self.light_ids[index],
            self.kinds[index],
            self.offsets[index],
            self.extents[index],
            self.n_objects,
            self.object_seed,
            self.seed,
            self.light_families,
        )


@functools.lru_cache(maxsize=4)
def _catalog(n_objects: int, object_seed: int) -> tuple[ReliefObject, ...]:
    return tuple(make_catalog(n_objects, object_seed, _CANONICAL))


def _families(lighting: str | Sequence[str]) -> list[int]:
    if isinstance(lighting, str):
        names = list(LIGHT_FAMILIES) if lighting == "random" else [s.strip() for s in lighting.split(",")]
    else:
        names = list(lighting)
    bad = [s for s in names if s not in LIGHT_FAMILIES]
    if bad or not names:
        raise InputError(f"unknown lighting {bad or lighting!r}; use 'random' or names from {LIGHT_FAMILIES}")
    return [LIGHT_FAMILIES.index(s) for s in names]


def _check_parameters(n: int, n_objects: int, background_fraction: float, lighting: str | Sequence[str]) -> list[int]:
    """Check the parameters of :func:`render_windows`; return the indices of the lighting families."""
    if n < 0 or n_objects < 1:
        raise InputError(f"need n >= 0 and n_objects >= 1, got n={n}, n_objects={n_objects}")
    if not 0.0 <= background_fraction <= 1.0:
        raise InputError(f"background_fraction must be in [0, 1], got {background_fraction}")
    return _families(lighting)


def _render_chunk(
    c: int,
    count: int,
    seed: int,
    catalog: Sequence[ReliefObject],
    families: list[int],
    background_fraction: float,
    object_size: tuple[float, float],
) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng([seed, c])
    w = WINDOW
    grounds = [background_surface(rng, 2 * w, 2 * w, random_texture(rng, 2 * w, p_photo=0.6)) for _ in range(_POOL)]
    distractors = [make_object(rng, _CANONICAL) for _ in range(_POOL // 2)]
    items, lightings = [], []
    labels = np.zeros(count, np.int64)
    light_ids = np.zeros(count, np.int64)
    kinds = np.zeros(count, np.int64)
    offsets = np.full((count, 2), np.nan, np.float32)
    extents = np.full(count, np.nan, np.float32)
    centre = (w - 1) / 2.0
    for i in range(count):
        g = grounds[int(rng.integers(_POOL))]
        y0, x0 = (int(v) for v in rng.integers(0, w + 1, 2))
        albedo = g[0][y0 : y0 + w, x0 : x0 + w].copy()
        height = g[1][y0 : y0 + w, x0 : x0 + w].copy()
        material = g[2][y0 : y0 + w, x0 : x0 + w].copy()
        extent = float(rng.uniform(*object_size))
        scale = extent / (0.92 * _CANONICAL)
        if rng.random() < 0.3:  # clutter at the window's edge
            a = rng.uniform(0, 2 * np.pi)
            d = rng.uniform(0.65, 0.9) * w
            paste(
                albedo,
                height,
                material,
                distractors[int(rng.integers(len(distractors)))],
                (centre + d * np.cos(a), centre + d * np.sin(a)),
                scale * rng.uniform(0.7, 1.3),
                rng.uniform(0, 360),
            )
        is_object = rng.random() >= background_fraction
        kind = 0 if is_object else int(rng.choice([1, 2, 3], p=[0.35, 0.4, 0.25]))
        angle = rng.uniform(-15, 15)
        tilt = (rng.uniform(-0.08, 0.08), rng.uniform(-0.08, 0.08))
        if kind in (0, 3):
            k = int(rng.integers(len(catalog)))
            off = rng.uniform(-3, 3, 2)
            if kind == 3:
                a = rng.uniform(0, 2 * np.pi)
                off = rng.uniform(14, 26) * np.array([np.cos(a), np.sin(a)])
            paste(albedo, height, material, catalog[k], (centre + off[0], centre + off[1]), scale, angle, tilt=tilt)
            labels[i] = k + 1 if kind == 0 else 0
            offsets[i] = off
            extents[i] = extent
        elif kind == 2:
            off = rng.uniform(-3, 3, 2)
            paste(
                albedo,
                height,
                material,
                distractors[int(rng.integers(len(distractors)))],
                (centre + off[0], centre + off[1]),
                scale,
                rng.uniform(0, 360),
                tilt=tilt,
            )
        kinds[i] = kind
        fam = families[int(rng.integers(len(families)))]
        light_ids[i] = fam
        lightings.append(sample_lighting(rng, LIGHT_FAMILIES[fam], w, w, relief=float(height.max())))
        items.append((albedo, height, material))
    windows = render_surfaces(to_surface(items), lightings, rng, gray=True, shadow_steps=10, shadow_scale=2)
    return windows, labels, light_ids, kinds, offsets, extents


def render_windows(
    n: int,
    seed: int,
    *,
    n_objects: int = 100,
    object_seed: int = 0,
    lighting: str | Sequence[str] = "random",
    background_fraction: float = 0.35,
    object_size: tuple[float, float] = (34.0, 46.0),
    progress: bool = False,
    workers: int = 1,
) -> PhosBatch:
    """Render ``n`` labelled 64x64 grayscale windows (the Normalizer's stage-1 training data).

    Args:
        n: number of windows.
        seed: seed of the windows (objects depend on ``object_seed`` only).
        n_objects: number K of catalogue objects (labels 1..K).
        object_seed: seed of the catalogue; keep it fixed between training and validation.
        lighting: ``"random"`` (every family, uniformly), a family name of
            :data:`LIGHT_FAMILIES`, a comma-separated list or a sequence of names.
        background_fraction: expected fraction of background (label 0) windows.
        object_size: range of object extents in pixels (the detector sees the centre 32x32).
        progress: show a progress bar.
        workers: worker processes (the output does not depend on it).

    Returns:
        A :class:`PhosBatch`.
    """
    families = _check_parameters(n, n_objects, background_fraction, lighting)
    cols = [
        np.empty((n, WINDOW, WINDOW), np.uint8),
        np.empty(n, np.int64),
        np.empty(n, np.int64),
        np.empty(n, np.int64),
        np.empty((n, 2), np.float32),
        np.empty(n, np.float32),
    ]
    jobs = [
        (
            c,
            min(_CHUNK, n - c * _CHUNK),
            int(seed),
            int(n_objects),
            int(object_seed),
            families,
            float(background_fraction),
            tuple(object_size),
        )
        for c in range((n + _CHUNK - 1) // _CHUNK)
    ]
    parts = parallel_map(_chunk_job, jobs, workers=workers, desc="phos windows", unit="chunk", progress=progress)
    for (c, count, *_), part in zip(jobs, parts):
        for dst, src in zip(cols, part):
            dst[c * _CHUNK : c * _CHUNK + count] = src
    return PhosBatch(*cols, n_objects=int(n_objects), object_seed=int(object_seed), seed=int(seed))


def _chunk_job(job: tuple) -> tuple[np.ndarray, ...]:
    c, count, seed, n_objects, object_seed, families, background_fraction, object_size = job
    return _render_chunk(c, count, seed, _catalog(n_objects, object_seed), families, background_fraction, object_size)


def generate(
    out_dir: str | os.PathLike,
    n: int,
    seed: int,
    *,
    overwrite: bool = False,
    progress: bool = True,
    **params,
) -> Path:
    """Render windows with :func:`render_windows` and write ``windows.npz`` + ``manifest.json``.

    Args:
        out_dir: output folder (written atomically).
        n, seed, params: as :func:`render_windows`.
        overwrite: replace an existing folder.

    Returns:
        The output folder.
    """
    # The manifest records every parameter, the defaults of render_windows included.
    defaults = {
        k: p.default
        for k, p in inspect.signature(render_windows).parameters.items()
        if p.kind == p.KEYWORD_ONLY and k not in ("progress", "workers")
    }
    defaults.update({k: v for k, v in params.items() if k != "workers"})
    # Every user error is told before the rendering (minutes for the default 100000 windows), the output's by
    # atomic_output_dir, which the rendering runs in.
    if n < 1:
        raise InputError(f"the number of windows (-n) must be at least 1, got {n}")
    _check_parameters(n, defaults["n_objects"], defaults["background_fraction"], defaults["lighting"])
    defaults = {k: (list(v) if isinstance(v, tuple) else v) for k, v in defaults.items()}
    with atomic_output_dir(out_dir, overwrite=overwrite) as tmp:
        batch = render_windows(n, seed, progress=progress, **params)
        save_npz(tmp / "windows.npz", **{k: getattr(batch, k) for k in PhosBatch.ARRAYS})
        counts = np.bincount(batch.labels, minlength=batch.n_objects + 1)
        write_json(
            tmp / "manifest.json",
            make_manifest(
                "phos",
                seed,
                {"n": int(n), **defaults},
                window=WINDOW,
                light_families=list(LIGHT_FAMILIES),
                kinds=list(KIND_NAMES),
                files={"windows": "windows.npz"},
                counts={"background": int(counts[0]), "object": int(counts[1:].sum())},
            ),
        )
    return Path(out_dir)


def load(out_dir: str | os.PathLike) -> PhosBatch:
    """Read a folder written by :func:`generate`.

    Raises:
        DatasetError: missing or malformed manifest or arrays (the message names file and field).
    """
    out = Path(out_dir)
    man = read_manifest(out, "phos")
    path = out / man.get("files", {}).get("windows", "windows.npz")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in PhosBatch.ARRAYS if k in z.files}
    except FileNotFoundError:
        raise DatasetError(f"{path}: file not found") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise DatasetError(f"{path}: truncated or corrupt ({exc})") from None
    missing = [k for k in PhosBatch.ARRAYS if k not in arrays]
    if missing:
        raise DatasetError(f"{path}: missing array(s) {missing}")
    n = len(arrays["labels"])
    win = arrays["windows"]
    if win.dtype != np.uint8 or win.ndim != 3 or win.shape[0] != n or win.shape[1:] != (WINDOW, WINDOW):
        raise DatasetError(
            f"{path}: field 'windows' must be uint8 ({n}, {WINDOW}, {WINDOW}), got {win.dtype} {win.shape}"
        )
    for k in PhosBatch.ARRAYS[1:]:
        if len(arrays[k]) != n:
            raise DatasetError(f"{path}: field {k!r} has {len(arrays[k])} entries, expected {n}")
    k_obj = int(man["parameters"].get("n_objects", 0))
    if n and (arrays["labels"].min() < 0 or arrays["labels"].max() > k_obj):
        raise DatasetError(f"{path}: field 'labels' outside 0..{k_obj} (parameters.n_objects)")
    fams = tuple(man.get("light_families", LIGHT_FAMILIES))
    return PhosBatch(
        win,
        arrays["labels"].astype(np.int64),
        arrays["light_ids"].astype(np.int64),
        arrays["kinds"].astype(np.int64),
        arrays["offsets"].astype(np.float32),
        arrays["extents"].astype(np.float32),
        k_obj,
        int(man["parameters"].get("object_seed", 0)),
        int(man["seed"]),
        fams,
    )
