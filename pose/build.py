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

Named presets of the build's settings (hloc's ``confs``): :data:`CONFS`, ``alcn pose build --conf NAME``
(``static-camera``: a hand-held object before a static camera; ``cookie-box``: the shared data's, its examples' and
its experiment's, also :data:`COOKIE_BOX`); :func:`build_options`: settings as options of ``alcn pose build``.
"""

from __future__ import annotations

import logging
import tempfile
import types
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from alcn_cv import io
from alcn_cv.enhance.alcn import pin_default_model
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.extras import require
from alcn_cv.formats.colmap import camera_from_pycolmap
from alcn_cv.io import check_no_earlier_output, check_writable
from alcn_cv.presets import preset_named
from pose import model as part_model
from pose.box import box_size as box_edge_lengths
from pose.box_fit import fit_box, size_errors
from pose.model import PartModel, box_corners, read_box_corners
from pose.parts import descriptor_norm
from pose.plots import plot_model
from pose.sequence import (
    VIDEO_MAX_FRAMES,
    VIDEO_STEP,
    TrainingSequence,
    check_known_units,
    load_sequence,
    motion_masks,
    video_sequence,
)
from pose.solver import camera_matrix, check_intrinsics
from pose.triangulate import (
    collect_points,
    extract_features,
    image_pairs,
    reconstruct_incremental,
    triangulate_fixed_poses,
    write_database,
)

if TYPE_CHECKING:
    from calib.camera import Calibration

logger = logging.getLogger(__name__)

#: Units of the box's size when building from a video and none are given.
VIDEO_BOX_UNITS = "cm"
#: A refined focal length's fx / fy moved by more than this share from the given one's, off square pixels
#: (:data:`SQUARE_PIXELS`): warned (``docs/journal.md`` has the measurements). Moved to square pixels, it is what
#: most cameras have, and the given ratio was the guess.
SUSPICIOUS = 0.1
#: An fx / fy within this share of 1: square pixels.
SQUARE_PIXELS = 0.05
#: A refined focal length whose fx / fy is off square pixels (1) by more than this factor: the build fails, its
#: reconstruction degenerate (too few images registered; ``docs/journal.md`` has the measurements).
DEGENERATE_FOCAL_RATIO = 1.5
#: The box fit off the known size (``mean_abs_relative_size_error``, the mean over the three edges) by more than this
#: share: warned, in every branch (``--box-ply`` or ``--box-size``, video or registered sequence); it lies between the
#: builds that track well and the poor ones (``docs/journal.md`` has the measurements).
BOX_FIT_WARNING = 0.05
#: The box fit off the known size, on the edges its points cover (``seen_relative_size_error``: the best-seen face's
#: two edges, and the excess of its normal over the true length; a normal seen only in part, as a box seen from above,
#: is short by design), by more than this share: the build fails instead of writing a model. It is about twice the
#: worst honest build measured, and under what cannot track (poses in other units, a wrong ``--box-units``, another
#: box's edges; ``docs/journal.md`` has the measurements).
BOX_FIT_FAILURE = 0.2


def _read_only(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False  # a preset's array is shared by every build that uses it
    return array


#: A hand-held object turned before a static camera: the features kept on what moves
#: (:func:`pose.sequence.motion_masks`; the static background would otherwise dominate the reconstruction), the focal
#: length refined by the bundle adjustment (a guessed one held fixed folds the box; ``docs/journal.md``), every 10th
#: frame, 3000 ORB keypoints a frame: the cookie box's settings but its camera and number of frames.
_STATIC_CAMERA: dict[str, Any] = {
    "step": 10,
    "motion_mask": True,
    "feature": "ORB",
    "n_features": 3000,
    "refine_focal": True,
}

#: The named presets of :func:`main` (hloc's ``confs``; ``alcn pose build --conf NAME``), read-only: each a mapping of
#: :func:`main`'s keyword arguments but the paths (the input, the output, ``box_ply``). A keyword given to
#: :func:`main` (an option on the command line) overrides the preset's value (:func:`conf_settings`); a preset's
#: values of a video (:data:`PRESET_VIDEO_SETTINGS`) apply to a video only.
#:
#: * ``static-camera``: a hand-held object before a static camera (:data:`_STATIC_CAMERA`); the camera (``K`` or
#:   ``camera``) and the box's size are the caller's.
#: * ``cookie-box``: the shared data's ``cookie_box/box.mp4``: ``static-camera`` with the intrinsics of OpenCV's
#:   real-time pose tutorial (fx = 640*55/22.3, fy = 480*55/14.9, cx = 320, cy = 240; refined), the box in cm, at
#:   most 46 frames: all the frames the video decodes at every 10th.
#:
#: Without a preset, :func:`main`'s defaults (:data:`DEFAULTS`) hold: those of a registered sequence, which ignores
#: the options of a video.
CONFS: Mapping[str, Mapping[str, Any]] = types.MappingProxyType(
    {
        "static-camera": types.MappingProxyType(dict(_STATIC_CAMERA)),
        "cookie-box": types.MappingProxyType(
            {
                "K": _read_only(camera_matrix(640 * 55 / 22.3, 480 * 55 / 14.9, 320.0, 240.0)),
                **_STATIC_CAMERA,
                "max_frames": 46,
                "box_units": "cm",
            }
        ),
    }
)

#: The frame size ``(width, height)`` that a preset's intrinsics are for: a video of another size built with them is
#: refused before the work (its camera is another one; ``--K`` or ``--camera`` give it).
PRESET_FRAME_SIZES: Mapping[str, tuple[int, int]] = types.MappingProxyType({"cookie-box": (640, 480)})

#: One line per preset of :data:`CONFS`, for ``alcn pose build --help``.
CONF_SUMMARIES: Mapping[str, str] = types.MappingProxyType(
    {
        "static-camera": "a hand-held object before a static camera (give --K or --camera, and the box)",
        "cookie-box": "the shared data's cookie_box/box.mp4: static-camera with the intrinsics of OpenCV's real-time "
        "pose tutorial, the box in cm, every 10th of its 455 frames",
    }
)

#: The cookie box's settings of :func:`main`, ``CONFS["cookie-box"]`` (read-only, shared by every build that uses
#: them): ``main(video, output, box_ply=..., **COOKIE_BOX)``, the same as ``main(..., conf="cookie-box")``.
COOKIE_BOX: Mapping[str, Any] = CONFS["cookie-box"]

#: The values of :func:`main`'s settings that neither a preset nor the caller gives (``step`` and ``max_frames``:
#: :data:`pose.sequence.VIDEO_STEP` and :data:`pose.sequence.VIDEO_MAX_FRAMES`; ``box_units``: the sequence's, or
#: :data:`VIDEO_BOX_UNITS` for a video).
DEFAULTS: Mapping[str, Any] = types.MappingProxyType(
    {"feature": "ORB", "n_features": 4000, "normalization": "none", "motion_mask": False, "refine_focal": False}
)

#: :func:`main`'s settings that only a video uses (a registered sequence has its cameras and poses): given by the
#: caller for a registered sequence, they are warned about as ignored.
VIDEO_SETTINGS = ("K", "camera", "step", "max_frames", "motion_mask", "refine_focal")
#: A preset's settings that apply to a video only: :data:`VIDEO_SETTINGS` and the units of its box, which are its
#: video's (``cookie-box``: cm); a registered sequence's box is in the caller's ``box_units`` or the sequence's.
PRESET_VIDEO_SETTINGS = (*VIDEO_SETTINGS, "box_units")


def conf_settings(conf: str | None, *, video: bool = True, **given: Any) -> dict[str, Any]:
    """The settings of :func:`main` from the preset ``CONFS[conf]`` (none: ``{}``) and the keywords ``given``: a value
    given (not ``None``) overrides the preset's, and a camera given (``K`` or ``camera``) replaces the preset's.
    Without ``video`` (a registered sequence) the preset's :data:`PRESET_VIDEO_SETTINGS` are left out. A calibration
    given (``camera``) holds the focal length fixed unless ``refine_focal`` is given too: it was measured, and a
    preset's refinement (``static-camera``'s, for a guessed ``K``) would move the model's camera away from it. Settings
    neither gives are left out (:func:`main` takes :data:`DEFAULTS` for them).

    >>> conf_settings("static-camera", n_features=1000, max_frames=None)["n_features"]
    1000
    >>> conf_settings("static-camera", camera="camera.yaml")["refine_focal"]
    False

    Raises:
        InputError: an unknown preset (:func:`~alcn_cv.presets.preset_named`).
    """
    preset: Mapping[str, Any] = {} if conf is None else preset_named(CONFS, conf)
    settings = {k: v for k, v in preset.items() if video or k not in PRESET_VIDEO_SETTINGS}
    if given.get("K") is not None or given.get("camera") is not None:
        settings.pop("K", None)
        settings.pop("camera", None)
    if given.get("camera") is not None and given.get("refine_focal") is None and "refine_focal" in settings:
        settings["refine_focal"] = False
    settings.update({key: value for key, value in given.items() if value is not None})
    return settings


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
    refine_focal: bool = False,
    fit_hint: str | None = None,
    progress: bool = True,
) -> tuple[PartModel, np.ndarray]:
    """Build a part model from a sequence; returns it and the training cameras' centres (object frame).

    For a registered sequence the object frame is the sequence's world frame (BOP: the object's
    model frame), and the box is fitted in it; when ``box_ply`` is given it is taken to be in that
    frame (a BOP model), its corners are the model's and the fit's error against it is reported.
    For an unregistered sequence the object frame is the fitted box's frame (origin at a
    corner, axes along its edges), scaled to the known size.

    With a known size, a fit more than :data:`BOX_FIT_WARNING` off it is warned, and one whose points are more than
    :data:`BOX_FIT_FAILURE` off it on the edges they cover fails (:func:`check_box_fit`); ``fit_hint``: what its
    message, and that of a known box with too few points on it, tells the caller to check (default: the options of
    ``alcn pose build``).

    The model stores the camera for ``alcn pose track`` (a video's, or a registered sequence's when all its images
    share one): ``extra["K"]`` (refined with ``refine_focal``; OpenCV pixel convention), ``extra["image_size"]`` the
    frames' ``(width, height)`` and, when the views have one, the lens distortion ``extra["dist"]`` (OpenCV order).

    Raises:
        InputError: a registered sequence in arbitrary units (:func:`pose.sequence.check_known_units`), or an
            unregistered one without the box's size.
        DatasetError: too few images or points, or the box fit too far off the known size.
    """
    if len(seq.views) < 2:
        raise DatasetError(f"{seq.info.get('path')}: {len(seq.views)} training image(s); at least 2 are needed")
    registered = seq.registered
    check_known_units(
        seq,
        "a part model",
        ", or build from the video itself with --K or --camera and --box-size W H D (the box's size then sets the "
        "scale)",
    )
    known, known_corners = None, None
    if box_ply is not None:
        known_corners = read_box_corners(box_ply)
        known = box_edge_lengths(known_corners)
    elif box_size is not None:
        known = np.asarray(box_size, np.float64)
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
            rec = reconstruct_incremental(seq, tmp / "database.db", tmp / "sparse", refine_focal, progress)
        xyz, desc, desc_point, tl, rgb = collect_points(rec, feats, norm)
        posed = [im for im in rec.images.values() if im.has_pose]
        centers = np.array([im.projection_center() for im in posed])
        reg = {im.name: im.cam_from_world().matrix() for im in posed}
        # the refined camera, in OpenCV's pixel convention (converted by alcn_cv.formats.colmap)
        refined = (
            np.mean([camera_from_pycolmap(rec.cameras[im.camera_id]).to_opencv()[0] for im in posed], axis=0)
            if refine_focal and not registered
            else None
        )
    logger.info("%d 3D points (mean track %.1f) from %d images", len(xyz), tl.mean(), len(reg))
    # square pixels give fx = fy: a bundle adjustment that pulls them apart had too few or too similar views; far
    # apart, the reconstruction is degenerate: refused before the box is fitted to it
    ratio = None if refined is None else float(refined[0, 0] / refined[1, 1])
    if ratio is not None and max(ratio, 1 / ratio) > DEGENERATE_FOCAL_RATIO:
        raise DatasetError(
            f"the bundle adjustment pulled the focal lengths apart (fx {refined[0, 0]:.1f}, fy {refined[1, 1]:.1f}; "
            f"{len(reg)} of {len(seq.views)} images registered): a degenerate reconstruction, no model written; "
            "give more frames (--max-frames, --step) or views from more directions"
        )
    if registered and known_corners is not None:
        # the box is known in the world (= object) frame: keep the points near it, fit it for the report
        lo, hi = known_corners.min(0), known_corners.max(0)
        margin = 0.05 * np.linalg.norm(hi - lo)
        near = np.all((xyz >= lo - margin) & (xyz <= hi + margin), axis=1)
        if near.sum() < 10:
            raise DatasetError(
                f"only {int(near.sum())} triangulated points lie on the known box; "
                + (
                    fit_hint
                    or "check that the sequence's poses are those of this object, and that --box-ply is the box "
                    "placed in the sequence's world frame (a BOP model); --box-size W H D gives the box's size alone, "
                    "fitted where its points are"
                )
            )
        fit = fit_box(xyz[near], known)
        fit.stats["corner_error"] = float(
            np.mean(np.min(np.linalg.norm(fit.corners[:, None] - known_corners[None], axis=2), axis=1))
        )
        # the model's box is the known one, along the world's axes: the fit measured against it there
        edges = "x, y, z" if _against_the_known_box(fit.stats, fit.R, known) else _FIT_EDGES
        keep = near.copy()
        keep[near] = fit.keep
        pts, corners, cams = xyz, known_corners, centers
    else:
        edges = "x, y, z"  # the model's box is the fit's: its edges in the order of the fit's axes
        fit = fit_box(xyz, known, scale_free=not registered, viewpoints=centers)
        # registered: every point triangulated with the known poses is kept (the object need not be a
        # box, e.g. Middlebury's temple); unregistered: only the object's cluster moves with it
        keep = np.ones(len(xyz), bool) if registered else fit.keep
        if registered:
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
    check_box_fit(fit.stats, units, scale_free=not registered, edges=edges, hint=fit_hint)
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
    if refined is not None and ratio is not None:
        K = refined
        model.extra["K"] = K.tolist()
        level, how = _focal_ratio_note(seq.views[0].K[0, 0] / seq.views[0].K[1, 1], ratio)
        logger.log(
            level,
            "focal length refined by the bundle adjustment: fx %.1f fy %.1f (given %.1f %.1f)%s",
            K[0, 0],
            K[1, 1],
            seq.views[0].K[0, 0],
            seq.views[0].K[1, 1],
            how,
        )
    elif not registered or all(np.allclose(v.K, seq.views[0].K) for v in seq.views):
        model.extra["K"] = np.asarray(seq.views[0].K, np.float64).tolist()  # the camera, for `alcn pose track`
    if "K" in model.extra:
        model.extra["image_size"] = list(seq.size)  # the frames that camera is for
        dist = seq.views[0].dist
        # the lens distortion the reconstruction modelled (held fixed in it): the frames' keypoints are distorted
        if dist is not None and all(v.dist is not None and np.array_equal(v.dist, dist) for v in seq.views):
            model.extra["dist"] = np.asarray(dist, np.float64).ravel().tolist()
    return model, cams


def _focal_ratio_note(given: float, refined: float) -> tuple[int, str]:
    """The log level of a refined focal length whose fx / fy is ``refined`` where the given one's was ``given``, and
    the words on its ratio: a warning where it moved (:data:`SUSPICIOUS`) off square pixels (:data:`SQUARE_PIXELS`)."""
    if abs(refined / given - 1) <= SUSPICIOUS:
        return logging.INFO, ""
    moved = f"; their ratio moved from {given:.2f} to {refined:.2f}"
    if abs(refined - 1) <= SQUARE_PIXELS:
        return logging.INFO, f"{moved}, square pixels"
    return logging.WARNING, f"{moved}: more frames or views from more directions"


#: The edges a box fit's per-axis statistics are along when they are not the model's box's x, y, z
#: (:func:`_against_the_known_box`): :func:`pose.box_fit.fit_box`'s axes.
_FIT_EDGES = "of the fit (its best-seen face's two edges, then the face's normal)"


def _against_the_known_box(stats: dict[str, Any], R: np.ndarray, known: np.ndarray) -> bool:
    """Measure a box fit against the known box of a registered sequence's ``--box-ply``, which is the model's, along
    the world's axes: per world axis, the fit's extent along its axis nearest it against the known box's edge there
    (:func:`pose.box_fit.size_errors`, the face's normal where the fit's is), in place of the fit's own assignment of
    the known lengths to its axes (:func:`pose.box_fit.match_known_size`: a box turned against the .ply had its lengths
    matched in another order, and was logged as the .ply's x, y, z). Returns ``False``, the statistics left along the
    fit's axes, when each of them is not nearest a different world axis (a box turned about 45 degrees)."""
    order = np.argmax(np.abs(np.asarray(R)), axis=1)  # world axis j is nearest the fit's axis order[j]
    if sorted(order.tolist()) != [0, 1, 2]:
        return False
    fitted = np.asarray(stats["fitted_size"], np.float64)[order]
    stats.update(fitted_size=fitted.tolist(), **size_errors(fitted, known, normal=int(np.flatnonzero(order == 2)[0])))
    return True


def check_box_fit(
    stats: dict[str, Any], units: str, *, scale_free: bool = False, edges: str = "x, y, z", hint: str | None = None
) -> None:
    """Log a box fit's error against the known size (its sizes along the ``edges`` of the box: by default those of the
    model's box, corner 0 to corners 4, 2, 1), as a warning when it is over :data:`BOX_FIT_WARNING`; nothing without
    a known size. ``scale_free``: the fit scaled the points to the known size (a video's reconstruction), so their
    units cannot be off, and the failure's message does not suggest them. ``hint``: what the failure's message tells
    the caller to check (default: the options of ``alcn pose build``).

    Raises:
        DatasetError: the error on the edges the points cover (``seen_relative_size_error``) is over
            :data:`BOX_FIT_FAILURE`: the model's points are not this box (or, registered, not in these units).
    """
    if "mean_abs_relative_size_error" not in stats:
        return
    error = stats["mean_abs_relative_size_error"]
    seen = stats.get("seen_relative_size_error", error)
    if seen > BOX_FIT_FAILURE:
        if hint:
            why = hint
        elif scale_free:
            why = (
                "the reconstruction's points are not this box's shape; check --box-size/--box-ply (the box's three "
                "edges), that the video shows this box, and its camera (--refine-focal for a guessed --K)"
            )
        else:
            why = (
                "the model's points are not this box, or not in these units; check --box-size/--box-ply and "
                "--box-units, and that the sequence's poses are this object's"
            )
        raise DatasetError(
            f"the box fit is {100 * seen:.0f}% off the known size on the edges its points cover (known "
            f"{np.round(stats['known_size'], 3).tolist()} {units}, off by {np.round(stats['size_error'], 3).tolist()}"
            f" along the edges {edges}), over {100 * BOX_FIT_FAILURE:.0f}%: {why}"
        )
    poor = error > BOX_FIT_WARNING
    logger.log(
        logging.WARNING if poor else logging.INFO,
        "box fit error vs the known size: %.1f%% (per edge %s %s %s)%s",
        100 * error,
        edges,
        np.round(stats["size_error"], 3).tolist(),
        units,
        "; the model's points fit the box poorly: more frames or views from more directions" if poor else "",
    )


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
    camera: str | Path | Calibration | None = None,
    step: int | None = None,
    max_frames: int | None = None,
    motion_mask: bool | None = None,
    feature: str | None = None,
    n_features: int | None = None,
    normalization: str | None = None,
    box_ply: str | Path | None = None,
    box_size: tuple[float, float, float] | None = None,
    box_units: str | None = None,
    refine_focal: bool | None = None,
    conf: str | None = None,
    overwrite: bool = False,
    progress: bool = True,
    what: str = "pose.build.main",
) -> Path:
    """Build a part model from ``input_path`` and write ``output`` (.npz, .ply, _cameras.png).

    ``input_path``: a registered sequence (see :func:`load_sequence`) or a video file (unregistered:
    needs ``K`` or ``camera`` and the box size; ``motion_mask`` keeps only what moves, for a static camera;
    ``refine_focal`` lets the bundle adjustment refine the focal length; the camera, refined or
    given, is stored in the model's ``extra["K"]``, which ``alcn pose track`` uses by default).
    Of a video every ``step``-th frame is used, at most ``max_frames`` (``None``: the defaults
    :data:`pose.sequence.VIDEO_STEP` and :data:`pose.sequence.VIDEO_MAX_FRAMES`). The options of a
    video (:data:`VIDEO_SETTINGS`) that a registered sequence ignores are warned about when given. ``what``: the
    caller the error of a missing ``[pose]`` extra names (``alcn pose build`` gives its own name).

    ``camera``: the calibration of a video's camera instead of ``K`` (a ``camera.yaml`` of ``alcn calib camera``, read
    by :func:`calib.camera.load_calibration`, or its :class:`~calib.camera.Calibration`): its K, held fixed unless
    ``refine_focal`` is given (:func:`conf_settings`), and its distortion, which the reconstruction models (pycolmap's
    ``OPENCV`` camera: the frames are not undistorted, their keypoints are those ``alcn pose track`` finds in the
    same frames). The model stores both (``extra["K"]``, ``extra["dist"]``, with the frames' ``extra["image_size"]``):
    ``alcn pose track`` tracks with them unless given another camera. The video's frames must be the calibration's
    size, checked on its first frame before the work.

    ``box_ply``/``box_size``: the box. For a video a cuboid ``.ply`` gives its size only (the box's frame is fitted);
    for a registered sequence it is the box placed in the sequence's world frame (a BOP model: its corners become the
    model's), while ``box_size`` gives the size alone (the box is fitted in the world frame).

    ``conf``: a preset of :data:`CONFS` (``"static-camera"``, ``"cookie-box"``); the settings given (not ``None``)
    override its values, its values of a video apply to a video only (:func:`conf_settings`), and those neither gives
    are :data:`DEFAULTS`. The model records the preset's name and the settings the build used (``extra["build"]``:
    :func:`_provenance`).

    ``overwrite``: replace the files of an earlier build (``output``, its ``.ply`` and :func:`cameras_plot`).

    Raises:
        InputError: an unknown preset, a video without its camera, a camera or the box given twice, ``K`` not a
            camera matrix (positive focal lengths), a box size not three lengths greater than 0, ``output`` a
            folder, or the files of an earlier build there without ``overwrite`` (all before the work); a video's
            frames of another size than its calibration's, or than a preset's intrinsics are for
            (:data:`PRESET_FRAME_SIZES`); and :func:`build`'s.
    """
    input_path, output = Path(input_path), part_model.model_file(output)
    is_video = input_path.is_file() and io.is_video(input_path)
    given = {
        "K": K,
        "camera": camera,
        "step": step,
        "max_frames": max_frames,
        "motion_mask": motion_mask,
        "feature": feature,
        "n_features": n_features,
        "normalization": normalization,
        "box_units": box_units,
        "refine_focal": refine_focal,
    }
    settings = {**DEFAULTS, **conf_settings(conf, video=is_video, **given)}
    if is_video:  # the frames a video keeps unless a preset or the caller says
        settings.setdefault("step", VIDEO_STEP)
        settings.setdefault("max_frames", VIDEO_MAX_FRAMES)
    # the reconstruction (pycolmap), the box fit (open3d) and the plot come after the features: checked before those
    require("pycolmap", "open3d", "matplotlib", what=what, preferred="pose")
    if box_ply is not None and box_size is not None:
        raise InputError(
            "give the box once: --box-ply (a cuboid .ply) or --box-size (its edge lengths), not both (in Python: "
            "box_ply= or box_size=)"
        )
    if box_size is not None:
        sizes = np.asarray(box_size, np.float64)
        if sizes.shape != (3,) or not (np.isfinite(sizes).all() and (sizes > 0).all()):
            raise InputError(f"--box-size W H D: three lengths greater than 0, got {sizes.tolist()}")
    if settings.get("K") is not None:
        check_intrinsics(settings["K"])
    if output.is_dir():
        raise InputError(f"{output} is a folder; give the part model's file (.npz)")
    check_no_earlier_output([output, output.with_suffix(".ply"), cameras_plot(output)], overwrite)
    check_writable(output)  # before the work
    if input_path.is_file() and not is_video:
        raise InputError(
            f"{input_path}: build from a video ({', '.join(sorted(io.VIDEO_SUFFIXES))}) or a registered sequence's "
            "folder (a BOP scene, a COLMAP model or a Middlebury set)"
        )
    from calib.camera import camera_once

    calibration = camera_once(settings.get("camera"), settings.get("K")) if is_video else None
    K, dist = settings.get("K"), None
    if calibration is not None:
        K = np.asarray(calibration.K, np.float64)
        dist = np.asarray(calibration.dist, np.float64) if np.any(calibration.dist) else None
    if is_video:
        if K is None:
            raise InputError(
                "building from a video needs the intrinsics (--K fx fy cx cy, or --camera camera.yaml; in Python: K= "
                "or camera=)"
            )
        # before the frames are extracted
        if calibration is not None:
            name = settings["camera"] if isinstance(settings["camera"], str | Path) else "the calibration"
            _check_frame_size(input_path, calibration.image_size, str(name))
        elif conf in PRESET_FRAME_SIZES and given["K"] is None:
            _check_frame_size(input_path, PRESET_FRAME_SIZES[conf], f"the preset {conf!r}'s camera")
    with io.new_folder(output.parent):  # a build that fails leaves no empty folder behind
        with tempfile.TemporaryDirectory(prefix="alcn_pose_frames_", dir=output.parent) as work:
            if is_video:
                if images is not None:
                    logger.warning("%s: a video; images (the image folder of a COLMAP model) ignored", input_path)
                seq = video_sequence(
                    input_path,
                    K,
                    work,
                    step=settings["step"],
                    max_frames=settings["max_frames"],
                    dist=dist,
                )
                masks = None
                if settings["motion_mask"]:
                    frames = [io.read_image(seq.image_dir / v.name) for v in seq.views]
                    masks = dict(zip((v.name for v in seq.views), motion_masks(frames)))
                # an unregistered video: its own units, matches within 8 frames, the focal length refinable
                video = {
                    "box_units": settings.get("box_units") or VIDEO_BOX_UNITS,
                    "masks": masks,
                    "window": 8,
                    "refine_focal": settings["refine_focal"],
                }
            else:
                seq = load_sequence(input_path, images)
                video = {"box_units": settings.get("box_units")}
                # a registered sequence has its cameras and poses: the caller's options of a video are ignored
                ignored = [name for name in VIDEO_SETTINGS if given[name] is not None]
                if ignored:
                    logger.warning(
                        "%s: a registered sequence; %s apply to a video only, ignored", input_path, ", ".join(ignored)
                    )
            model, cams = build(
                seq,
                feature=settings["feature"],
                n_features=settings["n_features"],
                normalization=settings["normalization"],
                box_ply=box_ply,
                box_size=box_size,
                work_dir=work,
                progress=progress,
                **video,
            )
        box_read_in = None if box_ply is None and box_size is None else video["box_units"] or seq.units
        model.extra["build"] = _provenance(conf, settings, seq if is_video else None, box_read_in)
        path = part_model.save(model, output)
        plot_model(model, cams, cameras_plot(path))
    return path


