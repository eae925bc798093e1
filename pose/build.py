"""``alcn pose build``: a part model (:mod:`pose.model`) from a training sequence.

Pipeline (hloc-style, one module per stage):

1. :mod:`pose.sequence`: the training images and their cameras: a registered sequence (known
   poses: BOP scene, COLMAP model, Middlebury ``_par.txt``) or the frames of a video
   (unregistered, optionally with masks of what moves in front of a static camera).
2. :mod:`pose.triangulate`: OpenCV features on the normalized images, matches verified by
   pycolmap, then ``pycolmap.triangulate_points`` with the known poses held fixed, or, for an
   unregistered video with a known object size, ``pycolmap.incremental_mapping`` (unknown
   scale). Each 3D point keeps up to 8 of its track's descriptors: the medoid (the one closest
   to all others) and those farthest from it (:func:`pose.triangulate.representatives`), so that a
   view unlike the typical one (a face seen at a lower angle) still finds a close descriptor; the
   ratio test at tracking time compares distinct points (:class:`pose.parts.FeaturePartDetector`).
   More descriptors per point matched more parts (``docs/journal.md``).
3. :mod:`pose.box_fit`: the box's size, frame and 8 corners (open3d); an unregistered
   reconstruction is scaled by it.
4. :func:`build` assembles the model in the object frame; :func:`main` writes ``<out>.npz`` +
   ``<out>.ply`` (:mod:`pose.model`) and ``<out>_cameras.png`` (:func:`pose.plots.plot_model`).

:data:`COOKIE_BOX` holds the settings the shared data's cookie box is built with by its examples and its experiment
(hloc's ``confs``; :func:`build_options`: the same settings as options of ``alcn pose build``).
"""

from __future__ import annotations

import logging
import tempfile
import types
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from alcn_cv import io
from alcn_cv.enhance.alcn import pin_default_model
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.extras import require
from alcn_cv.io import check_writable, make_folder
from pose import model as part_model
from pose.box_fit import fit_box
from pose.model import PartModel, box_corners, read_box_corners
from pose.parts import descriptor_norm
from pose.plots import plot_model
from pose.sequence import (
    VIDEO_MAX_FRAMES,
    VIDEO_STEP,
    TrainingSequence,
    load_sequence,
    motion_masks,
    video_sequence,
)
from pose.solver import camera_matrix
from pose.triangulate import (
    collect_points,
    extract_features,
    image_pairs,
    reconstruct_incremental,
    triangulate_fixed_poses,
    write_database,
)

logger = logging.getLogger(__name__)

#: Units of the box's size when building from a video and none are given.
VIDEO_BOX_UNITS = "cm"
#: A refined focal length's fx / fy moved, or the box fit off the known size, by more than this share: warned
#: (the cookie box from its first 120 frames with the motion mask: fx / fy 0.79, 15% off; from the whole video 2.7%).
SUSPICIOUS = 0.1


