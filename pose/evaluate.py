"""``alcn pose eval``: pose accuracy under light changes (Table 1 of Rad et al., BMVC 2017).

Metrics of one estimated pose against the ground truth (both object-to-camera):

* 2D projection: mean distance in pixels between the model's vertices projected with both
  poses; correct under 5 px (as in BB8, Rad & Lepetit, ICCV 2017);
* ADD: mean 3D distance between the model's vertices transformed by both poses; correct under
  10% of the model's diameter (Hinterstoisser et al., ACCV 2012);
* 5 cm / 5 deg: rotation error under 5 degrees and translation error under 5 cm
  (Shotton et al., CVPR 2013).

A lost frame counts as wrong. :func:`main` writes the Table-1-style report (rows: normalization x
detector, columns: sequences #1..#8, cells: % correct by the 2D projection metric; ADD and
5cm/5deg in the JSON) as Markdown, JSON and PNG. :func:`middlebury_main` evaluates real
photographs: a model built from 8 of the 16 calibrated views, the pose of the 8 others from
their images alone, also after a synthetic light change.
"""

from __future__ import annotations

import logging
import re
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from alcn_cv.checks import check_seeds
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.io import atomic_write, holds_out_dir, make_folder, write_json
from alcn_cv.report import describe_machine, machine, markdown_table, nan_to_none
from pose.box import box_diameter
from pose.build import build as build_model
from pose.corner_train import CONFS as CORNER_CONFS
from pose.corner_train import CornerRecipe
from pose.model import read_box_corners, unit_scale
from pose.model import save as save_model
from pose.parts import FeaturePartDetector, PartDetector
from pose.plots import plot_table
from pose.sequence import check_known_units, load_sequence
from pose.solver import PoseSolver, project, rotation_error_deg
from pose.track import make_tracker

logger = logging.getLogger(__name__)

PROJ_PX = 5.0
ADD_FRACTION = 0.1
DEG, CM = 5.0, 5.0


def projection_error(
    vertices: np.ndarray, R: np.ndarray, t: np.ndarray, R_gt: np.ndarray, t_gt: np.ndarray, K: np.ndarray
) -> float:
    """Mean 2D distance (px) between ``vertices (N, 3)`` projected with both poses."""
    a = project(vertices, cv2.Rodrigues(np.asarray(R, np.float64))[0], np.asarray(t, np.float64), K)
    b = project(vertices, cv2.Rodrigues(np.asarray(R_gt, np.float64))[0], np.asarray(t_gt, np.float64), K)
    return float(np.linalg.norm(a - b, axis=1).mean())


def add_error(vertices: np.ndarray, R: np.ndarray, t: np.ndarray, R_gt: np.ndarray, t_gt: np.ndarray) -> float:
    """Mean 3D distance between ``vertices`` under both poses (ADD), in the vertices' units."""
    v = np.asarray(vertices, np.float64)
    a = v @ np.asarray(R).T + np.ravel(t)
    b = v @ np.asarray(R_gt).T + np.ravel(t_gt)
    return float(np.linalg.norm(a - b, axis=1).mean())


@dataclass
class PoseScore:
    """Errors of one frame; ``None`` errors for a lost frame."""

    proj_px: float | None
    add: float | None
    rot_deg: float | None
    trans_cm: float | None

    def correct(self, diameter: float) -> dict[str, bool]:
        if self.proj_px is None:
            return {"proj2d": False, "add": False, "5cm5deg": False}
        return {
            "proj2d": self.proj_px < PROJ_PX,
            "add": self.add < ADD_FRACTION * diameter,
            "5cm5deg": self.rot_deg < DEG and self.trans_cm < CM,
        }


def score(
    vertices: np.ndarray,
    K: np.ndarray,
    units: str,
    est: tuple[np.ndarray, np.ndarray] | None,
    gt: tuple[np.ndarray, np.ndarray],
) -> PoseScore:
    """Errors of the pose ``est = (R, t)`` (``None`` when lost) against ``gt``; lengths in ``units``."""
    if est is None:
        return PoseScore(None, None, None, None)
    R, t = est
    R_gt, t_gt = gt
    return PoseScore(
        projection_error(vertices, R, t, R_gt, t_gt, K),
        add_error(vertices, R, t, R_gt, t_gt),
        rotation_error_deg(R, R_gt),
        float(np.linalg.norm(np.ravel(t) - np.ravel(t_gt)) * unit_scale(units, "cm")),
    )


