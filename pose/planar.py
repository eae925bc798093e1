"""``alcn pose planar``: pose of a planar target under real light changes (a real-light Table 1).

Rendered light is not real light. The frames of a fixed outdoor camera (the Webcam data set of
Verdie et al., "TILDE: A Temporally Invariant Learned DEtector", CVPR 2015) are taken at other
times of day and seasons with the camera unmoved, so they give real light changes with a known
truth. For each scene:

1. a *reference frame* (default: the one of median mean brightness, a typical daylight frame)
   and in it a textured rectangle, the *target* (default: the window of
   ``target_fraction`` of the frame's width and height holding the most keypoints of the
   reference frame itself, :func:`select_region`);
2. the target's part model (:class:`pose.model.PartModel`): an assumed pinhole camera
   (:func:`pinhole_camera`, ``hfov`` degrees), the target a fronto-parallel plane at depth ``f``
   so that one object unit (``mm``) is one reference pixel, its 4 corners the box's (a flat box),
   the keypoints of the *normalized* reference frame inside it back-projected on the plane, one
   descriptor each (:func:`build_target`). The classical pipeline's triangulation over
   several views (:mod:`pose.build`) has nothing to add here: every frame is seen from the
   same viewpoint, and training views under other lights would defeat the experiment
   (Table 1 trains under one light);
3. in every other frame of the scene, the pose of the target by the box's pipeline: the part
   detector (:class:`pose.parts.FeaturePartDetector`, every keypoint of the frame, no prior:
   the frames are not a video) and :class:`pose.solver.PoseSolver` with the settings of
   ``alcn pose eval`` (:func:`pose.track.make_solver`, the target's corners as the outline);
4. the truth is the reference pose; a pose is correct when the target's corners reproject
   within 5 px of their reference positions on average (:func:`pose.evaluate.score`, the 2D
   projection metric of ``alcn pose eval``; the JSON also has the share with *every* corner
   within 5 px). A lost frame counts as wrong.

The part detector is a factory of :data:`DETECTORS`: ``"features"``, the classical detector,
or ``"corners"``, the learned corner detector of the box (:mod:`pose.corners`) trained for the
target from the reference frame alone, as the box's is from its training sequence under one
light (:func:`corner_detector`, the ``planar`` recipe of :data:`pose.corner_train.CONFS`): its 8
parts are the target's 4 corners and the middles of its 4 sides (:func:`target_parts`; 4 parts
would leave PnP nothing to check a pose with).

The Webcam frames are for academic research only (cite TILDE and AMOS).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from alcn_cv.data.scenes import Scene, load_scene_folder, select_scenes
from alcn_cv.enhance.registry import from_spec
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.io import atomic_write, holds_out_dir, make_folder, to_gray, write_json
from alcn_cv.report import describe_machine, machine, markdown_table, nan_to_none, new_figure, save_figure
from alcn_cv.shared_data import default_folder, missing_folder
from pose.corner_train import CONFS as CORNER_CONFS
from pose.corner_train import CornerRecipe
from pose.evaluate import PROJ_PX, score, table_markdown
from pose.model import PartModel, box_corners
from pose.parts import FeaturePartDetector, PartDetector, create_feature
from pose.plots import plot_table
from pose.solver import camera_matrix, project
from pose.track import make_solver

logger = logging.getLogger(__name__)

#: The rows of the real-light table: no normalization, the DoG tuned for pose (as ``alcn pose
#: eval``), DLCN and Tan-Triggs (the strongest classical methods of ``alcn bench relight``), the
#: default ALCN (the gain-adaptive Normalizer trained on real webcam frames) and the lite one distilled
#: from the paper's, trained on rendered data.
DEFAULT_NORMALIZATIONS = ("none", "dog:sigma1=1:sigma2=2", "dlcn", "tantriggs", "alcn", "alcn:model=lite")
#: Assumed horizontal field of view (degrees) of the webcams, whose intrinsics are unknown.
DEFAULT_HFOV = 60.0
#: Side of the target as a fraction of the frame's width and height.
DEFAULT_TARGET_FRACTION = 0.5


def pinhole_camera(width: int, height: int, hfov_deg: float = DEFAULT_HFOV) -> np.ndarray:
    """Intrinsics ``(3, 3)`` of a pinhole camera with square pixels, the principal point at the
    image centre (OpenCV convention) and a horizontal field of view of ``hfov_deg`` degrees."""
    if not 0 < hfov_deg < 180:
        raise InputError(f"hfov must be in (0, 180) degrees, got {hfov_deg}")
    f = 0.5 * width / np.tan(np.radians(hfov_deg) / 2)
    return camera_matrix(f, f, (width - 1) / 2, (height - 1) / 2)


def reference_index(frames: np.ndarray) -> int:
    """The frame of median mean brightness among ``frames (n, H, W)``: a typical daylight frame,
    neither night nor glare."""
    means = frames.reshape(len(frames), -1).mean(1)
    return int(np.argsort(means)[len(means) // 2])


def select_region(
    gray: np.ndarray, fraction: float = DEFAULT_TARGET_FRACTION, feature: str = "SIFT"
) -> tuple[int, int, int, int]:
    """``(x, y, w, h)``: the window of ``fraction`` of the image's width and height that holds the
    most keypoints of ``gray`` (uint8, as it is: every normalization gets the same target), searched on a grid of
    1/20 of the image, 8 px from the borders (where a descriptor has no room)."""
    if not 0 < fraction <= 1:
        raise InputError(f"the target fraction must be in (0, 1], got {fraction}")
    h, w = gray.shape[:2]
    tw, th = max(int(round(fraction * w)), 16), max(int(round(fraction * h)), 16)
    margin = 8
    kps = create_feature(feature, 0).detect(gray, None)
    count = np.zeros((h + 1, w + 1), np.float64)
    pts = np.array([k.pt for k in kps], np.float64).reshape(-1, 2).astype(int)
    np.add.at(count, (np.minimum(pts[:, 1], h - 1) + 1, np.minimum(pts[:, 0], w - 1) + 1), 1)
    integral = count.cumsum(0).cumsum(1)
    best, best_n = (margin, margin), -1.0
    xs = np.unique(np.linspace(margin, max(w - tw - margin, margin), 21).astype(int))
    ys = np.unique(np.linspace(margin, max(h - th - margin, margin), 21).astype(int))
    for y in ys:
        for x in xs:
            x1, y1 = min(x + tw, w), min(y + th, h)
            n = integral[y1, x1] - integral[y, x1] - integral[y1, x] + integral[y, x]
            if n > best_n:
                best, best_n = (int(x), int(y)), n
    return best[0], best[1], min(tw, w - best[0]), min(th, h - best[1])


@dataclass
class PlanarTarget:
    """A planar target in a reference frame and its part model.

    Attributes:
        model: the part model (object frame: the plane ``z = 0``, origin at the region's top-left
            corner, ``mm`` = reference pixels; a flat box whose 4 distinct corners are the target's).
        K: the assumed intrinsics.
        rvec, tvec: the reference pose (object to camera), the truth of every frame of the scene.
        region: ``(x, y, w, h)`` of the target in the reference frame.
        reference: the reference frame's name.
        image: the reference frame, gray uint8 (training data of a learned detector).
    """

    model: PartModel
    K: np.ndarray
    rvec: np.ndarray
    tvec: np.ndarray
    region: tuple[int, int, int, int]
    reference: str = ""
    image: np.ndarray | None = None

    @property
    def corners(self) -> np.ndarray:
        """The target's 4 corners ``(4, 3)`` in the object frame (the flat box's distinct corners)."""
        return np.unique(self.model.corners, axis=0)

    def image_corners(self) -> np.ndarray:
        """The 4 corners ``(4, 2)`` projected with the reference pose (pixels)."""
        return project(self.corners, self.rvec, self.tvec, self.K)


def build_target(
    image: np.ndarray,
    region: tuple[int, int, int, int],
    K: np.ndarray,
    normalization: str = "none",
    *,
    feature: str = "SIFT",
    reference: str = "",
) -> PlanarTarget:
    """The part model of the rectangle ``region = (x, y, w, h)`` of ``image`` (BGR or gray uint8).

    The keypoints of the normalized image (the same normalization and feature as the part
    detector's, :meth:`pose.parts.FeaturePartDetector.normalize`) inside the region are
    back-projected onto the fronto-parallel plane at depth ``K[0, 0]`` (object units: ``mm``, one
    per reference pixel), one descriptor per point.

    Raises:
        DatasetError: fewer than 4 keypoints in the region.
    """
    x, y, w, h = (int(v) for v in region)
    gray = to_gray(image)
    if w <= 0 or h <= 0 or x < 0 or y < 0 or x + w > gray.shape[1] or y + h > gray.shape[0]:
        raise InputError(f"region {region} is not inside the {gray.shape[1]}x{gray.shape[0]} image")
    K = np.asarray(K, np.float64)
    mask = np.zeros(gray.shape, np.uint8)
    mask[y : y + h, x : x + w] = 255
    det = create_feature(feature, 0)  # every keypoint of the region: the target's descriptors
    kps, desc = det.detectAndCompute(from_spec(normalization).apply(gray), mask)
    if desc is None or len(kps) < 4:
        raise DatasetError(f"only {len(kps)} {feature} keypoints in the target region {region}; choose a textured one")
    uv = np.array([k.pt for k in kps], np.float64)
    depth = K[0, 0]
    # object frame: x right, y down, z away from the camera; 1 unit = 1 reference pixel at the plane
    points = np.c_[(uv - [x, y]) * [depth / K[0, 0], depth / K[1, 1]], np.zeros(len(uv))]
    rvec = np.zeros((3, 1))
    tvec = np.array([[(x - K[0, 2]) * depth / K[0, 0]], [(y - K[1, 2]) * depth / K[1, 1]], [depth]])
    size = np.array([w * depth / K[0, 0], h * depth / K[1, 1], 0.0])
    model = PartModel(
        corners=box_corners(size),
        points3d=points.astype(np.float32),
        descriptors=desc,
        units="mm",
        feature=feature.upper(),
        normalization=normalization,
        source=reference,
        extra={"K": K.tolist(), "region": [x, y, w, h], "planar": True},
    )
    return PlanarTarget(model, K, rvec, tvec, (x, y, w, h), reference, gray)


def feature_detector(
    target: PlanarTarget,
    normalization: str,
    n_features: int = 0,
    work_dir: Path | None = None,
    recipe: CornerRecipe | None = None,
) -> PartDetector:
    """The classical part detector of the target: every keypoint of a frame (``n_features=0``)
    matched to the target's descriptors (:class:`pose.parts.FeaturePartDetector`); ``work_dir``
    and ``recipe`` unused (nothing to train)."""
    return FeaturePartDetector(target.model, normalization, n_features_global=n_features)


def target_parts(target: PlanarTarget) -> tuple[np.ndarray, np.ndarray]:
    """The learned detector's 8 parts of the target: its corners and the middles of its sides, in
    turn around it; ``(8, 3)`` in the object frame and ``(8, 2)`` their reference pixels."""
    w, h = np.ptp(target.corners[:, :2], axis=0)
    xy = np.array([[0, 0], [0.5, 0], [1, 0], [1, 0.5], [1, 1], [0.5, 1], [0, 1], [0, 0.5]]) * [w, h]
    parts = np.c_[xy + target.corners[:, :2].min(0), np.zeros(len(xy))]
    return parts, project(parts, target.rvec, target.tvec, target.K)


def corner_detector(
    target: PlanarTarget,
    normalization: str,
    n_features: int = 0,
    work_dir: Path | None = None,
    recipe: CornerRecipe | None = None,
) -> PartDetector:
    """The learned corner detector of the target (:class:`pose.corners.CornerDetector`), trained
    on the reference frame after ``normalization`` by ``recipe`` (default: the ``planar`` preset of
    :data:`pose.corner_train.CONFS`) and written to ``work_dir`` (default: a temporary folder);
    ``n_features`` unused."""
    import tempfile

    from pose.corner_train import train_image_corners
    from pose.corners import CornerDetector
    from pose.evaluate import file_stem

    if target.image is None:
        raise InputError("the target has no reference image to train a detector on")
    parts, uv = target_parts(target)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(work_dir or tmp) / f"corners_{Path(target.reference).stem}_{file_stem(normalization)}.onnx"
        train_image_corners(
            target.image,
            uv,
            parts,
            target.model.corners,
            path,
            recipe,
            normalization=normalization,
            source=target.reference,
            conf=None if recipe else "planar",
            progress=False,
        )
        return CornerDetector(path)


#: Part detectors by name: ``(target, normalization, n_features, work_dir, recipe) -> PartDetector``.
DETECTORS: dict[str, Callable[[PlanarTarget, str, int, Path | None, CornerRecipe | None], PartDetector]] = {
    "features": feature_detector,
    "corners": corner_detector,
}


def row_label(normalization: str, detector: str, feature: str = "SIFT") -> str:
    """The table's row of a normalization and a detector of :data:`DETECTORS`."""
    return f"{normalization} / " + (f"{feature.lower()} features" if detector == "features" else "corner CNN")


@dataclass
class FrameResult:
    """The pose of the target in one frame against the reference pose."""

    name: str
    proj_px: float | None
    max_corner_px: float | None
    inliers: int
    matches: int
    seconds: float


def evaluate_scene(
    scene: Scene,
    normalization: str,
    *,
    detector: str = "features",
    feature: str = "SIFT",
    n_features: int = 0,
    region: tuple[int, int, int, int],
    hfov: float = DEFAULT_HFOV,
    work_dir: Path | None = None,
    recipe: CornerRecipe | None = None,
) -> tuple[PlanarTarget, list[FrameResult]]:
    """Build the target in the scene's reference frame (:func:`reference_index`) after ``normalization`` and pose it
    in every other frame; returns the target and one :class:`FrameResult` per other frame. ``n_features``: the
    strongest keypoints kept per frame (0: all).

    ``region``: the target's rectangle in the reference frame, :func:`select_region`'s on the raw frame, so that
    every normalization gets the same target; ``work_dir``: where a learned detector is written; ``recipe``: its
    training (default: the ``planar`` preset)."""
    if detector not in DETECTORS:
        raise InputError(f"unknown detector {detector!r}; choose one of {sorted(DETECTORS)}")
    frames = scene.frames
    ref = reference_index(frames)
    h, w = frames.shape[1:3]
    K = pinhole_camera(w, h, hfov)
    target = build_target(frames[ref], region, K, normalization, feature=feature, reference=scene.files[ref])
    det = DETECTORS[detector](target, normalization, n_features, work_dir, recipe)
    solver = make_solver(detector, K, target.model.corners)
    truth = (cv2.Rodrigues(target.rvec)[0], target.tvec)
    ref_uv = target.image_corners()
    results = []
    for i in range(len(frames)):
        if i == ref:
            continue
        t0 = time.perf_counter()
        corr = det.detect(frames[i])
        est = solver.solve(corr.object_points, corr.image_points, directions=corr.directions)
        seconds = time.perf_counter() - t0
        s = score(target.corners, K, "mm", (est.R, est.tvec) if est.ok else None, truth)
        worst = (
            float(np.linalg.norm(project(target.corners, est.rvec, est.tvec, K) - ref_uv, axis=1).max())
            if est.ok
            else None
        )
        results.append(FrameResult(scene.files[i], s.proj_px, worst, len(est.inliers), est.num_matches, seconds))
    return target, results


def _percent(values: Sequence[float | None]) -> float:
    return 100.0 * float(np.mean([v is not None and v < PROJ_PX for v in values])) if values else float("nan")


def plot_targets(scenes: Sequence[Scene], targets: dict[str, PlanarTarget], path: str | Path) -> Path:
    """A PNG of each scene's reference frame with its target's rectangle."""
    plt, fig, axes = new_figure(len(scenes), 1, figsize=(8, 2.6 * len(scenes)))
    for ax, scene in zip(axes[:, 0], scenes):
        t = targets[scene.name]
        ax.imshow(scene.frames[scene.files.index(t.reference)], cmap="gray")
        x, y, w, h = t.region
        ax.add_patch(plt.Rectangle((x - 0.5, y - 0.5), w, h, fill=False, color="tab:orange", lw=2))
        ax.set_title(
            f"{scene.name}: reference {t.reference}, target {w}x{h} px, {len(t.model.points3d)} parts "
            f"({t.model.normalization})",
            fontsize=9,
        )
        ax.axis("off")
    fig.tight_layout()
    return save_figure(plt, fig, path, dpi=90)


@holds_out_dir
def main(
    out_dir: str | Path,
    data: str | Path | None = None,
    *,
    scenes: Sequence[str] | None = None,
    normalizations: Sequence[str] = DEFAULT_NORMALIZATIONS,
    detectors: Sequence[str] = ("features",),
    feature: str = "SIFT",
    n_features: int = 0,
    target_fraction: float = DEFAULT_TARGET_FRACTION,
    hfov: float = DEFAULT_HFOV,
    max_frames: int | None = None,
    recipe: CornerRecipe | None = None,
    command: str = "",
    progress: bool = True,
) -> dict[str, Any]:
    """The real-light Table 1: per scene of ``data`` (default ``<shared data>/webcam``), detector of
    :data:`DETECTORS` and normalization, the % of frames whose target pose is correct. Writes
    ``planar_pose.md``, ``planar_pose.json``, ``planar_pose.png`` and ``targets.png`` (and the
    learned detectors, ``corners_<reference>_<normalization>.onnx``, trained by ``recipe``, default the
    ``planar`` preset) into ``out_dir``."""
    root = Path(data) if data is not None else default_folder("webcam")
    if not root.is_dir():
        raise DatasetError(missing_folder(root))
    all_scenes = load_scene_folder(root, max_frames)
    chosen = select_scenes(all_scenes, scenes) if scenes else all_scenes
    out_dir = Path(out_dir)
    make_folder(out_dir)
    for name in normalizations:  # a bad spec fails now, not after minutes of work
        from_spec(name)
    unknown = sorted(set(detectors) - set(DETECTORS))
    if unknown:
        raise InputError(f"unknown detectors {unknown}; choose among {sorted(DETECTORS)}")
    columns = [s.name for s in chosen]
    table: dict[str, dict[str, float]] = {}
    details: dict[str, Any] = {}
    targets: dict[str, PlanarTarget] = {}
    regions = {s.name: select_region(s.frames[reference_index(s.frames)], target_fraction, feature) for s in chosen}
    runs = [(detector, name, s) for detector in detectors for name in normalizations for s in chosen]
    for detector, name, scene in tqdm(runs, desc="relight pose", unit="scene", leave=False, disable=not progress):
        row = row_label(name, detector, feature)
        target, frames = evaluate_scene(
            scene,
            name,
            detector=detector,
            feature=feature,
            n_features=n_features,
            region=regions[scene.name],
            hfov=hfov,
            work_dir=out_dir,
            recipe=recipe,
        )
        targets.setdefault(scene.name, target)
        proj = [f.proj_px for f in frames]
        pct = _percent(proj)
        table.setdefault(row, {})[scene.name] = pct
        details.setdefault(row, {})[scene.name] = {
            "reference": target.reference,
            "region": list(target.region),
            "parts": len(target.model.points3d) if detector == "features" else len(target_parts(target)[0]),
            "frames": len(frames),
            "correct_pct": pct,
            "all_corners_within_pct": _percent([f.max_corner_px for f in frames]),
            "posed_pct": 100.0 * float(np.mean([p is not None for p in proj])) if frames else float("nan"),
            "median_error_px": float(np.median([p for p in proj if p is not None]))
            if any(p is not None for p in proj)
            else None,
            "ms_per_frame": 1000.0 * float(np.mean([f.seconds for f in frames])) if frames else None,
            "per_frame": [vars(f) for f in frames],
        }
        logger.info("%s %s: %.1f%% correct (%d frames)", row, scene.name, pct, len(frames))
    for vals in table.values():
        vals["mean"] = float(np.mean([vals[c] for c in columns]))
    host = machine()
    keypoints = "every keypoint" if not n_features else f"the {n_features} strongest keypoints"
    K_note = f"pinhole camera, {hfov:g} deg horizontal field of view, principal point at the centre"
    md = (
        "# Pose of a planar target under real light (Table 1 on fixed webcams)\n\n"
        f"Command: `{command}`\n\nMachine: {describe_machine(host)}\n\n"
        f"Data: `{root}` (Webcam data set of TILDE, Verdie et al., CVPR 2015, from AMOS; academic research use "
        "only). Per scene, a target of "
        f"{target_fraction:g} x the frame's width and height in its reference frame (median brightness; "
        "`targets.png`), its part model from that frame alone after each normalization "
        f"({feature} keypoints, {K_note}), its pose in every other frame by the box's pipeline "
        f"(`pose.parts.FeaturePartDetector` on {keypoints} of each frame"
        + (
            ", or the corner CNN of `pose.corners` trained on the reference frame alone for the target's corners "
            "and side middles"
            if "corners" in detectors
            else ""
        )
        + ", then `pose.solver.PoseSolver`); "
        "truth: the reference "
        f"pose (the camera did not move). Cells: % of frames whose target corners reproject within {PROJ_PX:g} px "
        "on average (lost frames count as wrong); the JSON also gives the share with every corner within "
        f"{PROJ_PX:g} px, the median error and the time per frame.\n\n"
        + table_markdown(table, columns + ["mean"])
        + "\n\n"
        + _details_markdown(details, columns)
    )
    atomic_write(out_dir / "planar_pose.md", md)
    write_json(
        out_dir / "planar_pose.json",
        nan_to_none(
            {
                "command": command,
                "machine": host,
                "data": str(root),
                "columns": columns,
                "table": table,
                "details": details,
                "settings": {
                    "feature": feature,
                    "n_features": n_features,
                    "detectors": list(detectors),
                    "corner_recipe": asdict(recipe or CORNER_CONFS["planar"]),
                    "target_fraction": target_fraction,
                    "hfov_deg": hfov,
                    "proj2d_px": PROJ_PX,
                    "max_frames": max_frames,
                },
            }
        ),
    )
    plot_table(
        table,
        columns + ["mean"],
        out_dir / "planar_pose.png",
        f"Planar target on fixed webcams: correct poses (< {PROJ_PX:g} px)",
    )
    plot_targets(chosen, targets, out_dir / "targets.png")
    return {"table": table, "details": details}


def _details_markdown(details: dict[str, Any], columns: list[str]) -> str:
    headers = [
        "row",
        "scene",
        "reference",
        "target (x, y, w, h)",
        "parts",
        "posed %",
        f"all 4 corners < {PROJ_PX:g} px %",
        "median err (px)",
        "ms/frame",
    ]
    rows = []
    for row, per_scene in details.items():
        for c in columns:
            d = per_scene[c]
            med = None if d["median_error_px"] is None else f"{d['median_error_px']:.2f}"
            rows.append(
                [
                    row,
                    c,
                    d["reference"],
                    tuple(d["region"]),
                    d["parts"],
                    f"{d['posed_pct']:.1f}",
                    f"{d['all_corners_within_pct']:.1f}",
                    med,
                    f"{d['ms_per_frame']:.0f}",
                ]
            )
    return markdown_table(headers, rows)