def _read_only(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False  # a preset's array is shared by every build that uses it
    return array


#: The cookie box's settings of :func:`main` (read-only, shared by every build that uses them), its keyword arguments
#: but the paths (the video, the output, ``box_ply``): ``main(video, output, box_ply=..., **COOKIE_BOX)``. The shared
#: data's ``cookie_box/box.mp4``, a hand-held box before a static camera (the motion mask), with the intrinsics of
#: OpenCV's real-time pose tutorial (fx = 640*55/22.3, fy = 480*55/14.9, cx = 320, cy = 240), which are refined (held
#: fixed at fx 1578 px, the box's front side folds into the plane of its lid: the box fit is 8.5% off instead of
#: 2.7%); every 10th frame, at most 46: all 456 frames.
COOKIE_BOX: Mapping[str, Any] = types.MappingProxyType(
    {
        "K": _read_only(camera_matrix(640 * 55 / 22.3, 480 * 55 / 14.9, 320.0, 240.0)),
        "step": 10,
        "max_frames": 46,
        "motion_mask": True,
        "feature": "ORB",
        "n_features": 3000,
        "box_units": "cm",
        "refine_focal": True,
    }
)


def build(
    seq: TrainingSequence,
    *,
    feature: str = "ORB",
    n_features: int = 4000,
    normalization: str = "none",
    box_ply: str | Path | None = None,
    box_size: np.ndarray | None = None,
    box_units: str | None = None,
    masks: dict[str, np.ndarray] | None = None,
    window: int | None = None,
    ratio: float = 0.8,
    work_dir: str | Path | None = None,
    world_is_object: bool = True,
    refine_focal: bool = False,
    descriptors_per_point: int = 8,
    progress: bool = True,
) -> tuple[PartModel, np.ndarray]:
    """Build a part model from a sequence; returns it and the training cameras' centres (object frame).

    For a registered sequence the object frame is the sequence's world frame (BOP: the object's
    model frame), and the box is fitted in it; when ``box_ply`` is given it is taken to be in that
    frame (a BOP model), its corners are the model's and the fit's error against it is reported.
    For an unregistered sequence the object frame is the fitted box's frame (origin at a
    corner, axes along its edges), scaled to the known size.
    """
    if len(seq.views) < 2:
        raise DatasetError(f"{seq.info.get('path')}: {len(seq.views)} training image(s); at least 2 are needed")
    known, known_corners = None, None
    if box_ply is not None:
        known_corners = read_box_corners(box_ply)
        known = np.linalg.norm(known_corners[[4, 2, 1]] - known_corners[0], axis=1)
    elif box_size is not None:
        known = np.asarray(box_size, np.float64)
    registered = seq.registered
    if not registered and known is None:
        raise InputError("an unregistered sequence needs the object's size for its scale: --box-ply or --box-size")
    units = seq.units or box_units or "mm"
    if known is not None and box_units and seq.units and box_units != seq.units:
        known = known * part_model.unit_scale(box_units, seq.units)
        known_corners = None if known_corners is None else known_corners * part_model.unit_scale(box_units, seq.units)
    norm = descriptor_norm(feature)
    with tempfile.TemporaryDirectory(prefix="alcn_pose_build_", dir=work_dir, ignore_cleanup_errors=True) as work:
        tmp = Path(work)
        feats = extract_features(seq, feature, n_features, normalization, masks, progress)
        write_database(tmp / "database.db", seq, feats, image_pairs(len(seq.views), window), norm, ratio, progress)
        if registered:
            rec = triangulate_fixed_poses(seq, tmp / "database.db", tmp / "sparse")
        else:
            rec = reconstruct_incremental(seq, tmp / "database.db", tmp / "sparse", refine_focal)
        xyz, desc, desc_point, tl, rgb = collect_points(rec, feats, norm, descriptors_per_point=descriptors_per_point)
        cams_K = [rec.cameras[im.camera_id].calibration_matrix() for im in rec.images.values() if im.has_pose]
        centers = np.array([im.projection_center() for im in rec.images.values() if im.has_pose])
        reg = {im.name: im.cam_from_world().matrix() for im in rec.images.values() if im.has_pose}
    logger.info("%d 3D points (mean track %.1f) from %d images", len(xyz), tl.mean(), len(reg))
    if registered and world_is_object and known_corners is not None:
        # the box is known in the world (= object) frame: keep the points near it, fit it for the report
        lo, hi = known_corners.min(0), known_corners.max(0)
        margin = 0.05 * np.linalg.norm(hi - lo)
        near = np.all((xyz >= lo - margin) & (xyz <= hi + margin), axis=1)
        if near.sum() < 10:
            raise DatasetError(
                f"only {int(near.sum())} triangulated points lie on the known box; check that the "
                "sequence's poses are those of this object"
            )
        fit = fit_box(xyz[near], known)
        fit.stats["corner_error"] = float(
            np.mean(np.min(np.linalg.norm(fit.corners[:, None] - known_corners[None], axis=2), axis=1))
        )
        keep = near.copy()
        keep[near] = fit.keep
        pts, corners, cams = xyz, known_corners, centers
    else:
        fit = fit_box(xyz, known, scale_free=not registered, viewpoints=centers)
        # registered: every point triangulated with the known poses is kept (the object need not be a
        # box, e.g. Middlebury's temple); unregistered: only the object's cluster moves with it
        keep = np.ones(len(xyz), bool) if registered else fit.keep
        if registered and world_is_object:
            pts, corners, cams = xyz, fit.corners, centers
        else:  # object frame = box frame
            s = fit.stats.get("scale", 1.0)
            pts = (xyz * s - fit.origin) @ fit.R
            cams = (centers * s - fit.origin) @ fit.R
            corners = box_corners(fit.size)
            for v in seq.views:
                if v.name in reg:
                    T = reg[v.name]
                    v.R_w2c = T[:, :3] @ fit.R
                    v.t_w2c = T[:, :3] @ fit.origin + T[:, 3] * s
    index = np.full(len(xyz), -1, np.int64)
    index[keep] = np.arange(int(keep.sum()))
    kept_desc = keep[desc_point]
    model = PartModel(
        corners=corners,
        points3d=pts[keep],
        descriptors=desc[kept_desc],
        descriptor_point=index[desc_point[kept_desc]],
        track_length=tl[keep],
        colors=rgb[keep],
        units=units,
        feature=feature.upper(),
        normalization=pin_default_model(normalization),
        source=str(seq.info.get("path", "")),
        box_fit=_jsonable(fit.stats),
        extra={"registered_images": len(reg), "training_images": len(seq.views), "triangulated_points": int(len(xyz))},
    )
    if refine_focal and not registered:
        K = np.mean(cams_K, axis=0)
        K[:2, 2] -= 0.5  # COLMAP -> OpenCV pixel convention
        model.extra["K"] = K.tolist()
        # square pixels give fx = fy: a bundle adjustment that pulls them apart had too few or too similar views
        moved = abs((K[0, 0] / K[1, 1]) / (seq.views[0].K[0, 0] / seq.views[0].K[1, 1]) - 1) > SUSPICIOUS
        logger.log(
            logging.WARNING if moved else logging.INFO,
            "focal length refined by the bundle adjustment: fx %.1f fy %.1f (given %.1f %.1f)%s",
            K[0, 0],
            K[1, 1],
            seq.views[0].K[0, 0],
            seq.views[0].K[1, 1],
            "; their ratio moved: more frames or views from more directions" if moved else "",
        )
    elif not registered or all(np.allclose(v.K, seq.views[0].K) for v in seq.views):
        model.extra["K"] = np.asarray(seq.views[0].K, np.float64).tolist()  # the camera, for `alcn pose track`
    if "K" in model.extra:
        model.extra["image_size"] = list(seq.size)  # the frames that camera is for (extract_features read them)
    return model, cams


def _jsonable(d: dict[str, Any]) -> dict[str, Any]:
    return {
        k: (
            v.tolist()
            if isinstance(v, np.ndarray)
            else float(v)
            if isinstance(v, np.floating)
            else int(v)
            if isinstance(v, np.integer)
            else v
        )
        for k, v in d.items()
    }


def main(
    input_path: str | Path,
    output: str | Path,
    *,
    images: str | Path | None = None,
    K: np.ndarray | None = None,
    step: int | None = None,
    max_frames: int | None = None,
    motion_mask: bool = False,
    feature: str = "ORB",
    n_features: int = 4000,
    normalization: str = "none",
    box_ply: str | Path | None = None,
    box_size: tuple[float, float, float] | None = None,
    box_units: str | None = None,
    refine_focal: bool = False,
    progress: bool = True,
    what: str = "pose.build.main",
) -> Path:
    """Build a part model from ``input_path`` and write ``output`` (.npz, .ply, _cameras.png).

    ``input_path``: a registered sequence (see :func:`load_sequence`) or a video file (unregistered:
    needs ``K`` and the box size; ``motion_mask`` keeps only what moves, for a static camera;
    ``refine_focal`` lets the bundle adjustment refine the focal length; the camera, refined or
    given, is stored in the model's ``extra["K"]``, which ``alcn pose track`` uses by default).
    Of a video every ``step``-th frame is used, at most ``max_frames`` (``None``: the defaults
    :data:`pose.sequence.VIDEO_STEP` and :data:`pose.sequence.VIDEO_MAX_FRAMES`). The options of a
    video that a registered sequence ignores are warned about when given. ``what``: the caller the error of a
    missing ``[pose]`` extra names (``alcn pose build`` gives its own name).
    """
    # the reconstruction (pycolmap), the box fit (open3d) and the plot come after the features: checked before those
    require("pycolmap", "open3d", "matplotlib", what=what, preferred="pose")
    input_path, output = Path(input_path), part_model.model_file(output)
    check_writable(output)  # before the work
    make_folder(output.parent)
    with tempfile.TemporaryDirectory(prefix="alcn_pose_frames_", dir=output.parent) as work:
        if input_path.is_file() and io.is_video(input_path):
            if K is None:
                raise InputError("building from a video needs the intrinsics (--K fx fy cx cy)")
            if images is not None:
                logger.warning("%s: a video; images (the image folder of a COLMAP model) ignored", input_path)
            seq = video_sequence(
                input_path,
                K,
                work,
                step=VIDEO_STEP if step is None else step,
                max_frames=VIDEO_MAX_FRAMES if max_frames is None else max_frames,
            )
            masks = None
            if motion_mask:
                frames = [io.read_image(seq.image_dir / v.name) for v in seq.views]
                masks = dict(zip((v.name for v in seq.views), motion_masks(frames)))
            # an unregistered video: its own units, matches within 8 frames, the focal length refinable
            video = {
                "box_units": box_units or VIDEO_BOX_UNITS,
                "masks": masks,
                "window": 8,
                "refine_focal": refine_focal,
            }
        elif input_path.is_file():
            raise InputError(
                f"{input_path}: build from a video ({', '.join(sorted(io.VIDEO_SUFFIXES))}) or a registered sequence's "
                "folder (a BOP scene, a COLMAP model or a Middlebury set)"
            )
        else:
            seq = load_sequence(input_path, images)
            video = {"box_units": box_units}
            # a registered sequence has its cameras and poses: these only apply to a video
            video_options = {
                "K": K is not None,
                "step": step is not None,
                "max_frames": max_frames is not None,
                "motion_mask": motion_mask,
                "refine_focal": refine_focal,
            }
            ignored = [name for name, given in video_options.items() if given]
            if ignored:
                logger.warning(
                    "%s: a registered sequence; %s apply to a video only, ignored", input_path, ", ".join(ignored)
                )
        model, cams = build(
            seq,
            feature=feature,
            n_features=n_features,
            normalization=normalization,
            box_ply=box_ply,
            box_size=box_size,
            work_dir=work,
            progress=progress,
            **video,
        )
    path = part_model.save(model, output)
    plot_model(model, cams, path.with_name(path.stem + "_cameras.png"))
    if "mean_abs_relative_size_error" in model.box_fit:
        error = model.box_fit["mean_abs_relative_size_error"]
        # with the corners of the box file the model's box is exact: the fit only says how its points cover it
        poor = error > SUSPICIOUS and "corner_error" not in model.box_fit
        logger.log(
            logging.WARNING if poor else logging.INFO,
            "box fit error vs the known size: %.1f%% (per axis %s %s)%s",
            100 * error,
            np.round(model.box_fit["size_error"], 3).tolist(),
            model.units,
            "; the model's points fit the box poorly: more frames or views from more directions" if poor else "",
        )
    return path


def build_options(settings: Mapping[str, Any]) -> list[str]:
    """The command-line options of ``alcn pose build`` that give :func:`main` the keyword arguments ``settings``
    (:data:`COOKIE_BOX`, say), for a script that runs the command: ``alcn pose build VIDEO OUT --box-ply PLY
    *build_options(COOKIE_BOX)``. Numbers are written in full (``repr``), so that the command builds from the same
    values as :func:`main` does; a switch that is ``False`` (the command's default) is left out.

    Raises:
        InputError: a value no option can give (``None``, a list: the command's default, or several values, are not
            written so), or ``K`` not 3x3.
    """
    options: list[str] = []
    for key, value in settings.items():
        option = "--" + key.replace("_", "-")
        if key == "K":
            K = np.asarray(value, np.float64)
            if K.shape != (3, 3):
                raise InputError(f"{key}: a 3x3 camera matrix, not {K.shape}")
            options += [option, *(repr(float(v)) for v in (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))]
        elif isinstance(value, bool):
            options += [option] if value else []
        elif isinstance(value, int | float | str):  # str(float) is its repr: in full
            options += [option, str(value)]
        else:
            raise InputError(f"{key}={value!r}: no option of alcn pose build gives it (a number, a string or a switch)")
    return options