def summarize(scores: list[PoseScore], diameter: float) -> dict[str, float]:
    """Percentages of correct poses by each metric, and the share of tracked frames."""
    if not scores:
        return {"proj2d": float("nan"), "add": float("nan"), "5cm5deg": float("nan"), "tracked": float("nan")}
    c = [s.correct(diameter) for s in scores]
    out = {k: 100.0 * float(np.mean([x[k] for x in c])) for k in ("proj2d", "add", "5cm5deg")}
    out["tracked"] = 100.0 * float(np.mean([s.proj_px is not None for s in scores]))
    return out


# --------------------------------------------------------------------------------------------
# Table 1 on BOP pose sequences
# --------------------------------------------------------------------------------------------


#: The rows of the default report: no normalization, a DoG tuned for pose, ALCN. The DoG's sigmas
#: (pixels of the 640x480 frames) gave the most correct poses of the pairs tried on the data engine's
#: sequences #1-#8 (``docs/journal.md`` has the measurements).
DEFAULT_NORMALIZATIONS = ("none", "dog:sigma1=1:sigma2=2", "alcn")


def evaluate_sequence(
    detector: PartDetector,
    scene_dir: Path,
    obj_id: int,
    vertices: np.ndarray,
    units: str,
    kind: str = "features",
    outline: np.ndarray | None = None,
) -> tuple[list[PoseScore], float]:
    """Track with ``detector`` (a part detector of :mod:`pose.parts` or :mod:`pose.corners`, of ``kind``
    ``"features"`` or ``"corners"``) through a BOP test scene, as ``alcn pose track`` does
    (:func:`pose.track.make_tracker`), and score every frame; returns scores and fps. ``outline``: the
    detector's box corners for :class:`pose.solver.PoseSolver` (its coverage check)."""
    from alcn_cv import io
    from alcn_cv.formats import bop

    scene = bop.load_scene(scene_dir)
    tracker = None
    scores, t_total = [], 0.0
    for fr in scene.frames:
        if tracker is None:
            tracker = make_tracker(kind, fr.K, outline)
        img = io.read_image(fr.rgb_path)
        t0 = time.perf_counter()
        est, _ = tracker.step(fr.im_id, img, detector)
        t_total += time.perf_counter() - t0
        index = fr.object_index(obj_id)
        if index is None:
            raise DatasetError(f"{scene_dir}: object {obj_id} is not annotated in frame {fr.im_id} (scene_gt.json)")
        gt = fr.objects[index]
        scores.append(score(vertices, fr.K, units, (est.R, est.tvec) if est.ok else None, (gt.R, gt.t)))
    return scores, len(scene.frames) / max(t_total, 1e-9)


