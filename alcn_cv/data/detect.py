"""An ALCN-2D-like detection benchmark (paper Sec. 4.3, Fig. 4).

The paper's ALCN-2D has three objects (matte, velvet-like and specular), ten training images
per object under one lighting, and test images with and without the objects, under very
different lightings and light colours, with distractors and clutter. This module renders such
a set and writes it in COCO format::

    DIR/manifest.json          generator version, seed, parameters, working_scale, box_size
    DIR/train.json             COCO: n_train images per object, one constant lighting
    DIR/test.json              COCO: test images (1280x800 by default), 0..K objects each
    DIR/val.json               COCO: validation images, drawn as the test images but from their own seeds
    DIR/images/train/*.png     BGR
    DIR/images/test/*.png
    DIR/images/val/*.png

``working_scale`` is the factor by which to resize the images so that the objects are about
36 px (the detector's window is 48x48 at the working scale, its centre 32x32); ``box_size`` is
the side, in working-scale pixels, of the fixed-size square boxes of the PASCAL criterion.
COCO boxes are the tight boxes of each object's visible silhouette at full resolution. Each
test and validation image's lighting family and parameters are stored in its ``lighting`` field.

The validation images are test-like (clutter, the test's lighting families) for choosing a method's parameters
(``alcn bench detect --tune``) without the test images. Each image draws from its own random stream (training:
``[seed, 1, object, j]``, test: ``[seed, 2, j]``, validation: ``[seed, 3, j]``), so the number of validation images
changes neither the training nor the test images.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np

from alcn_cv.data.detect_settings import CONFS, MAX_SIDE, DetectConfig
from alcn_cv.data.lighting import LIGHT_FAMILIES, Lighting, directional, sample_lighting
from alcn_cv.data.manifest import atomic_output_dir, make_manifest
from alcn_cv.data.objects import ReliefObject, background_surface, make_object, paste, to_surface
from alcn_cv.data.parallel import parallel_map
from alcn_cv.data.render import Material, render_surfaces
from alcn_cv.data.textures import photo_crop, procedural_texture
from alcn_cv.errors import InputError
from alcn_cv.formats.coco import write_coco
from alcn_cv.io import write_image, write_json
from alcn_cv.presets import preset_named, with_given

__all__ = ["OBJECTS", "benchmark_objects", "generate"]


#: The benchmark's objects: (name, material family, shape).
OBJECTS: tuple[tuple[str, str, str], ...] = (
    ("matte_box", "matte", "box"),
    ("velvet_toy", "velvet", "blob"),
    ("specular_can", "metal", "cylinder"),
)


# A glossy metallic finish whose texture stays visible (printed tin): strong, tight, tinted highlights.
_SPECULAR = Material("metal", diffuse=0.55, specular=0.8, shininess=120.0, metallic=0.5)


def benchmark_objects(object_seed: int, canonical: int) -> list[ReliefObject]:
    """The objects of :data:`OBJECTS`, deterministic for ``object_seed`` (distinct from Phos')."""
    out = []
    for k, (_, mat, shape) in enumerate(OBJECTS):
        rng = np.random.default_rng([object_seed, 7919, k])
        material = _SPECULAR if mat == "metal" else mat
        out.append(make_object(rng, canonical, shape=shape, material=material, relief=rng.uniform(0.12, 0.2)))
    return out


def training_lighting() -> Lighting:
    """The constant training lighting: white light from 70 degrees elevation, moderate ambient."""
    return Lighting(
        "ambient",
        [directional(45.0, 70.0, (0.85, 0.85, 0.85))],
        np.full(3, 0.25, np.float32),
        gain=1.0,
        gamma=2.2,
        shot_noise=5e-4,
        read_noise=1e-3,
    )


def _ground(rng: np.random.Generator, h: int, w: int):
    tex = photo_crop(rng, (h, w)) if rng.random() < 0.6 else procedural_texture(rng, (h, w))
    return background_surface(rng, h, w, tex, relief=2.0)


def _tight_box(cov: np.ndarray) -> list[float] | None:
    ys, xs = np.nonzero(cov > 0.5)
    if len(xs) == 0:
        return None
    return [float(xs.min()), float(ys.min()), float(xs.max() - xs.min() + 1), float(ys.max() - ys.min() + 1)]


def _render(
    rng: np.random.Generator, surf: tuple[np.ndarray, np.ndarray, np.ndarray], lighting: Lighting, cfg: DetectConfig
) -> np.ndarray:
    scale = 2 if max(cfg.width, cfg.height) > 400 else 1
    return render_surfaces(
        to_surface([surf]),
        [lighting],
        rng,
        camera_height=1.5 * max(cfg.width, cfg.height),
        shadow_steps=24,
        shadow_scale=scale,
    )[0]


def _train_image(rng: np.random.Generator, obj: ReliefObject, cfg: DetectConfig):
    h, w = cfg.height, cfg.width
    surf = _ground(rng, h, w)
    centre = (w / 2 + rng.uniform(-0.1, 0.1) * w, h / 2 + rng.uniform(-0.1, 0.1) * h)
    scale = cfg.object_px / (0.92 * obj.size) * rng.uniform(0.92, 1.08)
    cov = paste(*surf, obj, centre, scale, rng.uniform(-10, 10))
    return _render(rng, surf, training_lighting(), cfg), _tight_box(cov), float(cov.sum())


def _free(boxes: list[tuple[float, float, float]], x: float, y: float, r: float) -> bool:
    return all((x - bx) ** 2 + (y - by) ** 2 > (r + br) ** 2 for bx, by, br in boxes)


def _test_image(rng: np.random.Generator, objs: list[ReliefObject], cfg: DetectConfig):
    h, w = cfg.height, cfg.width
    surf = _ground(rng, h, w)
    obj_scale = cfg.object_px / (0.92 * objs[0].size)
    taken: list[tuple[float, float, float]] = []
    r_obj = cfg.object_px * 0.6
    # Clutter: flat printed patches and relief distractors, away from the objects' places.
    placements = []
    for k in range(len(objs)):
        if rng.random() < cfg.p_object:
            for _ in range(30):
                x, y = rng.uniform(r_obj, w - r_obj), rng.uniform(r_obj, h - r_obj)
                if _free(taken, x, y, r_obj):
                    taken.append((x, y, r_obj))
                    placements.append((k, x, y))
                    break
    for _ in range(int(rng.integers(3, 9))):
        patch = make_object(rng, 64, shape="slab", relief=0.01)
        s = cfg.object_px / 58.0 * rng.uniform(0.5, 1.6)
        x, y = rng.uniform(0, w), rng.uniform(0, h)
        if _free(taken, x, y, 0.5 * s * 64):
            paste(*surf, patch, (x, y), s, rng.uniform(0, 360))
    for _ in range(int(rng.integers(3, 11))):
        dist = make_object(rng, 96)
        s = cfg.object_px / 88.0 * rng.uniform(0.6, 1.4)
        x, y = rng.uniform(0, w), rng.uniform(0, h)
        if _free(taken, x, y, 0.5 * s * 96):
            taken.append((x, y, 0.5 * s * 96))
            paste(*surf, dist, (x, y), s, rng.uniform(0, 360))
    anns = []
    for k, x, y in placements:
        cov = paste(
            *surf,
            objs[k],
            (x, y),
            obj_scale * rng.uniform(0.9, 1.1),
            rng.uniform(-10, 10),
            tilt=(rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05)),
        )
        box = _tight_box(cov)
        if box is not None:
            anns.append((k + 1, box, float(cov.sum())))
    family = LIGHT_FAMILIES[int(rng.integers(len(LIGHT_FAMILIES)))]
    lighting = sample_lighting(rng, family, w, h, relief=float(np.percentile(surf[1], 99)))
    return _render(rng, surf, lighting, cfg), anns, lighting


