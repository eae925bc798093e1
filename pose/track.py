"""``alcn pose track``: the box's pose in every frame of a video or image folder.

Each frame is normalized, its parts are detected (``detector="features"``: :mod:`pose.parts`
with a part model; ``detector="corners"``: the corner CNN of :mod:`pose.corners`, whose ONNX
file replaces the part model) and the pose solved (:mod:`pose.solver`) with the previous
frame's pose as prior. Output:

* poses per frame as BOP ``scene_gt``-style JSON: ``{"<frame>": [{"obj_id": 1, "cam_R_m2c": [9 floats],
  "cam_t_m2c": [3 floats]}]}``, object-to-camera (``x_cam = R x_obj + t``, ``R`` row-major), ``t`` in
  millimetres as BOP's (converted from the model's units; a lost frame has an empty list), plus a
  ``<name>_info.json`` with per-frame inlier counts, timings and the lost/recovered events (by frame name), written
  first: :func:`read_poses` tells poses of another run beside it (an interrupted one) by its ``poses_digest``, and
  :func:`tracked_camera` reads the camera the poses were solved with and the model's ``model_digest``;
* with ``overlay``, a video (``.mp4``/``.avi``) or a folder of PNGs with the box drawn in the
  colours of the paper's Fig. 1: ground truth green, ALCN blue, no normalization red
  (:data:`COLORS`; any other normalization yellow), written under a temporary name and renamed
  when complete (as the poses): an interrupted run leaves none, and an earlier one as it was.

The Python entry point is :func:`open_tracker`: the detector and tracker the command tracks with, set
up as it sets them up, one frame at a time (:meth:`BoxTracker.step`); :func:`main` is the command.
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import json
import logging
import re
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from alcn_cv import io
from alcn_cv.checks import check_array
from alcn_cv.enhance.registry import same_method
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.io import check_no_earlier_output, check_writable, output_path, read_json, write_json
from alcn_cv.report import machine
from pose import model as part_model
from pose.model import BOX_EDGES
from pose.parts import Correspondences, FeaturePartDetector, PartDetector
from pose.solver import PoseEstimate, PoseSolver, PoseTracker, project

if TYPE_CHECKING:
    from calib.camera import Calibration

logger = logging.getLogger(__name__)

#: BGR colours of the paper's Fig. 1.
COLORS = {"gt": (0, 200, 0), "alcn": (255, 80, 0), "none": (0, 0, 255)}
OTHER_COLOR = (0, 220, 255)


def color_for(name: str) -> tuple[int, int, int]:
    """Overlay colour (BGR) of a normalization (a name or ``NAME:KEY=VALUE...`` spec) or ``"gt"``."""
    from alcn_cv.enhance.registry import parse_spec

    return COLORS.get(parse_spec(name)[0], OTHER_COLOR)


def draw_box(
    image: np.ndarray,
    corners: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
    K: np.ndarray,
    color: tuple[int, int, int],
    thickness: int = 2,
    dist: np.ndarray | None = None,
) -> np.ndarray:
    """Draw the 12 edges of the box ``corners`` under the pose ``rvec, tvec`` on ``image`` in place; return it.

    Args:
        image: ``(H, W, 3)`` BGR (or ``(H, W)`` gray) uint8, drawn on.
        corners: ``(8, 3)`` the box's corners in the object's frame, in the units of ``tvec`` (a tracker's
            :attr:`BoxTracker.corners` and a :class:`~pose.solver.PoseEstimate`'s ``tvec`` are both in its ``units``).
        rvec, tvec: ``(3, 1)`` object to camera, OpenCV's convention.
        K: ``(3, 3)`` camera matrix of ``image``'s pixels.
        color: BGR.
        thickness: pixels.
        dist: the camera's distortion coefficients (a tracker's :attr:`BoxTracker.dist`: a calibrated camera's), or
            None.

    A pose that projects a corner to a non-finite point or beyond 1e5 px draws nothing."""
    uv = project(corners, rvec, tvec, K, dist)
    if not np.isfinite(uv).all() or np.abs(uv).max() > 1e5:
        return image
    p = np.round(uv * 16).astype(np.int32)
    for i, j in BOX_EDGES:
        cv2.line(image, tuple(p[i]), tuple(p[j]), color, thickness, cv2.LINE_AA, shift=4)
    return image


def _overlay_is_video(path: Path) -> bool:
    """Whether the overlay ``path`` is a video (:data:`alcn_cv.io.VIDEO_SUFFIXES`) rather than a folder of PNGs: a
    path without a suffix, or an existing folder (its name may hold a dot).

    Raises:
        InputError: any other suffix (``.gif``, an image's): it would silently have been a folder.
    """
    if io.is_video(path):
        return True
    if path.suffix and not path.is_dir():
        raise InputError(
            f"overlay {path}: a video ({', '.join(sorted(io.VIDEO_SUFFIXES))}) or a folder (no suffix, or an existing "
            "folder)"
        )
    return False


def _check_overlay_folder(path: Path, overwrite: bool) -> None:
    """Refuse an overlay folder that holds files, unless ``overwrite`` and it is an earlier overlay (PNGs only): its
    frames would have mixed with this run's (a shorter video left the earlier run's last frames in it).

    Raises:
        InputError: a folder of other files (never replaced), or an earlier overlay without ``overwrite``.
    """
    if not path.is_dir():
        return
    files = list(path.iterdir())
    if any(f.suffix.lower() != ".png" or not f.is_file() for f in files):
        raise InputError(
            f"overlay {path} is not an earlier overlay (it holds more than PNGs): not replaced; give another path"
        )
    if files and not overwrite:
        raise InputError(f"overlay {path} exists (--overwrite replaces it)")


class OverlayWriter:
    """Writes overlay frames to a video (``.mp4``, ``.avi``, ...) or to a folder of PNGs named by frame (a path
    without a suffix, or an existing folder).

    Either is written under a temporary name (:func:`alcn_cv.io.atomic_path`,
    :func:`alcn_cv.data.manifest.atomic_output_dir`) and renamed by :meth:`close`; used as a context manager, an
    overlay unfinished by an error or an interrupt is removed, and an earlier one is left as it was. A folder that
    holds PNGs (an earlier overlay) is replaced only with ``overwrite`` (a video is replaced as any output file).

    Raises:
        InputError: a path with another suffix; a folder that holds files (:func:`_check_overlay_folder`).
    """

    def __init__(self, path: str | Path, fps: float = 30.0, *, overwrite: bool = False) -> None:
        self.path = Path(path)
        self.fps = fps
        self._is_video = _overlay_is_video(self.path)
        if not self._is_video:
            _check_overlay_folder(self.path, overwrite)
        self._video: io.VideoFileWriter | None = None
        self._folder: Path | None = None
        self._stack = contextlib.ExitStack()

    def write(self, name: str, frame: np.ndarray) -> None:
        if self._is_video:
            if self._video is None:
                tmp = self._stack.enter_context(io.atomic_path(self.path))
                # closed (its file checked) before the rename
                self._video = self._stack.enter_context(
                    io.open_video_writer(tmp, self.fps, frame.shape[1::-1], name=self.path)
                )
            self._video.write(frame)
        else:
            if self._folder is None:
                from alcn_cv.data.manifest import atomic_output_dir

                # checked in __init__: absent, empty, or an earlier overlay that may be replaced; the marker that
                # atomic_output_dir asks of an earlier output is one of its PNGs
                marker = next((f.name for f in self.path.glob("*.png")), "") if self.path.is_dir() else ""
                self._folder = self._stack.enter_context(atomic_output_dir(self.path, overwrite=True, marker=marker))
            io.write_image(self._folder / f"{name}.png", frame)

    def close(self) -> None:
        """Finish the overlay: :attr:`path` appears complete.

        Raises:
            OSError: the video could not be written (:meth:`alcn_cv.io.VideoFileWriter.close`).
        """
        self._stack.close()
        self._video = self._folder = None

    def __enter__(self) -> OverlayWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.__exit__(*exc)
        self._video = self._folder = None


@dataclass
class TrackedFrame:
    """The pose found in one frame, the time it took and the keypoints detected."""

    name: str
    estimate: PoseEstimate
    seconds: float
    keypoints: int


#: The ``obj_id`` of the box in the poses ``alcn pose track`` writes (BOP's ids start at 1; one object is tracked).
OBJ_ID = 1


def pose_to_bop(est: PoseEstimate, mm_per_unit: float = 1.0) -> list[dict]:
    """One frame's entry of a BOP ``scene_gt`` (object :data:`OBJ_ID`): ``[]`` when lost. ``cam_t_m2c`` in mm, as
    BOP's: ``est.tvec``
    (in the model's units) times ``mm_per_unit`` (:func:`pose.model.unit_scale` of the model's units to ``"mm"``,
    :attr:`BoxTracker.mm_per_unit`)."""
    if not est.ok:
        return []
    t = est.tvec.ravel() * mm_per_unit
    return [{"obj_id": OBJ_ID, "cam_R_m2c": est.R.ravel().tolist(), "cam_t_m2c": t.tolist()}]


#: The units of ``cam_t_m2c`` in the poses ``alcn pose track`` writes (BOP's), recorded in the summary of its
#: ``_info.json`` as ``translation_units``; a file without that key was written in the model's units.
POSE_UNITS = "mm"

#: The entries of :func:`main`'s summary that are paths of the machine it ran on (the model read, the files written):
#: a report published elsewhere leaves them out (``experiments/calibration.py``).
SUMMARY_PATHS = ("model", "poses", "info", "overlay")


def info_path(poses: str | Path) -> Path:
    """The ``_info.json`` beside the poses ``poses`` (:func:`main` writes both)."""
    poses = Path(poses)
    return poses.with_name(poses.stem + "_info.json")


def poses_digest(scene_gt: dict) -> str:
    """SHA-256 of the poses ``scene_gt`` (:func:`main`'s, as read back from their JSON: the floats round-trip), the
    ``poses_digest`` of the ``_info.json`` that describes them."""
    return hashlib.sha256(json.dumps(scene_gt, sort_keys=True).encode()).hexdigest()


def read_poses(path: str | Path, units: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The ``(rvec, tvec)`` ``(3, 1)`` float64 (object to camera, ``tvec`` in ``units``, the model's) of every frame
    posed in ``path``, poses written by :func:`main` (``cam_t_m2c`` in mm). Poses written before they were in mm,
    in the model's units, are told by the ``_info.json`` beside them (no ``translation_units`` in its summary).

    Raises:
        DatasetError: not poses of :func:`main` (:func:`check_poses`), or the ``_info.json`` beside them is of other
            poses (its ``poses_digest``): a track interrupted between the two files, whose units are unknown.
    """
    path, info_file = Path(path), info_path(path)
    scene_gt = read_json(path)
    check_poses(scene_gt, path)  # before the info: a poses file of the wrong shape has no digest to compare
    info = read_json(info_file) if info_file.is_file() else {}
    digest = info.get("poses_digest")
    if digest is not None and digest != poses_digest(scene_gt):
        raise DatasetError(
            f"{info_file} describes other poses than {path} (a track interrupted between the two?): track again"
        )
    summary = info.get("summary", {})
    # an _info.json without translation_units: an earlier track's, in the model's units (main writes the info first,
    # so an interrupted run never leaves its poses beside an earlier info)
    written = summary.get("translation_units", units if summary else POSE_UNITS)
    scale = part_model.unit_scale(written, units)
    poses = {}
    for name, entry in scene_gt.items():
        if entry:
            R = np.asarray(entry[0]["cam_R_m2c"], np.float64).reshape(3, 3)
            t = np.asarray(entry[0]["cam_t_m2c"], np.float64).reshape(3, 1) * scale
            poses[name] = (cv2.Rodrigues(R)[0], t)
    return poses


#: The fields of a pose :func:`main` writes and :func:`read_poses` reads, and how many numbers each holds.
POSE_FIELDS = {"cam_R_m2c": 9, "cam_t_m2c": 3}


def check_poses(scene_gt: object, path: str | Path) -> None:
    """Check that ``scene_gt``, read from ``path``, has the shape of the poses :func:`main` writes: frame name ->
    a list, empty for a lost frame, whose first entry holds :data:`POSE_FIELDS` as that many finite numbers.

    Raises:
        DatasetError: another shape, naming the frame and field; the ``_info.json`` beside poses told as such.
    """
    if isinstance(scene_gt, dict) and isinstance(scene_gt.get("summary"), dict) and "frames" in scene_gt:
        poses = scene_gt["summary"].get("poses")
        raise DatasetError(
            f"{path}: the _info.json that `alcn pose track` writes beside its poses, not the poses"
            + (f" (they are {poses})" if isinstance(poses, str) else "")
        )
    not_poses = f"{path}: not a poses file of `alcn pose track` (frame -> [{{cam_R_m2c, cam_t_m2c}}])"
    if not isinstance(scene_gt, dict):
        raise DatasetError(f"{not_poses}: a JSON {type(scene_gt).__name__}")
    for name, entry in scene_gt.items():
        if not isinstance(entry, list) or (entry and not isinstance(entry[0], dict)):
            raise DatasetError(f"{not_poses}: frame {name!r} is no list of poses")
        for key, size in POSE_FIELDS.items() if entry else ():
            value = entry[0].get(key)
            try:
                numbers = np.asarray(value, np.float64)
            except (TypeError, ValueError):
                numbers = None
            if numbers is None or numbers.size != size or not np.isfinite(numbers).all():
                wrong = "missing" if value is None else f"not {size} finite numbers"
                raise DatasetError(f"{not_poses}: frame {name!r}: {key} is {wrong}")


def model_digest(path: str | Path) -> str:
    """SHA-256 of the model file ``path`` (a part model, or the corner CNN's ONNX file), the ``model_digest`` of the
    ``_info.json`` of the poses tracked with it."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def tracked_camera(path: str | Path, model_path: str | Path) -> tuple[np.ndarray, np.ndarray | None] | None:
    """The camera the poses at ``path`` were solved with, ``K (3, 3)`` and the distortion or None, as the
    ``_info.json`` beside them records it (``camera_matrix``, ``dist_coeffs``), checked against the part model the
    caller draws them with; None where there is no info, or an info from a track that did not record them and
    tracked with the model's camera.

    Raises:
        DatasetError: poses of the part model's features whose info records another model than ``model_path``, or
            ``model_path`` as it was before it was built again (``model_digest``, ``model_file``: drawn with that
            model's box, the poses would be judged against another object frame); a camera given to that track
            (``--K``, ``--camera``) that the info does not record.
    """
    path, info_file = Path(path), info_path(path)
    info = read_json(info_file) if info_file.is_file() else {}
    summary = info.get("summary", {})
    digest = info.get("model_digest")
    # the corner CNN's runs record its ONNX file: their box is the part model's it was trained from
    if summary.get("detector") != "corners" and digest is not None and digest != model_digest(model_path):
        recorded = info.get("model_file") or summary.get("model")
        if recorded and Path(recorded).resolve() == Path(model_path).resolve():
            raise DatasetError(f"{path} was tracked with {model_path} before it was built again: track again")
        raise DatasetError(
            f"{path} was tracked with {recorded or 'another model'}, another file than {model_path}: give that model"
        )
    if "camera_matrix" not in info:
        if summary.get("camera") == "given":
            raise DatasetError(
                f"{path} was tracked with a camera given to `alcn pose track` that {info_file.name} does not record: "
                "track again"
            )
        return None
    dist = info["dist_coeffs"]
    return np.asarray(info["camera_matrix"], np.float64), None if dist is None else np.asarray(dist, np.float64)


#: fewer inliers than this loses a frame, per detector (the corner detector has few parts: 26 by default,
#: :func:`pose.box.box_parts`, at most 19 of them seen at once)
MIN_INLIERS = {"features": 12, "corners": 5}
#: a pose close to the tracker's prediction needs only this many (:class:`pose.solver.PoseSolver`'s
#: ``min_inliers_near_prior``; ``docs/journal.md`` has the measurements).
MIN_INLIERS_NEAR_PRIOR = {"features": 10, "corners": 4}
#: A pose found around the tracker's prediction with fewer than this share of the matches found there as
#: inliers is checked against the whole frame, whose pose replaces it (:class:`pose.solver.PoseTracker`'s
#: ``trusted_guided_ratio``); without one it is kept only with at least :data:`MIN_GUIDED_RATIO`. The
#: matches found around a wrong prediction lean toward it, and the pose solved from them stays near it; right poses
#: have a larger share of their matches as inliers (``docs/journal.md`` has the measurements). The corner detector
#: is not checked: several candidates per part (``top_k`` of :class:`pose.corners.CornerDetector`, 5 by default, in
#: the whole frame), most of them wrong (:data:`RANSAC_ITERATIONS`), leave its right poses a small share too.
TRUSTED_GUIDED_RATIO = {"features": 0.6, "corners": 0.0}
#: See :data:`TRUSTED_GUIDED_RATIO`.
MIN_GUIDED_RATIO = {"features": 0.3, "corners": 0.0}
#: RANSAC iterations per detector (a cap: USAC stops once confident): the corner detector's candidates are few but
#: mostly wrong, and features matched in the whole frame (first frame, lost tracking) can be mostly wrong
#: (``docs/journal.md`` has the measurements).
RANSAC_ITERATIONS = {"features": 5000, "corners": 5000}


def track(
    frames: Iterator[tuple[str, np.ndarray]],
    *,
    tracker: BoxTracker,
    total: int | None = None,
    progress: bool = True,
    source: str | Path | None = None,
) -> Iterator[tuple[TrackedFrame, np.ndarray]]:
    """Track the box through ``frames`` (``(name, BGR frame)``) with ``tracker`` (:func:`open_tracker`); yields each
    frame's result and the frame itself. ``total``: the frames' count, for the progress bar; ``source``: what the
    frames are of, named in an error about a frame.

    ``tracker.events`` collects the lost/recovered events, by the frames' names.
    """
    for name, frame in io.frame_progress(frames, total, desc="track", leave=False, disable=not progress):
        t0 = time.perf_counter()
        if source is not None:  # the error names the source too; step checks the frame again, without it
            tracker.check_size(frame, f"frame {name} of {source} is")
        est = tracker.step(frame, name=name)
        keypoints = tracker.correspondences.keypoints if tracker.correspondences is not None else 0
        yield TrackedFrame(name, est, time.perf_counter() - t0, keypoints), frame


def camera_matrix_for(
    model_K: np.ndarray | None,
    K: np.ndarray | None,
    model_path: str | Path,
    rtol: float = 0.02,
    *,
    model_size: tuple[int, int] | None = None,
    frame_size: tuple[int, int] | None = None,
) -> np.ndarray:
    """The intrinsics to track with: ``K`` when given, else those stored in the model (``model_K``,
    e.g. the focal length refined by ``alcn pose build --refine-focal``).

    Warns when both are given and an entry differs by more than ``rtol`` (the drawn box would
    take the wrong shape) from the model's, or, for frames of ``frame_size`` ``(width, height)`` other than the
    ``model_size`` the model's camera is for, from the model's resized to them (:func:`pose.corners.scaled_camera`);
    the warning names the ``--K`` that tracks with the model's camera.

    Raises:
        InputError: neither is there.
    """
    if K is None:
        if model_K is None:
            raise InputError(
                f"{model_path} stores no camera: give the intrinsics (--K FX FY CX CY or "
                "--camera camera.yaml from `alcn calib camera`)"
            )
        K = np.asarray(model_K, np.float64)
        logger.info("camera of the model: fx %.1f fy %.1f cx %.1f cy %.1f", K[0, 0], K[1, 1], K[0, 2], K[1, 2])
        return K
    K = np.asarray(K, np.float64)
    if model_K is None:
        return K
    m, resized = np.asarray(model_K, np.float64), ""
    if model_size is not None and frame_size is not None and tuple(frame_size) != tuple(model_size):
        from pose.corners import scaled_camera

        m = scaled_camera(m, frame_size[0] / model_size[0], frame_size[1] / model_size[1])
        resized = f" resized from {model_size[0]}x{model_size[1]} to the frames' {frame_size[0]}x{frame_size[1]}"
    if not np.allclose(K, m, rtol=rtol, atol=1e-6):
        # without --K the model's camera is used only for frames of its size: for others the --K to give is named
        advice = (
            f"give --K {m[0, 0]:.2f} {m[1, 1]:.2f} {m[0, 2]:.2f} {m[1, 2]:.2f} to track with the model's"
            if resized
            else "leave out --K/--camera to track with the model's"
        )
        logger.warning(
            "the given intrinsics (fx %.1f fy %.1f cx %.1f cy %.1f) differ from those %s was built with%s "
            "(fx %.1f fy %.1f cx %.1f cy %.1f); %s",
            K[0, 0],
            K[1, 1],
            K[0, 2],
            K[1, 2],
            model_path,
            resized,
            m[0, 0],
            m[1, 1],
            m[0, 2],
            m[1, 2],
            advice,
        )
    return K


def _overlay_path(overlay: str | Path, source: str | Path, overwrite: bool = False) -> Path:
    """The overlay's path, checked before the tracking: a video or a folder of PNGs (:class:`OverlayWriter`), not
    the input, that can be written; a folder that holds files only with ``overwrite``
    (:func:`_check_overlay_folder`)."""
    overlay = Path(overlay)
    is_video = _overlay_is_video(overlay)
    if overlay.resolve() == Path(source).resolve():
        raise InputError(f"--overlay {overlay} is the input; write the overlay elsewhere")
    if overlay.exists() and not overlay.is_dir() and not is_video:
        raise InputError(f"cannot write the overlay folder {overlay}: it is a file")
    if not is_video:
        _check_overlay_folder(overlay, overwrite)
    check_writable(overlay)  # a folder: made beside it under a temporary name, renamed at the end
    return overlay


def check_frame_size(
    size: tuple[int, int], image_size: tuple[int, int], what: str, of: str, resized: np.ndarray | None = None
) -> None:
    """Raise :class:`InputError` when frames of ``size`` ``(width, height)`` are not ``image_size``, the size ``of``
    (a calibration, a model's camera) is for: ``alcn pose track`` for every frame, ``alcn pose build --camera`` for a
    video's first, before the work. ``what`` (``"the frames of X are"``) begins the message. ``resized``: the camera
    ``of`` is, whose resized copy the message names (the model's)."""
    w, h = int(size[0]), int(size[1])
    if (w, h) != (int(image_size[0]), int(image_size[1])):
        hint = "give the intrinsics at this resolution (--K or --camera)"
        if resized is not None:
            from pose.corners import scaled_camera

            k = scaled_camera(resized, w / image_size[0], h / image_size[1])
            hint += (
                f"; the model's camera resized to them, if they are its frames resized (not cropped): "
                f"--K {k[0, 0]:.2f} {k[1, 1]:.2f} {k[0, 2]:.2f} {k[1, 2]:.2f}"
            )
        raise InputError(f"{what} {w}x{h} but {of} is for {int(image_size[0])}x{int(image_size[1])}; {hint}")


def make_solver(
    detector: str,
    K: np.ndarray,
    outline: np.ndarray | None,
    *,
    dist: np.ndarray | None = None,
    method: str | None = None,
    min_inliers: int | None = None,
    reprojection_error: float | None = None,
) -> PoseSolver:
    """The :class:`~pose.solver.PoseSolver` of a ``detector`` (``"features"`` or ``"corners"``): its inliers and
    RANSAC iterations are the detector's (:data:`MIN_INLIERS`, :data:`MIN_INLIERS_NEAR_PRIOR`,
    :data:`RANSAC_ITERATIONS`); ``min_inliers`` overrides the first. ``outline``: the detector's box corners.
    ``method`` and ``reprojection_error``: ``None`` is :class:`~pose.solver.PoseSolver`'s own default."""
    min_inliers = MIN_INLIERS[detector] if min_inliers is None else min_inliers
    given = {"method": method, "reprojection_error": reprojection_error}
    return PoseSolver(
        K,
        dist,
        min_inliers=min_inliers,
        min_inliers_near_prior=min(MIN_INLIERS_NEAR_PRIOR[detector], min_inliers),
        iterations=RANSAC_ITERATIONS[detector],
        outline=outline,
        **{key: value for key, value in given.items() if value is not None},
    )


def make_tracker(
    detector: str,
    K: np.ndarray,
    outline: np.ndarray | None,
    *,
    dist: np.ndarray | None = None,
    method: str | None = None,
    min_inliers: int | None = None,
    reprojection_error: float | None = None,
) -> PoseTracker:
    """The :class:`~pose.solver.PoseTracker` of a ``detector`` around its :func:`make_solver` (same arguments):
    its checks of a pose near the prediction are the detector's (:data:`TRUSTED_GUIDED_RATIO`,
    :data:`MIN_GUIDED_RATIO`)."""
    solver = make_solver(
        detector,
        K,
        outline,
        dist=dist,
        method=method,
        min_inliers=min_inliers,
        reprojection_error=reprojection_error,
    )
    return PoseTracker(
        solver,
        trusted_guided_ratio=TRUSTED_GUIDED_RATIO[detector],
        min_guided_ratio=MIN_GUIDED_RATIO[detector],
    )


class BoxTracker:
    """The box's pose in one frame after another: a part detector and a :class:`~pose.solver.PoseTracker` set up as
    ``alcn pose track`` sets them up. Made by :func:`open_tracker`.

    Attributes:
        detector: the part detector (:class:`~pose.parts.FeaturePartDetector` or
            :class:`~pose.corners.CornerDetector`).
        tracker: the :class:`~pose.solver.PoseTracker` (its ``events``: the lost/recovered frames).
        K: ``(3, 3)`` float64 intrinsics tracked with (OpenCV pixel convention); ``dist``: their distortion or None.
        image_size: ``(width, height)`` the camera holds for (frames of another size are an error), or None.
        corners: ``(8, 3)`` float64 the box's corners in the object frame (:func:`pose.model.box_corners`' order),
            in :attr:`units`.
        units: the model's units (``"mm"``, ``"cm"`` or ``"m"``): of ``tvec`` and :attr:`corners`.
        mm_per_unit: millimetres per unit of :attr:`units` (``cam_t_m2c`` of :func:`pose_to_bop`).
        normalization: the normalization spec applied first.
        kind: ``"features"`` or ``"corners"``.
        camera: ``"model"`` (the camera stored in the part model, with its distortion) or ``"given"``.
        frames: frames stepped so far; correspondences: those of the last frame.
    """

    def __init__(
        self,
        detector: PartDetector,
        tracker: PoseTracker,
        *,
        kind: str,
        name: str,
        normalization: str,
        corners: np.ndarray,
        units: str,
        dist: np.ndarray | None,
        image_size: tuple[int, int] | None,
        camera: str,
        model_K: np.ndarray | None,
        model_size: tuple[int, int] | None,
    ) -> None:
        self.detector, self.tracker = detector, tracker
        self.kind, self.name, self.normalization = kind, name, normalization
        self.corners, self.units, self.mm_per_unit = corners, units, part_model.unit_scale(units, "mm")
        self.K, self.dist, self.image_size, self.camera = tracker.solver.K, dist, image_size, camera
        self._model_K, self._model_size = model_K, model_size
        self.frames = 0
        self.correspondences: Correspondences | None = None

    @property
    def events(self) -> list[tuple[int | str, str, str]]:
        """``(frame, "lost" | "recovered", reason)`` of the frames stepped so far: ``frame`` is the ``name`` given to
        :meth:`step`, else the frame's index among those stepped."""
        return self.tracker.events

    def check_size(self, frame: np.ndarray, what: str = "the frame is") -> None:
        """Raise :class:`InputError` when ``frame`` is not an image of :attr:`image_size` (``what`` begins the
        message)."""
        check_array(frame, what.rsplit(" ", 1)[0])  # "the frame is" -> "the frame"
        if self.image_size is not None:
            model = self.camera == "model"
            of = f"the camera of {self.name}" if model else "the calibration"
            check_frame_size(frame.shape[1::-1], self.image_size, what, of, self.K if model else None)

    def step(self, frame: np.ndarray, *, name: str | None = None) -> PoseEstimate:
        """The pose of the box in ``frame`` (BGR or grey uint8, the next frame of the sequence), its previous frames'
        poses as prior.

        Returns:
            A :class:`~pose.solver.PoseEstimate`: ``ok`` False when the frame is lost (``reason`` says why), else
            ``rvec``, ``tvec`` ``(3, 1)`` float64 object-to-camera (``x_cam = R x_obj + t``, OpenCV convention),
            ``tvec`` in :attr:`units` (times :attr:`mm_per_unit`: mm).

        ``name``: the frame's name in its source (``frame_000030``), which :attr:`events`, the log and an error give
        (default: its index among the frames stepped).

        Raises:
            InputError: a frame of another size than :attr:`image_size`.
        """
        self.check_size(frame, "the frame is" if name is None else f"frame {name} is")
        if self.frames == 0 and self.camera == "given":  # the given camera against the model's, at the frames' size
            camera_matrix_for(
                self._model_K, self.K, self.name, model_size=self._model_size, frame_size=frame.shape[1::-1]
            )
        # the tracker's index counts the frames stepped: its motion model predicts one index ahead
        est, self.correspondences = self.tracker.step(self.frames, frame, self.detector, name=name)
        self.frames += 1
        return est


def open_tracker(
    model: str | Path | part_model.PartModel,
    K: np.ndarray | None = None,
    *,
    camera: str | Path | Calibration | None = None,
    dist: np.ndarray | None = None,
    image_size: tuple[int, int] | None = None,
    detector: str = "features",
    normalization: str | None = None,
    n_features: int = 1000,
    n_features_global: int = 0,
    method: str | None = None,
    min_inliers: int | None = None,
    reprojection_error: float | None = None,
) -> BoxTracker:
    """The box tracker of ``alcn pose track`` (the command tracks with it): a part detector and a pose tracker with
    the command's settings, the camera and the normalization. Its :meth:`BoxTracker.step` gives the pose of one
    frame after another.

    Args:
        model: ``detector="features"``: a part model (``.npz`` of ``alcn pose build``, or a
            :class:`~pose.model.PartModel`); ``detector="corners"``: a corner detector (``.onnx`` of
            ``alcn pose train-corners``).
        K: ``(3, 3)`` intrinsics (OpenCV pixel convention); default: the camera stored in the part model
            (:func:`camera_matrix_for`; ``extra["K"]``, with its distortion ``extra["dist"]`` when the model was built
            with one, ``alcn pose build --camera``), which holds for frames of the size it stores only.
        camera: instead of ``K``: a ``camera.yaml`` of ``alcn calib camera`` or its
            :class:`~calib.camera.Calibration` (intrinsics, distortion and the frames' size).
        dist: ``K``'s distortion coefficients (OpenCV order), or None (without ``K``: the model's).
        image_size: ``(width, height)`` the calibration of ``K`` and ``dist`` is for; frames of another size are an
            error.
        normalization: the normalization applied first, ``NAME[:KEY=VALUE...]`` (default: the one the model was
            made after, recorded in it; a part model tracked after another one warns, a corner detector's is an
            error).
        n_features: keypoints per frame kept around the predicted box (0: all); ``n_features_global``: those kept
            where the whole frame is searched (first frame, tracking lost; 0: all, each a match against every
            descriptor of the model, the cost of a frame without the box).
        method, reprojection_error: the RANSAC variant and inlier threshold (px); default
            :class:`~pose.solver.PoseSolver`'s. ``min_inliers``: default :data:`MIN_INLIERS` of the detector.

    Raises:
        InputError: settings out of range, a corner detector given as a part model, a model without a camera and
            no ``K``, a camera given both as ``camera`` and as ``K`` (:func:`calib.camera.camera_once`), a camera
            with lens distortion for ``detector="corners"`` (the frames must be undistorted first).
        DatasetError: a calibration that is not one.

    Example: the cookie box, its model ``cb/model.npz`` built from its video (it stores the camera) by
    ``alcn pose build ../shared/data/cookie_box/box.mp4 cb/model.npz --box-ply ../shared/data/cookie_box/box.ply
    --conf cookie-box`` (:data:`pose.build.CONFS`; the box in cm); ``docs/pose.md`` walks through it::

        import cv2
        from pose.track import open_tracker

        box = open_tracker("cb/model.npz")  # the camera of the model; K=, camera="camera.yaml": another
        video = cv2.VideoCapture("../shared/data/cookie_box/box.mp4")
        while (frame := video.read()[1]) is not None:
            est = box.step(frame)
            if est.ok:  # rvec, tvec (3, 1): object to camera, tvec in box.units (cm here)
                R, t_mm = cv2.Rodrigues(est.rvec)[0], est.tvec.ravel() * box.mm_per_unit
                print(box.frames - 1, R.round(3).tolist(), t_mm.round(1).tolist())
            else:
                print(box.frames - 1, "lost:", est.reason)
    """
    # `not > 0`: a NaN threshold fails too (every point would be an outlier)
    if (
        (reprojection_error is not None and not reprojection_error > 0)
        or n_features < 0
        or n_features_global < 0
        or (min_inliers is not None and min_inliers < 4)
    ):
        raise InputError(
            "reprojection_error must be > 0 px, n_features and n_features_global >= 0 (0: all) and min_inliers >= 4 "
            f"(a pose needs 4 points); got {reprojection_error}, {n_features}, {n_features_global} and {min_inliers}"
        )
    from calib.camera import camera_once

    calibration = camera_once(camera, K, dist, image_size)
    if calibration is not None:
        K, dist, image_size = calibration.K, calibration.dist, calibration.image_size
    name = str(model) if isinstance(model, (str, Path)) else "the part model"
    model_size = model_dist = None
    if detector == "features":
        if isinstance(model, (str, Path)) and Path(model).suffix.lower() == ".onnx":
            raise InputError(f"{model} is a corner detector: track with it by --detector corners")
        pm = model if isinstance(model, part_model.PartModel) else part_model.load(model)
        det: PartDetector = FeaturePartDetector(
            pm, normalization or pm.normalization, n_features=n_features, n_features_global=n_features_global
        )
        if normalization is not None and not same_method(normalization, pm.normalization):
            logger.warning(
                "%s was built after the normalization %r; tracking after %r, its descriptors may not match",
                name,
                pm.normalization,
                normalization,
            )
        normalization = normalization or pm.normalization
        corners, units = pm.corners, pm.units
        model_K, model_size, model_dist = pm.extra.get("K"), pm.extra.get("image_size"), pm.extra.get("dist")
    elif detector == "corners":
        from pose.corners import CornerDetector

        if isinstance(model, part_model.PartModel):
            raise InputError("--detector corners tracks with a corner detector (.onnx), not a part model")
        cd = CornerDetector(model)
        if normalization not in (None, cd.normalization_spec):
            raise InputError(
                f"{model} was trained after the normalization {cd.normalization_spec!r}, not {normalization!r}"
            )
        if dist is not None and np.any(dist):
            raise InputError(
                "the camera has lens distortion, which the corner detector does not model; undistort the frames "
                "first (`alcn calib undistort --keep-K`) and track them with the camera's K"
            )
        det, normalization, corners, units = cd, cd.normalization_spec, cd.corners, cd.units
        model_K = None
    else:
        raise InputError(f"unknown detector {detector!r}; choose 'features' or 'corners'")
    given = K is not None
    if not given and model_size is not None:  # the model's camera: it holds for frames of its size only
        image_size = model_size
    if not given and dist is None and model_dist is not None:  # the lens distortion the model was built with
        dist = np.asarray(model_dist, np.float64)
    K = camera_matrix_for(model_K, K, name) if not given else np.asarray(K, np.float64)
    tracker = make_tracker(
        detector,
        K,
        corners,
        dist=dist,
        method=method,
        min_inliers=min_inliers,
        reprojection_error=reprojection_error,
    )
    return BoxTracker(
        det,
        tracker,
        kind=detector,
        name=name,
        normalization=normalization,
        corners=np.asarray(corners, np.float64),
        units=units,
        dist=dist,
        image_size=None if image_size is None else (int(image_size[0]), int(image_size[1])),
        camera="given" if given else "model",
        model_K=None if model_K is None else np.asarray(model_K, np.float64),
        model_size=None if model_size is None else (int(model_size[0]), int(model_size[1])),
    )


def main(
    model_path: str | Path,
    source: str | Path,
    output: str | Path,
    K: np.ndarray | None = None,
    *,
    camera: str | Path | Calibration | None = None,
    normalization: str | None = None,
    overlay: str | Path | None = None,
    overwrite: bool = False,
    method: str | None = None,
    n_features: int = 1000,
    n_features_global: int = 0,
    min_inliers: int | None = None,
    reprojection_error: float | None = None,
    dist: np.ndarray | None = None,
    detector: str = "features",
    image_size: tuple[int, int] | None = None,
    step: int = 1,
    max_frames: int | None = None,
    progress: bool = True,
) -> dict:
    """Track the box through ``source`` and write ``output`` (scene_gt JSON, keyed by the frame
    names of :func:`alcn_cv.io.iter_frames`: ``frame_000000``, ... for a video, the file stems for a
    folder; the overlay PNGs are named alike). Its rotations ``cam_R_m2c`` and translations ``cam_t_m2c`` are
    object-to-camera, the translations in mm as BOP's (:data:`POSE_UNITS`, the summary's ``translation_units``; the
    model's units are its ``units``). The ``_info.json`` beside it is written first (:func:`read_poses`).

    Args:
        model_path, K, camera, dist, image_size, detector, normalization, n_features, n_features_global, method,
            min_inliers, reprojection_error: the tracker's (:func:`open_tracker`).
        overlay: a video or a folder of PNGs (:class:`OverlayWriter`) to draw the box into.
        overwrite: replace the outputs of an earlier run: the poses, their ``_info.json`` and the overlay (without
            it, any of them that exists is an error, before the tracking).
        step, max_frames: track every ``step``-th frame, at most ``max_frames`` of them (default all; checked by
            :class:`alcn_cv.io.FrameReader`, before the tracking).

    Returns:
        A summary dict: frames, tracked frames, the most frequent reason a frame was lost, fps, events (by frame
        name), the camera (``"model"`` or ``"given"``), the units of the poses (``translation_units``) and the
        model's (``units``), and the paths (:data:`SUMMARY_PATHS`): the model, the poses, the info and the overlay.

    Raises:
        InputError: an output that is the input, a suffix other than ``.json`` (the poses) or a video's (the
            overlay, unless it has none or is an existing folder), an output of an earlier run without
            ``overwrite``, an overlay folder that holds other files than PNGs, frames of another size than the
            camera's, or settings out of range.
    """
    output = output_path(output, ".json", "the poses")  # before the tracking, not after it
    info_file = info_path(output)
    earlier = [output, info_file]
    if overlay is not None:
        overlay = _overlay_path(overlay, source, overwrite)  # a folder of an earlier overlay: checked there
        earlier += [overlay] if _overlay_is_video(overlay) else []
    check_no_earlier_output(earlier, overwrite)
    box = open_tracker(
        model_path,
        K,
        camera=camera,
        dist=dist,
        image_size=image_size,
        detector=detector,
        normalization=normalization,
        n_features=n_features,
        n_features_global=n_features_global,
        method=method,
        min_inliers=min_inliers,
        reprojection_error=reprojection_error,
    )
    scene_gt, info = {}, {}
    times = []
    with contextlib.ExitStack() as stack:
        # the source opened once (the reader checks step and max_frames first): its first frame checked before the
        # tracking, then tracked with the rest
        reader = stack.enter_context(io.FrameReader(source, step, max_frames))
        first = next(reader)
        box.check_size(first[1], f"the frames of {source} are")
        frames = itertools.chain([first], reader)
        # the overlay video plays at the input's frame rate (of the frames kept); a folder of images has none: 30 fps
        fps = reader.fps / step if reader.fps else 30.0
        writer = stack.enter_context(OverlayWriter(overlay, fps, overwrite=overwrite)) if overlay is not None else None
        total = io.count_frames(source, step, max_frames)
        for res, frame in track(frames, tracker=box, total=total, progress=progress, source=source):
            scene_gt[res.name] = pose_to_bop(res.estimate, mm_per_unit=box.mm_per_unit)
            info[res.name] = {
                "inliers": len(res.estimate.inliers),
                "matches": res.estimate.num_matches,
                "keypoints": res.keypoints,
                "seconds": res.seconds,
                "reprojection_error": res.estimate.reprojection_error if res.estimate.ok else None,
                "lost_reason": res.estimate.reason,
            }
            times.append(res.seconds)
            if writer is not None:
                vis = frame.copy()
                if res.estimate.ok:
                    color = color_for(box.normalization)
                    draw_box(vis, box.corners, res.estimate.rvec, res.estimate.tvec, box.K, color, dist=box.dist)
                writer.write(res.name, vis)
    # a truncated video's frames decoded are tracked, as they would be of a shorter one, but not in silence
    if io.is_short(len(scene_gt), total):
        logger.warning(
            "%s: decoded %d of the %d frames its header counts (truncated or corrupt video); tracked those",
            source,
            len(scene_gt),
            total,
        )
    tracked = sum(bool(v) for v in scene_gt.values())
    # the reasons carry their frame's counts: grouped by their words, the first of the most frequent group
    lost = [(re.sub(r"[\d.]+%?", "#", r), r) for r in (f["lost_reason"] for f in info.values()) if r]
    most = Counter(words for words, _ in lost).most_common(1)[0][0] if lost else None
    summary = {
        "frames": len(scene_gt),
        "tracked": tracked,
        "lost_reason": next((r for words, r in lost if words == most), None),
        "fps": len(times) / max(sum(times), 1e-9),
        "normalization": box.normalization,
        "detector": detector,
        "model": str(model_path),
        "camera": box.camera,
        "translation_units": POSE_UNITS,
        "units": box.units,
        "poses": str(output),
        "info": str(info_file),
        "overlay": None if overlay is None else str(overlay),
        "events": [{"frame": f, "event": e, "reason": r} for f, e, r in box.events],
    }
    # the info first (its folder made by the atomic write): an interrupted run leaves it beside the earlier poses,
    # which read_poses refuses by the digest, never its poses (mm) beside an earlier info (the model's units)
    record = {
        "summary": summary,
        "machine": machine(),
        "poses_digest": poses_digest(scene_gt),
        "model_file": str(Path(model_path).resolve()),
        "model_digest": model_digest(model_path),
        "camera_matrix": box.K.tolist(),
        "dist_coeffs": None if box.dist is None else np.ravel(box.dist).tolist(),
        "frames": info,
    }
    write_json(info_file, record)
    write_json(output, scene_gt)
    # the caller reports the summary (`alcn pose track` prints it): logged at INFO it was printed twice
    logger.debug("tracked %d of %d frames at %.1f fps -> %s", tracked, len(scene_gt), summary["fps"], output)
    return summary