def file_stem(spec: str) -> str:
    """A file-name-safe form of a normalization spec: ``"alcn:model=lite"`` -> ``"alcn_model-lite"``."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", spec.replace("=", "-"))


def table_markdown(
    table: dict[str, dict[str, float]], columns: list[str], spread: dict[str, dict[str, float]] | None = None
) -> str:
    """The Table-1-style report as Markdown: one row per ``table`` key, percentages with one
    decimal (``mean ± spread`` where ``spread`` has the cell), ``-`` where a column is missing or NaN."""

    def cell(row: str, c: str) -> Any:
        value = table[row].get(c, np.nan)
        if value is None or np.isnan(value):
            return None
        dev = (spread or {}).get(row, {}).get(c)
        return float(value) if dev is None else f"{value:.1f} ± {dev:.1f}"

    return markdown_table(["", *columns], [[row, *(cell(row, c) for c in columns)] for row in table], digits=1)


def data_layout(
    data_dir: str | Path, obj_id: int = 1, sequences: Sequence[int] | None = None
) -> tuple[Path, list[Path], Path]:
    """The training sequence, the test sequences (those numbered in ``sequences``, default all) and the box's model
    of a pose data set (``alcn data pose``), checked before any work.

    Raises:
        InputError: no folder ``data_dir``.
        DatasetError: a folder without ``train/000001``, those test sequences or ``models/obj_<obj_id>.ply``.
    """
    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        what = "not a folder" if data_dir.exists() else "no such folder"
        raise InputError(f"{data_dir}: {what}; --data is a pose data set of `alcn data pose`")
    train = data_dir / "train" / "000001"
    tests = sorted(p for p in (data_dir / "test").glob("[0-9]*") if p.is_dir()) if (data_dir / "test").is_dir() else []
    if sequences:
        tests = [p for p in tests if int(p.name) in set(sequences)]
    model_ply = data_dir / "models" / f"obj_{obj_id:06d}.ply"
    if not train.is_dir() or not tests or not model_ply.is_file():
        raise DatasetError(
            f"{data_dir}: expected train/000001, test/0000NN (those of --sequences) and "
            f"models/obj_{obj_id:06d}.ply (`alcn data pose`)"
        )
    return train, tests, model_ply


@holds_out_dir
def main(
    data_dir: str | Path,
    out_dir: str | Path,
    *,
    normalizations: list[str] | tuple[str, ...] = DEFAULT_NORMALIZATIONS,
    feature: str = "SIFT",
    obj_id: int = 1,
    n_features: int = 2000,
    detectors: list[str] | tuple[str, ...] = ("features",),
    corner_recipe: CornerRecipe | None = None,
    corner_conf: str | None = None,
    corner_device: str | None = None,
    seeds: Sequence[int] = (0,),
    sequences: list[int] | None = None,
    command: str | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Table-1-style evaluation on a pose data set (``train/000001``, ``test/0000NN``, ``models/``).

    For each detector (``"features"``: :class:`pose.parts.FeaturePartDetector`, ``"corners"``:
    :class:`pose.corners.CornerDetector`) and normalization: a part model is built, or the corner
    detector trained once per seed of ``seeds`` (:func:`pose.corner_train.train_corners` by ``corner_recipe``,
    default the ``box`` preset, recorded as ``corner_conf``, on ``corner_device``; with several seeds a cell is
    the mean over them, its spread their standard deviation), from the
    training sequence on normalized images, then tracked through every test
    sequence (or those numbered in ``sequences``). Writes ``table1.md`` (with the machine and
    ``command``), ``table1.json``, ``table1.png`` (and the models; a folder with an earlier ``table1.json`` loses
    that run's ``model_*.npz`` and ``corners_*.onnx``) into ``out_dir``;
    ``progress``: a progress bar over the models.

    Raises:
        DatasetError: ``data_dir`` is not such a data set (:func:`data_layout`); a part model's box fit too far off
            the box (:func:`pose.build.build`; the message says what to change).
        InputError: no folder ``data_dir``; its training sequence registered in arbitrary units
            (:func:`pose.sequence.check_known_units`), before any model is made; an unknown detector.
    """
    data_dir, out_dir = Path(data_dir), Path(out_dir)
    train, tests, model_ply = data_layout(data_dir, obj_id, sequences)
    make_folder(out_dir)
    if corner_recipe is None:
        corner_recipe, corner_conf = CORNER_CONFS["box"], "box"
    seeds = check_seeds(seeds)
    # the models and corner detectors are made from the training sequence's poses: in known units, checked first
    check_known_units(load_sequence(train, obj_id=obj_id), "alcn pose eval (its models are built from these poses)")
    corners = read_box_corners(model_ply)
    diameter = box_diameter(corners)
    columns = [f"#{int(p.name)}" for p in tests]
    table: dict[str, dict[str, float]] = {}
    spread: dict[str, dict[str, float]] = {}
    details: dict[str, Any] = {}
    unknown = set(detectors) - {"features", "corners"}
    if unknown:
        raise InputError(f"unknown detectors {sorted(unknown)}; choose 'features' and/or 'corners'")
    if (out_dir / "table1.json").is_file():  # an earlier evaluation's folder: its models, of other normalizations
        for earlier in [*out_dir.glob("model_*.npz"), *out_dir.glob("corners_*.onnx")]:
            earlier.unlink()
    t_start = time.perf_counter()
    bar = tqdm(total=len(detectors) * len(normalizations), desc="pose eval", unit="model", disable=not progress)
    for det_name in detectors:
        for name in normalizations:
            runs = []  # per seed: (detector, units, outline, info)
            if det_name == "features":
                seq = load_sequence(train, obj_id=obj_id)
                # what the user of `alcn pose eval` can change when the points do not fit the data set's box
                fit_hint = (
                    f"after the normalization {name}, {train}'s {len(seq.views)} views gave too few points of the box "
                    f"{model_ply.name}, or its poses are not that box's; make the data set with more frames (`alcn "
                    "data pose --frames 12` or more), or try another --feature, or leave this normalization out"
                )
                model, _ = build_model(
                    seq,
                    feature=feature,
                    normalization=name,
                    box_ply=model_ply,
                    work_dir=out_dir,
                    fit_hint=fit_hint,
                    progress=progress,
                )
                save_model(model, out_dir / f"model_{file_stem(name)}.npz")
                row = f"{name} / {feature.lower()} features"
                runs.append(
                    (
                        FeaturePartDetector(model, name, n_features=n_features),
                        model.units,
                        model.corners,
                        {"model_points": len(model.points3d), "box_fit": model.box_fit},
                    )
                )
            else:
                from pose.corner_train import train_corners
                from pose.corners import CornerDetector

                row = f"{name} / corner CNN"
                for seed in seeds:
                    t0 = time.perf_counter()
                    suffix = f"_seed{seed}" if len(seeds) > 1 else ""
                    net = train_corners(
                        train,
                        corners,
                        out_dir / f"corners_{file_stem(name)}{suffix}.onnx",
                        corner_recipe,
                        normalization=name,
                        obj_id=obj_id,
                        seed=seed,
                        device=corner_device,
                        conf=corner_conf,
                        progress=False,
                    )
                    det = CornerDetector(net)
                    runs.append(
                        (
                            det,
                            det.units,  # its training sequence's (pose.corner_train.train_corners)
                            det.corners,
                            {"training_seconds": time.perf_counter() - t0, "detector": str(net)},
                        )
                    )
            per_run = []
            for det, units, outline, info in runs:
                result = {**info, "sequences": {}}
                for col, scene_dir in zip(columns, tests):
                    scores, fps = evaluate_sequence(
                        det,
                        scene_dir,
                        obj_id,
                        corners,
                        units,
                        det_name,
                        outline,
                    )
                    s = summarize(scores, diameter)
                    result["sequences"][col] = {**s, "fps": fps, "frames": len(scores)}
                    logger.info("%s %s: %.1f%% correct (2D proj.), %.1f%% tracked", row, col, s["proj2d"], s["tracked"])
                per_run.append(result)
            values = {c: [r["sequences"][c]["proj2d"] for r in per_run] for c in columns}
            table[row] = {c: float(np.mean(v)) for c, v in values.items()}
            if len(per_run) > 1:
                spread[row] = {c: float(np.std(v)) for c, v in values.items()}
            details[row] = (
                per_run[0]
                if len(per_run) == 1
                else {"seeds": per_run, "proj2d_per_seed": values, "proj2d_std": spread[row]}
            )
            bar.update()
    bar.close()
    host = machine()
    md = (
        "# Pose under light changes (Table 1 style)\n\n"
        f"Data: `{data_dir}`; cells: % of frames with 2D projection error < {PROJ_PX:g} px "
        f"(ADD < {ADD_FRACTION:g} d and 5 cm / 5 deg in table1.json)"
        + (
            f"; corner CNN rows: mean ± standard deviation over training seeds {', '.join(map(str, seeds))}"
            if len(seeds) > 1
            else ""
        )
        + f".\n\nMachine: {describe_machine(host)}. Wall time: {time.perf_counter() - t_start:.0f} s."
        + (f"\n\nCommand: `{command}`" if command else "")
        + "\n\n"
        + table_markdown(table, columns, spread)
    )
    atomic_write(out_dir / "table1.md", md)
    write_json(
        out_dir / "table1.json",
        nan_to_none(
            {
                "data": str(data_dir),
                "machine": host,
                "command": command,
                "columns": columns,
                "table": table,
                "spread": spread,
                "seeds": seeds,
                "details": details,
                "corner_conf": corner_conf if "corners" in detectors else None,
                "corner_recipe": asdict(corner_recipe) if "corners" in detectors else None,
                "metrics": {"proj2d_px": PROJ_PX, "add": ADD_FRACTION, "deg": DEG, "cm": CM},
            }
        ),
    )
    plot_table(table, columns, out_dir / "table1.png", f"Correct poses (2D projection < {PROJ_PX:g} px)", spread)
    return {"table": table, "spread": spread, "details": details}


