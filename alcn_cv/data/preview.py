"""Contact sheets of datasets with their ground truth drawn (``alcn data preview``).

Accepted inputs: a folder written by the data engine (its ``manifest.json`` says ``phos``,
``detect``, ``pose`` or ``relief_scenes``), a COCO JSON file, or a BOP scene folder
(``scene_camera.json``). Boxes are drawn for COCO, the projected 3D bounding box of each model for
BOP (models read from the dataset's ``models/``), the label and lighting family for Phos windows,
and the light family of each frame of the rendered scenes (a few frames of a few scenes, one scene a row).
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from alcn_cv.data.manifest import read_manifest
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.io import check_no_earlier_output, write_image

__all__ = ["KINDS", "preview", "grid", "draw_model_box"]

_COLOURS = [(0, 255, 0), (255, 128, 0), (0, 128, 255), (255, 0, 255), (0, 255, 255), (255, 255, 0)]
#: The kinds of data-engine folders :func:`preview` draws.
KINDS = ("phos", "detect", "pose", "relief_scenes")


def grid(tiles: list[np.ndarray], cols: int, pad: int = 2) -> np.ndarray:
    """Arrange equally sized BGR tiles in a grid of ``cols`` columns (fewer when there are fewer tiles) with
    ``pad`` pixels of gray between them."""
    if not tiles:
        raise DatasetError("nothing to preview: the dataset has no images")
    cols = min(cols, len(tiles))  # a single row is as wide as its tiles, without empty columns
    h, w = tiles[0].shape[:2]
    rows = (len(tiles) + cols - 1) // cols
    out = np.full((rows * (h + pad) + pad, cols * (w + pad) + pad, 3), 64, np.uint8)
    for i, t in enumerate(tiles):
        r, c = divmod(i, cols)
        t = cv2.cvtColor(t, cv2.COLOR_GRAY2BGR) if t.ndim == 2 else t
        out[pad + r * (h + pad) : pad + r * (h + pad) + h, pad + c * (w + pad) : pad + c * (w + pad) + w] = t
    return out


def _label(img: np.ndarray, text: str, org: tuple[int, int] = (4, 14), scale: float = 0.45) -> None:
    """White text with a black outline (shifted copies: a thicker stroke would change the advance)."""
    x, y = org
    for dx, dy in ((-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (1, 1), (-1, 1), (1, -1)):
        cv2.putText(img, text, (x + dx, y + dy), cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1, cv2.LINE_AA)


def _phos(folder: Path, n: int) -> np.ndarray:
    from alcn_cv.data.phos import load

    batch = load(folder)
    tiles = []
    for i in _spread(len(batch), n):
        t = cv2.cvtColor(cv2.resize(batch.windows[i], (128, 128), interpolation=cv2.INTER_NEAREST), cv2.COLOR_GRAY2BGR)
        cv2.rectangle(t, (32, 32), (95, 95), (0, 200, 255), 1)  # the detector's 32x32 centre
        _label(t, f"{batch.labels[i]}" if batch.labels[i] else "bg")
        _label(t, batch.light_families[batch.light_ids[i]], (4, 122), 0.4)
        tiles.append(t)
    return grid(tiles, 8)


def _coco(paths: list[Path], n: int, thumb: int = 400) -> np.ndarray:
    from alcn_cv.formats.coco import load_coco

    tiles = []
    for path in paths:
        ds = load_coco(path)
        names = {c.id: c.name for c in ds.categories}
        take = ds.images[:: max(1, len(ds.images) // max(1, n // len(paths)))][: max(1, n // len(paths))]
        for im in take:
            img = ds.read_image(im)
            s = thumb / max(img.shape[:2])
            small = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
            for a in ds.annotations_for(im.id):
                x, y, w, h = a.bbox * s
                col = _COLOURS[(a.category_id - 1) % len(_COLOURS)]
                cv2.rectangle(small, (int(round(x)), int(round(y))), (int(round(x + w)), int(round(y + h))), col, 2)
                _label(small, names.get(a.category_id, str(a.category_id)), (int(x), max(12, int(y) - 4)), 0.4)
            _label(small, f"{path.stem} {im.extra.get('light_family', '')}".strip())
            th, tw = thumb * img.shape[0] // max(img.shape[:2]), thumb * img.shape[1] // max(img.shape[:2])
            tiles.append(cv2.resize(small, (tw, th)))
    return grid(tiles, 4)


def draw_model_box(
    img: np.ndarray,
    corners: np.ndarray,
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    colour: tuple[int, int, int] = (0, 255, 0),
    thickness: int = 2,
) -> None:
    """Draw the 12 edges of a 3D box (corners (8, 3) in the order of ``itertools.product``)."""
    pts, _ = cv2.projectPoints(corners.astype(np.float64), cv2.Rodrigues(R)[0], t.astype(np.float64), K, None)
    p = pts.reshape(-1, 2)
    for i in range(8):
        for b in (1, 2, 4):
            j = i ^ b
            if j > i:
                a = tuple(int(round(v * 16)) for v in p[i])
                c = tuple(int(round(v * 16)) for v in p[j])
                cv2.line(img, a, c, colour, thickness, cv2.LINE_AA, 4)


def _box_corners(vertices: np.ndarray) -> np.ndarray:
    lo, hi = vertices.min(0), vertices.max(0)
    return np.array([[(lo, hi)[a][0], (lo, hi)[b][1], (lo, hi)[c][2]] for a in (0, 1) for b in (0, 1) for c in (0, 1)])


def _spread(count: int, take: int) -> list[int]:
    """``min(take, count)`` indices spread evenly over ``range(count)``, first and last included."""
    return [int(i) for i in np.linspace(0, count - 1, min(take, count)).round()]


def _bop(scene_dirs: list[Path], models_dir: Path | None, n: int) -> np.ndarray:
    from alcn_cv.formats.bop import load_scene, read_ply

    if not scene_dirs:
        raise DatasetError("nothing to preview: the dataset has no sequences")
    scenes = [(d, load_scene(d)) for d in scene_dirs]
    # n frames in all, as many of every sequence (at least one), so that the sheet's rows line up by sequence
    per_scene = max(1, min(round(n / len(scenes)), min(len(s.frames) for _, s in scenes)))
    if len(scenes) == 1:
        cols = 4
    elif per_scene == 1:
        cols = 3  # one frame of each sequence: 3 x 3 for the 9 sequences of a pose dataset
    else:
        cols = per_scene * max(1, 4 // per_scene)  # whole sequences a row: two of two frames, one of three or more
    corners: dict[int, np.ndarray] = {}
    tiles = []
    for d, scene in scenes:
        for f in (scene.frames[i] for i in _spread(len(scene.frames), per_scene)):
            img = cv2.imread(str(f.rgb_path), cv2.IMREAD_COLOR)
            if img is None:
                raise DatasetError(f"{d / 'scene_camera.json'}: field {f.im_id}: cannot read {f.rgb_path}")
            for o in f.objects:
                if o.obj_id not in corners:
                    ply = models_dir / f"obj_{o.obj_id:06d}.ply" if models_dir else None
                    if ply is None or not ply.exists():
                        continue
                    corners[o.obj_id] = _box_corners(read_ply(ply).vertices)
                draw_model_box(img, corners[o.obj_id], f.K, o.R, o.t, _COLOURS[(o.obj_id - 1) % len(_COLOURS)])
            _label(img, f"{d.parent.name}/{d.name} #{f.im_id}", scale=0.6, org=(6, 20))
            s = 320 / img.shape[1]
            tiles.append(cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA))
    return grid(tiles, cols)


def _relief_scenes(folder: Path, n: int, side: int = 256) -> np.ndarray:
    """About ``n`` frames of ``alcn data scenes``: about sqrt(n) scenes, a row each, about sqrt(n) lights each."""
    from alcn_cv.data.relief_scenes import KIND

    lights = read_manifest(folder, KIND).get("lights", {})
    scenes = sorted(p for p in folder.glob("scene_*") if p.is_dir())
    rows = [scenes[i] for i in _spread(len(scenes), max(1, round(np.sqrt(n))))]
    per_scene = max(1, -(-n // max(1, len(rows))))
    tiles, cols = [], 1
    for d in rows:
        files = sorted(d.glob("frame_*.png"))
        chosen = _spread(len(files), per_scene)
        cols = max(cols, len(chosen))  # a scene of fewer frames than asked: its row is as long as its frames
        for j in chosen:
            img = cv2.imread(str(files[j]), cv2.IMREAD_GRAYSCALE)
            if img is None:
                raise DatasetError(f"{files[j]}: unreadable frame")
            small = cv2.resize(
                img, (side, side), interpolation=cv2.INTER_AREA if img.shape[0] > side else cv2.INTER_NEAREST
            )
            tile = cv2.cvtColor(small, cv2.COLOR_GRAY2BGR)
            _label(tile, f"{d.name} #{j}")
            families = lights.get(d.name, [])
            _label(tile, families[j] if j < len(families) else "", (4, side - 6), 0.4)
            tiles.append(tile)
    return grid(tiles, cols)


def preview(dataset: str | os.PathLike, out_png: str | os.PathLike, *, n: int = 16, overwrite: bool = False) -> Path:
    """Write a contact sheet of ``dataset`` with its ground truth drawn to ``out_png``.

    Args:
        dataset: a data-engine folder, a COCO JSON file, or a BOP scene folder.
        out_png: output PNG.
        n: how many samples to show: Phos windows, COCO images (at least one a file), BOP frames (as many of
            each sequence, at least one), frames of rendered scenes (about sqrt(n) scenes, sqrt(n) frames each).
        overwrite: replace an existing ``out_png``.

    Returns:
        ``out_png``.

    Raises:
        InputError: ``n`` below 1, no ``dataset``, ``out_png`` a folder, or ``out_png`` exists and not
            ``overwrite`` (all before reading the dataset).
        DatasetError: ``dataset`` is none of the kinds above, or is malformed.
    """
    if n < 1:
        raise InputError(f"the number of samples to show (-n) must be at least 1, got {n}")
    src, out = Path(dataset), Path(out_png)
    if not src.exists():
        raise InputError(f"{src}: no such file or folder")
    if out.is_dir():  # not "exists (--overwrite replaces it)": --overwrite would not replace a folder
        raise InputError(f"cannot write the contact sheet to {out}: a folder")
    check_no_earlier_output([out], overwrite)
    if src.is_file() and src.suffix == ".json":
        sheet = _coco([src], n)
    elif (src / "scene_camera.json").exists():
        models = src.parent.parent / "models"
        sheet = _bop([src], models if models.is_dir() else None, n)
    elif (src / "manifest.json").exists():
        kind = read_manifest(src)["kind"]
        if kind == "phos":
            sheet = _phos(src, n)
        elif kind == "detect":
            sheet = _coco([src / "train.json", src / "test.json"], n)
        elif kind == "pose":
            scenes = sorted(p for p in src.glob("*/*") if (p / "scene_camera.json").exists())
            sheet = _bop(scenes, src / "models", n)
        elif kind == "relief_scenes":
            sheet = _relief_scenes(src, n)
        else:
            raise DatasetError(
                f"{src / 'manifest.json'}: field kind: unknown dataset kind {kind!r}; "
                f"alcn data preview draws {', '.join(KINDS)}"
            )
    else:
        raise DatasetError(f"{src}: not a dataset (no manifest.json, scene_camera.json, and not a .json file)")
    return write_image(out, sheet)
