"""Intensity statistics of rendered images beside real photographs (``alcn data compare-psm``).

The real set is ``../shared/data/psm``: objects photographed under 12 known directional lights
(``lights.txt``), with a mask per object. The data engine renders relief objects under (a) the
same 12 light directions, with their textures and materials and (b) with a plain matte albedo
like the plaster-like PSM objects, and (c) under 12 lightings drawn from its lighting families;
the same statistics are computed inside the objects' masks:

- per image: mean, standard deviation, dynamic range (99th - 1st percentile), fraction
  saturated (>= 254/255), fraction black (<= 2/255), and the distribution of local contrast
  (local standard deviation in a Gaussian window of sigma 2 px; median and 90th percentile);
- per object across its 12 lights: the coefficient of variation of the mean (how much the
  brightness changes) and the mean pairwise normalised cross-correlation (how much the
  appearance changes).

Intensities are grayscale in [0, 1]. The comparison is written as a Markdown and JSON table and a
side-by-side figure.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import cv2
import numpy as np

from alcn_cv.data.lighting import LIGHT_FAMILIES, Light, Lighting, sample_lighting
from alcn_cv.data.objects import make_object, paste, to_surface
from alcn_cv.data.render import render_surfaces
from alcn_cv.data.scenes import load_photometric, mean_pairwise_ncc
from alcn_cv.errors import DatasetError
from alcn_cv.io import atomic_write, check_no_earlier_output, check_writable, make_folder, write_json
from alcn_cv.report import describe_machine

logger = logging.getLogger(__name__)

__all__ = ["STAT_NAMES", "image_stats", "set_stats", "load_psm", "render_like_psm", "compare_psm"]

STAT_NAMES = ("mean", "std", "dynamic_range", "saturated", "black", "local_contrast_median", "local_contrast_p90")


def image_stats(gray: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    """Statistics of one grayscale image in [0, 1] (float32 HxW) inside a boolean mask."""
    v = gray[mask]
    if v.size < 10:
        raise DatasetError("mask has fewer than 10 pixels")
    mu = cv2.GaussianBlur(gray, (0, 0), 2.0)
    mu2 = cv2.GaussianBlur(gray * gray, (0, 0), 2.0)
    local = np.sqrt(np.maximum(mu2 - mu * mu, 0))
    inner = cv2.erode(mask.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
    lc = local[inner] if inner.sum() >= 10 else local[mask]
    p1, p99 = np.percentile(v, [1, 99])
    return {
        "mean": float(v.mean()),
        "std": float(v.std()),
        "dynamic_range": float(p99 - p1),
        "saturated": float((v >= 254 / 255).mean()),
        "black": float((v <= 2 / 255).mean()),
        "local_contrast_median": float(np.median(lc)),
        "local_contrast_p90": float(np.percentile(lc, 90)),
    }


def set_stats(objects: dict[str, tuple[list[np.ndarray], np.ndarray]]) -> dict[str, dict[str, float]]:
    """Mean and standard deviation over all images of each statistic, plus across-light ones.

    Args:
        objects: name -> (12 grayscale float32 images, boolean mask).
    """
    per_image = {k: [] for k in STAT_NAMES}
    cv_means, nccs = [], []
    for imgs, mask in objects.values():
        st = [image_stats(g, mask) for g in imgs]
        for k in STAT_NAMES:
            per_image[k] += [s[k] for s in st]
        means = np.array([s["mean"] for s in st])
        cv_means.append(float(means.std() / max(means.mean(), 1e-6)))
        nccs.append(mean_pairwise_ncc(imgs, mask))
    out = {k: {"mean": float(np.mean(v)), "std": float(np.std(v))} for k, v in per_image.items()}
    out["across_lights_cv_of_mean"] = {"mean": float(np.mean(cv_means)), "std": float(np.std(cv_means))}
    out["across_lights_pairwise_ncc"] = {"mean": float(np.mean(nccs)), "std": float(np.std(nccs))}
    return out


def load_psm(psm_dir: str | os.PathLike) -> tuple[dict[str, tuple[list[np.ndarray], np.ndarray]], np.ndarray]:
    """Read the PSM set: ``({name: (12 gray float32 images, bool mask)}, lights (12, 3))``: the objects of
    :func:`~alcn_cv.data.scenes.load_photometric`, each with one image per light of ``lights.txt``.

    Raises:
        DatasetError: as :func:`~alcn_cv.data.scenes.load_photometric`; ``lights.txt`` missing or malformed, or an
            object with another number of images.
    """
    root = Path(psm_dir)
    objects = load_photometric(root)  # the folder first: else the first complaint would be the missing lights.txt
    lf = root / "lights.txt"
    try:
        rows = lf.read_text(encoding="utf-8").split("\n")
        count = int(rows[0])
        lights = np.array([[float(x) for x in r.split()] for r in rows[1 : 1 + count]])
    except FileNotFoundError:
        raise DatasetError(f"{lf}: file not found") from None
    except (ValueError, IndexError) as exc:
        raise DatasetError(f"{lf}: malformed (first line: count, then x y z per light): {exc}") from None
    if lights.shape != (count, 3):
        raise DatasetError(f"{lf}: expected {count} rows of 3 numbers")
    for obj in objects:
        if len(obj.images) != count:
            raise DatasetError(f"{root / obj.name}: {len(obj.images)} images, but {lf.name} lists {count} lights")
    return {obj.name: (list(obj.images), obj.mask) for obj in objects}, lights


#: Objects :func:`render_like_psm` renders, and their images' side (pixels).
PSM_LIKE_OBJECTS, PSM_LIKE_SIZE = 4, 256


def render_like_psm(
    lights: np.ndarray | None, seed: int = 0, *, plain: bool = False
) -> dict[str, tuple[list[np.ndarray], np.ndarray]]:
    """Render :data:`PSM_LIKE_OBJECTS` relief objects on black, :data:`PSM_LIKE_SIZE` pixels square, under
    ``len(lights)`` lightings (12 when ``lights`` is None).

    Args:
        lights: (L, 3) light directions in the PSM convention (x right, y up, z towards the
            camera): white directional lights with no ambient light, gain 1, gamma 2.2. None:
            ``L = 12`` lightings drawn from :data:`LIGHT_FAMILIES` in turn.
        seed: the objects' seed.
        plain: give the objects a uniform matte albedo (0.5) instead of their textures and
            materials, like the plaster-like PSM objects, to isolate the effect of the lighting.

    Returns:
        ``{name: (images, mask)}`` as :func:`load_psm`.
    """
    out = {}
    shapes = ("dome", "blob", "cylinder", "box")
    count = 12 if lights is None else len(lights)
    size = PSM_LIKE_SIZE
    for k in range(PSM_LIKE_OBJECTS):
        rng = np.random.default_rng([seed, 31, k])
        obj = make_object(rng, 192, shape=shapes[k % len(shapes)], relief=0.3, material="matte" if plain else None)
        if plain:
            obj.albedo[:] = 0.5
        alb = np.zeros((size, size, 3), np.float32)
        hgt = np.zeros((size, size), np.float32)
        mat = np.zeros((size, size, 6), np.float32)
        cov = paste(alb, hgt, mat, obj, ((size - 1) / 2, (size - 1) / 2), size * 0.9 / 192)
        lts = []
        for i in range(count):
            if lights is None:
                lts.append(sample_lighting(rng, LIGHT_FAMILIES[i % len(LIGHT_FAMILIES)], size, size))
            else:
                x, y, z = lights[i]
                lts.append(
                    Lighting(
                        "psm",
                        [Light("directional", (float(x), float(-y), float(z)))],
                        np.zeros(3, np.float32),
                        gain=1.0,
                        gamma=2.2,
                        shot_noise=5e-4,
                        read_noise=2e-3,
                    )
                )
        surf = to_surface([(alb, hgt, mat)] * count)
        imgs = render_surfaces(surf, lts, rng, gray=True)
        out[f"object{k + 1}"] = ([g.astype(np.float32) / 255.0 for g in imgs], cov > 0.5)
    return out


def _figure(path: Path, sets: dict[str, dict], stats: dict[str, dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(sets)
    fig = plt.figure(figsize=(16, 4 + 1.4 * len(names)))
    gs = fig.add_gridspec(len(names) + 1, 12, height_ratios=[1] * len(names) + [2.2])
    for r, name in enumerate(names):
        imgs, mask = next(iter(sets[name].values()))
        ys, xs = np.nonzero(mask)
        y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
        for c in range(12):
            ax = fig.add_subplot(gs[r, c])
            ax.imshow(imgs[c % len(imgs)][y0:y1, x0:x1], cmap="gray", vmin=0, vmax=1)
            ax.set_xticks([])
            ax.set_yticks([])
            if c == 0:
                ax.set_ylabel(name.replace(" ", "\n", 2), fontsize=7)
    keys = ["mean", "std", "dynamic_range", "saturated", "local_contrast_median", "across_lights_pairwise_ncc"]
    for i, k in enumerate(keys):
        ax = fig.add_subplot(gs[len(names), 2 * i : 2 * i + 2])
        m = [stats[n][k]["mean"] for n in names]
        s = [stats[n][k]["std"] for n in names]
        ax.bar(range(len(names)), m, yerr=s, color=["tab:gray", "tab:blue", "tab:green", "tab:orange"][: len(names)])
        ax.set_xticks(range(len(names)))
        ax.set_xticklabels([n.replace(" ", "\n") for n in names], fontsize=7)
        ax.set_title(k, fontsize=9)
    fig.suptitle("Real PSM photographs (12 directional lights) vs. data-engine renderings")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def compare_psm(
    psm_dir: str | os.PathLike, out_dir: str | os.PathLike, *, seed: int = 0, overwrite: bool = False
) -> dict:
    """Compare the statistics of real PSM photographs with the engine's renderings.

    Writes ``out_dir/psm_comparison.png`` (figure), ``psm_comparison.md`` and
    ``psm_comparison.json`` (tables); an earlier run's only with ``overwrite``. Returns the statistics.
    """
    out = Path(out_dir)
    check_writable(out / "psm_comparison.json")  # before the renderings: an output under a file fails at once
    check_no_earlier_output([out / f"psm_comparison{suffix}" for suffix in (".json", ".md", ".png")], overwrite)
    real, lights = load_psm(psm_dir)
    sets = {
        "real psm": real,
        "engine psm lights": render_like_psm(lights, seed=seed),
        "engine psm lights plain albedo": render_like_psm(lights, seed=seed, plain=True),
        "engine light families": render_like_psm(None, seed=seed),
    }
    stats = {name: set_stats(objs) for name, objs in sets.items()}
    make_folder(out)
    write_json(out / "psm_comparison.json", stats)
    rows = list(STAT_NAMES) + ["across_lights_cv_of_mean", "across_lights_pairwise_ncc"]
    lines = [
        "# Real photometric-stereo photographs against the data engine's renderings\n",
        f"Real: `{Path(psm_dir)}` ({len(lights)} directional lights an object). Renderings: seed {seed}. Machine: "
        f"{describe_machine()}.\n",
        "Inside each object's mask, gray intensities in [0, 1], mean ± standard deviation over the images (per image: "
        "the mean, standard deviation, dynamic range (99th - 1st percentile), the share saturated (>= 254/255) and "
        "black (<= 2/255), the local contrast's median and 90th percentile (standard deviation in a Gaussian window "
        "of sigma 2 px)) or over the objects (across its lights: the coefficient of variation of an object's mean, "
        "and the mean pairwise normalized cross-correlation of its images).\n",
        "| statistic | " + " | ".join(sets) + " |",
        "|---" * (len(sets) + 1) + "|",
    ]
    for r in rows:
        lines.append(
            f"| {r} | " + " | ".join(f"{stats[n][r]['mean']:.3f} ± {stats[n][r]['std']:.3f}" for n in sets) + " |"
        )
    atomic_write(out / "psm_comparison.md", "\n".join(lines) + "\n")
    _figure(out / "psm_comparison.png", sets, stats)
    logger.info("wrote %s", out / "psm_comparison.png")
    return stats