# --------------------------------------------------------------------------------------------
# Middlebury: real photographs with calibrated poses
# --------------------------------------------------------------------------------------------


def relight(image: np.ndarray, seed: int = 0) -> np.ndarray:
    """A synthetic light change: darker and with a strong horizontal gradient and a gamma change.

    ``I' = 255 * (g(x) * (I / 255)) ** gamma`` with ``g`` from 0.25 to 1.1 across the image and
    ``gamma = 1.6``; uint8 in, uint8 out.
    """
    rng = np.random.default_rng(seed)
    h, w = image.shape[:2]
    flip = rng.random() < 0.5
    ramp = np.linspace(0.25, 1.1, w)[:: -1 if flip else 1]
    g = np.tile(ramp, (h, 1))
    if image.ndim == 3:
        g = g[..., None]
    out = 255.0 * np.clip(g * image.astype(np.float32) / 255.0, 0, 1) ** 1.6
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def _points(count: int | None) -> str:
    """A model's points in the Middlebury table: their number, or "none" where no model was built."""
    return "none" if count is None else str(count)


@holds_out_dir
def middlebury_main(
    sets: list[str | Path],
    out_dir: str | Path,
    *,
    normalizations: list[str] | tuple[str, ...] = DEFAULT_NORMALIZATIONS,
    feature: str = "SIFT",
    n_features: int = 8000,
    ratio: float = 0.9,
    min_inliers: int = 12,
    iterations: int = 10000,
    command: str | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Pose every view of each set from a model of the views on either side: a model built from the even views
    poses the odd ones, a model from the odd views the even ones (two folds, each view posed once).

    The views are 22.5 degrees apart, so a model's views are 45 degrees apart and a posed view is
    22.5 degrees from the nearest: a loose ratio test (``ratio``) keeps enough matches, mutual
    nearest neighbours (``FeaturePartDetector(cross_check=True)``) drop most wrong ones (the
    models have about a hundred points, the views 8000 keypoints), and RANSAC gets many
    ``iterations`` for the remaining low inlier ratios (8-25%). Without the cross-check, keeping wrong poses
    (8-15 deg) out takes a ``min_inliers`` of 20, which poses few views at all. A pose is *correct* within Table 1's
    5 deg and 5 cm (:data:`DEG`, :data:`CM`); one found further off is counted as posed, not correct.

    Reports per normalization and condition (original / relit) the views posed and posed correctly, the median
    rotation (deg), translation (mm) and camera-centre (mm) errors over the posed views and the two models' points,
    as ``middlebury.md`` and ``middlebury.json`` in ``out_dir`` (with the machine and ``command``, the command line
    that ran it); ``progress``: a progress bar over the models. A model that cannot be built (too few points, a
    :class:`~alcn_cv.errors.DatasetError` of :func:`pose.build.build`) poses none of its views: logged, its points
    ``None`` ("none" in the table), and the run goes on with the other normalizations.
    """
    from alcn_cv import io
    from alcn_cv.formats.middlebury import read_middlebury

    out_dir = Path(out_dir)
    make_folder(out_dir)
    results: dict[str, Any] = {}
    lines = [
        "# Middlebury: each view posed from a model of the views on either side (two folds)\n",
        f"Each view of a set is posed from a model of {feature} keypoints built from the views on either side: the "
        "even views' model poses the odd views, the odd views' model the even ones. Light: the photographs as taken "
        "(`original`) or darkened by a horizontal ramp and a gamma of 1.6 (`relit`). Correct: within "
        f"{DEG:g} deg and {CM:g} cm of the set's calibrated pose; posed: any pose RANSAC found. Errors: medians over "
        "the posed views; model points: the two models' 3D points.\n",
        f"| set | normalization | light | correct ({DEG:g} deg, {CM:g} cm) | posed | median rot. err (deg) | "
        "median trans. err (mm) | median centre err (mm) | model points |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    bar = tqdm(total=len(sets) * len(normalizations) * 2, desc="middlebury", unit="model", disable=not progress)
    for set_dir in sets:
        set_dir = Path(set_dir)
        views = read_middlebury(set_dir)
        for name in normalizations:
            errs: dict[str, list[tuple[float, float, float]]] = {"original": [], "relit": []}
            model_points: list[int | None] = []
            for fold in (0, 1):
                model_names = {v.name for v in views[fold::2]}
                seq = load_sequence(set_dir)
                seq.views = [v for v in seq.views if v.name in model_names]
                try:
                    model, _ = build_model(
                        seq,
                        feature=feature,
                        n_features=n_features,
                        normalization=name,
                        ratio=ratio,
                        work_dir=out_dir,
                        progress=progress,
                    )
                except DatasetError as exc:  # too few points for a model: the other normalizations still compare
                    logger.warning(
                        "%s, %s: no model of the views %s (%s); the views it would pose count as not posed",
                        set_dir.name,
                        name,
                        "even" if fold == 0 else "odd",
                        exc,
                    )
                    model_points.append(None)
                    bar.update()
                    continue
                model_points.append(len(model.points3d))
                det = FeaturePartDetector(model, name, n_features=n_features, ratio=ratio, cross_check=True)
                for k, v in enumerate(views):
                    if v.name in model_names:
                        continue
                    img = io.read_image(v.path)
                    for light, errors in errs.items():
                        corr = det.detect(relight(img, seed=k) if light == "relit" else img)
                        est = PoseSolver(v.K, min_inliers=min_inliers, iterations=iterations).solve(
                            corr.object_points, corr.image_points
                        )
                        if est.ok:
                            c = -est.R.T @ est.tvec.ravel()
                            errors.append(
                                (
                                    rotation_error_deg(est.R, v.R_w2c),
                                    1000 * float(np.linalg.norm(est.tvec.ravel() - v.t_w2c)),
                                    1000 * float(np.linalg.norm(c - v.center)),
                                )
                            )
                bar.update()
            for light, errors in errs.items():
                e = np.array(errors).reshape(-1, 3)
                med = np.median(e, 0) if len(e) else np.full(3, np.nan)
                correct = int(np.sum((e[:, 0] < DEG) & (e[:, 1] < 10 * CM)))
                key = f"{set_dir.name}/{name}/{light}"
                results[key] = {
                    "posed": len(e),
                    "correct": correct,
                    "views": len(views),
                    "errors": e.tolist(),
                    "median_rot_deg": med[0],
                    "median_trans_mm": med[1],
                    "median_center_mm": med[2],
                    "model_points": model_points,
                }
                lines.append(
                    f"| {set_dir.name} | {name} | {light} | {correct}/{len(views)} | {len(e)}/{len(views)} | "
                    f"{med[0]:.2f} | {med[1]:.1f} | {med[2]:.1f} | {' / '.join(_points(p) for p in model_points)} |"
                )
                logger.info(
                    "%s: %d/%d posed, %d correct, median rot %.2f deg, trans %.1f mm",
                    key,
                    len(e),
                    len(views),
                    correct,
                    med[0],
                    med[1],
                )
    bar.close()
    host = machine()
    lines.append(f"\nMachine: {describe_machine(host)}." + (f" Command: `{command}`" if command else ""))
    atomic_write(out_dir / "middlebury.md", "\n".join(lines) + "\n")
    write_json(out_dir / "middlebury.json", nan_to_none({**results, "machine": host, "command": command}))
    return results