def cameras_plot(output: str | Path) -> Path:
    """The plot of the model's points and cameras :func:`main` writes beside the part model ``output``."""
    output = Path(output)
    return output.with_name(output.stem + "_cameras.png")


def _provenance(
    conf: str | None, settings: Mapping[str, Any], video: TrainingSequence | None, box_units: str | None
) -> dict[str, Any]:
    """What a model records of its build (``extra["build"]``): the preset's name (``None`` without one) and the
    settings it used; for a ``video`` (its sequence) also its frames (``step``, ``max_frames``), ``motion_mask``,
    ``refine_focal`` and its camera: ``camera`` the calibration's file (``"calibration"`` for one given in Python,
    ``"K"`` for intrinsics) and ``distortion`` whether the reconstruction modelled the lens's (the model's
    ``extra["K"]``, ``extra["dist"]``); ``box_units``: the units the box's size was read in, where one was given."""
    used = {key: settings[key] for key in ("feature", "n_features", "normalization")}
    if video is not None:
        camera = settings.get("camera")
        used.update(
            step=settings["step"],
            max_frames=settings["max_frames"],
            motion_mask=settings["motion_mask"],
            refine_focal=settings["refine_focal"],
            camera="K" if camera is None else str(camera) if isinstance(camera, str | Path) else "calibration",
            distortion=video.views[0].dist is not None,
        )
    if box_units:
        used["box_units"] = box_units
    return {"conf": conf, **used}