@functools.lru_cache(maxsize=2)
def _objects(object_seed: int, canonical: int) -> tuple[ReliefObject, ...]:
    return tuple(benchmark_objects(object_seed, canonical))


def _image_job(job: tuple) -> tuple[list, dict]:
    """Render one image and write it; return its objects (category, box, area) and lighting."""
    split, k, j, path, _, seed, object_seed, cfg = job
    objs = _objects(object_seed, cfg.canonical)
    if split == "train":
        img, box, area = _train_image(np.random.default_rng([seed, 1, k, j]), objs[k], cfg)
        found, lighting = [(k + 1, box, area)], training_lighting()
    else:  # test and validation images: the same draw from separate streams
        stream = 2 if split == "test" else 3
        img, found, lighting = _test_image(np.random.default_rng([seed, stream, j]), list(objs), cfg)
    write_image(path, img)
    return found, lighting.describe()


def generate(
    out_dir: str | os.PathLike,
    *,
    seed: int = 0,
    conf: str = "default",
    object_seed: int = 0,
    n_test: int | None = None,
    n_val: int | None = None,
    n_train: int | None = None,
    width: int | None = None,
    height: int | None = None,
    p_object: float | None = None,
    overwrite: bool = False,
    progress: bool = True,
    workers: int = 1,
) -> Path:
    """Render the detection benchmark into ``out_dir`` (atomically).

    Args:
        out_dir: output folder.
        seed: seed of the images (deterministic: same seed and parameters, same bytes).
        conf: a preset of :data:`CONFS`, the values of the parameters below that are not given.
        object_seed: seed of the three objects.
        n_test, n_val, n_train, width, height: override the preset's values (objects keep their size in
            pixels, so the working scale does not change): at least one test image (`alcn bench detect` scores on
            them) and one training image per object; width and height from twice the object size to
            :data:`~alcn_cv.data.detect_settings.MAX_SIDE`.
        p_object: override the preset's probability that each object appears in a test image.
        overwrite: replace an existing folder.
        progress: show a progress bar.
        workers: worker processes (the output does not depend on it).

    Returns:
        The output folder.

    Raises:
        InputError: an unknown preset (:func:`~alcn_cv.presets.preset_named`), or a value out of range.
    """
    cfg = with_given(
        preset_named(CONFS, conf),
        width=width,
        height=height,
        n_train=n_train,
        n_test=n_test,
        n_val=n_val,
        p_object=p_object,
    )
    if not (2 * cfg.object_px <= cfg.width <= MAX_SIDE and 2 * cfg.object_px <= cfg.height <= MAX_SIDE):
        raise InputError(
            f"the images' width and height (--width, --height) must be from {2 * cfg.object_px:g} px (twice the "
            f"objects' size in preset {conf!r}) to {MAX_SIDE} px: got {cfg.width}x{cfg.height}"
        )
    # no test image: `alcn bench detect` has nothing to score on; no validation image: nothing to tune on (the demo's)
    if cfg.n_train < 1 or cfg.n_test < 1 or cfg.n_val < 0:
        raise InputError(
            f"need n_train >= 1, n_test >= 1 and n_val >= 0: got n_train={cfg.n_train}, n_test={cfg.n_test}, "
            f"n_val={cfg.n_val}"
        )
    if not 0.0 <= cfg.p_object <= 1.0:
        raise InputError(f"p_object is a probability, in [0, 1]; got {cfg.p_object}")
    cats = [
        {"id": k + 1, "name": name, "supercategory": "object", "material": mat}
        for k, (name, mat, _) in enumerate(OBJECTS)
    ]
    with atomic_output_dir(out_dir, overwrite=overwrite) as tmp:
        (tmp / "images" / "train").mkdir(parents=True)
        (tmp / "images" / "test").mkdir(parents=True)
        (tmp / "images" / "val").mkdir(parents=True)
        jobs = [
            ("train", k, j, f"images/train/{OBJECTS[k][0]}_{j:02d}.png")
            for k in range(len(OBJECTS))
            for j in range(cfg.n_train)
        ]
        jobs += [("test", 0, j, f"images/test/{j:05d}.png") for j in range(cfg.n_test)]
        jobs += [("val", 0, j, f"images/val/{j:05d}.png") for j in range(cfg.n_val)]
        jobs = [(split, k, j, str(tmp / name), name, seed, object_seed, cfg) for split, k, j, name in jobs]
        results = list(
            parallel_map(_image_job, jobs, workers=workers, desc="detect images", unit="img", progress=progress)
        )
        for split in ("train", "test", "val"):
            images, anns = [], []
            for job, (objs_here, lighting) in zip(jobs, results):
                if job[0] != split:
                    continue
                iid = len(images) + 1
                entry = {"id": iid, "file_name": job[4], "width": cfg.width, "height": cfg.height}
                if split != "train":
                    entry["light_family"] = lighting["family"]
                images.append({**entry, "lighting": lighting})
                for cat, box, area in objs_here:
                    anns.append(
                        {
                            "id": len(anns) + 1,
                            "image_id": iid,
                            "category_id": cat,
                            "bbox": box,
                            "area": round(area, 2),
                            "iscrowd": 0,
                        }
                    )
            info = {"description": f"alcn-cv ALCN-2D-like detection benchmark, {split} images", "seed": seed}
            write_coco(tmp / f"{split}.json", images, anns, cats, info)
        params = {
            "conf": conf,
            "object_seed": object_seed,
            "width": cfg.width,
            "height": cfg.height,
            "n_train": cfg.n_train,
            "n_test": cfg.n_test,
            "n_val": cfg.n_val,
            "object_px": cfg.object_px,
            "p_object": cfg.p_object,
        }
        write_json(
            tmp / "manifest.json",
            make_manifest(
                "detect",
                seed,
                params,
                working_scale=cfg.working_scale,
                box_size=cfg.box_px,
                window=48,
                detector_window=32,
                objects=[{"id": k + 1, "name": n, "material": m, "shape": s} for k, (n, m, s) in enumerate(OBJECTS)],
                light_families=list(LIGHT_FAMILIES),
                files={"train": "train.json", "test": "test.json", "val": "val.json"},
                bbox_convention="COCO [x, y, w, h]: tight box of the visible silhouette, full-resolution pixels",
            ),
        )
    return Path(out_dir)