def _check_frame_size(video: Path, image_size: tuple[int, int], camera: str) -> None:
    """Raise :class:`InputError` when the first frame of ``video`` is not ``image_size`` ``(width, height)``, the size
    that ``camera`` (the message's name of a calibration or a preset's intrinsics) is for
    (:func:`pose.track.check_frame_size`)."""
    from pose.track import check_frame_size

    with io.FrameReader(video, max_frames=1) as frames:
        frame = next(frames)[1]
    check_frame_size(frame.shape[1::-1], image_size, f"{video}: its frames are", camera)


def build_options(settings: Mapping[str, Any]) -> list[str]:
    """The command-line options of ``alcn pose build`` that give :func:`main` the keyword arguments ``settings``
    (:data:`COOKIE_BOX`, say), for a script that runs the command: ``alcn pose build VIDEO OUT --box-ply PLY
    *build_options(COOKIE_BOX)``. Numbers are written in full (``repr``), so that the command builds from the same
    values as :func:`main` does; a switch is ``--X`` when ``True`` and ``--no-X`` when ``False``, so that it overrides
    a preset's value (``--conf static-camera`` with ``build_options({"motion_mask": False})``: no motion mask).

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
            options += [option if value else "--no-" + option[2:]]
        elif isinstance(value, int | float | str):  # str(float) is its repr: in full
            options += [option, str(value)]
        else:
            raise InputError(f"{key}={value!r}: no option of alcn pose build gives it (a number, a string or a switch)")
    return options
