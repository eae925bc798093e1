"""Registration of a training sequence: a camera pose for every frame, in millimetres (SfM without a known length:
in its arbitrary units).

Two paths:

- **ChArUco** (:func:`register_charuco`): a ChArUco board lies in the scene. Each frame's pose
  is the board's, from ``cv2.solvePnPGeneric`` with ``SOLVEPNP_IPPE`` (Collins & Bartoli,
  IJCV 2014: both solutions of the planar problem) refined by ``cv2.solvePnPRefineLM``. A frame
  is dropped, and the reason reported, when the board is not found, too few corners are seen,
  the reprojection error is too large, or the two IPPE solutions explain the corners almost
  equally well (the planar pose ambiguity). The world frame is the board's (mm, z = 0 on the
  board, x right and y down along the printed board).
- **COLMAP** (:func:`register_colmap`): no board. pycolmap's SIFT extraction, exhaustive matching
  and incremental reconstruction (Schoenberger & Frahm, CVPR 2016) give poses up to a
  similarity; a similarity transform then brings them to millimetres from a known length
  (the distance between two camera centres) or from reference camera centres.

Output (both paths), in ``out_dir``:

- ``rgb/000000.png ...``: the registered frames (undistorted with the same K when the
  calibration has distortion, so that the pinhole ``cam_K`` holds exactly);
- ``scene_camera.json``: BOP ``cam_K``, ``cam_R_w2c``, ``cam_t_w2c`` (mm, or the arbitrary units) per image id,
  and an empty ``scene_gt.json`` (no objects annotated), written by :mod:`alcn_cv.formats.bop`;
- ``colmap/``: COLMAP text model (``PINHOLE`` camera, image names relative to ``rgb/``; poses in mm with a
  ``# Units: mm`` header, or, in arbitrary units, without a header; ``points3D.txt`` holds the SfM points on the
  COLMAP path and is empty on the ChArUco path) — what ``alcn pose build`` reads;
- ``registration.json``: the ``units`` (``"mm"`` or :data:`calib.conventions.ARBITRARY_UNITS`), and every input
  frame with its status, error and output id;
- ``registration.png``: per-frame errors and camera centres.

The folder is written under a temporary name and renamed when complete.
"""

from __future__ import annotations

import logging
import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from alcn_cv.data.manifest import atomic_output_dir
from alcn_cv.errors import InputError
from alcn_cv.formats import bop
from alcn_cv.formats.bop import BopFrame
from alcn_cv.formats.colmap import (
    ColmapImage,
    ColmapModel,
    ColmapPoint3D,
    camera_from_opencv,
    model_from_pycolmap,
    points_colmap_to_opencv,
    write_text_model,
)
from alcn_cv.io import count_frames, frame_progress, iter_frames, write_image, write_json

from .board import BoardSpec, Detection
from .camera import Calibration, explain_no_board
from .colmap_log import pycolmap_log
from .conventions import ARBITRARY_UNITS, colmap_from_bop_frames
from .undistort import Undistorter

logger = logging.getLogger(__name__)

__all__ = [
    "FrameRegistration",
    "Registration",
    "SfmSettings",
    "board_pose",
    "register_charuco",
    "register_colmap",
    "similarity_from_poses",
    "MIN_REGISTERED",
    "MIN_AMBIGUITY_RATIO",
]

#: Fewest registered frames for a usable training sequence.
MIN_REGISTERED = 2
#: :func:`board_pose` rejects a pose whose second IPPE solution has less than this times the reprojection error
#: of the first: the planar pose is ambiguous (a board seen nearly fronto-parallel, or small).
MIN_AMBIGUITY_RATIO = 1.5


@dataclass
class FrameRegistration:
    """What happened to one input frame of a registration: its pose, or why it was dropped.

    Attributes:
        name: input name, as :func:`alcn_cv.io.iter_frames` names it (the file stem, or
            ``frame_000123`` for videos).
        status: ``"ok"`` or the reason the frame was dropped.
        rms_px: RMS reprojection error of the pose (board corners or SfM points), px; NaN
            when no pose was estimated.
        num_points: corners or 3D points behind the pose.
        image_id: id in the output (``rgb/{id:06d}.png``) when registered.
        R_w2c, t_w2c: pose world -> camera (in the :attr:`Registration.units`) when registered.
    """

    name: str
    status: str
    rms_px: float = float("nan")
    num_points: int = 0
    image_id: int | None = None
    R_w2c: np.ndarray | None = None
    t_w2c: np.ndarray | None = None


@dataclass
class Registration:
    """A registered sequence: intrinsics of the output images, the per-frame results and the ``units`` of their
    poses (``"mm"``, or :data:`calib.conventions.ARBITRARY_UNITS` for SfM without a known length)."""

    K: np.ndarray
    image_size: tuple[int, int]
    frames: list[FrameRegistration] = field(default_factory=list)
    units: str = "mm"

    @property
    def registered(self) -> list[FrameRegistration]:
        return [f for f in self.frames if f.status == "ok"]

    @property
    def dropped(self) -> list[FrameRegistration]:
        return [f for f in self.frames if f.status != "ok"]


# -- ChArUco path ------------------------------------------------------------------------


def board_pose(
    detection: Detection,
    K: np.ndarray,
    dist: np.ndarray | None,
    min_points: int = 8,
    max_rms_px: float = 1.0,
) -> FrameRegistration:
    """Pose of the board (board -> camera, board units) from one detection.

    Args:
        detection: corners of the board (>= 4, not collinear).
        K, dist: intrinsics of the image the corners were found in.
        min_points: fewest corners accepted.
        max_rms_px: largest RMS reprojection error accepted.

    A pose whose two IPPE solutions explain the corners almost equally well (:data:`MIN_AMBIGUITY_RATIO`) is
    rejected as ambiguous.

    Returns:
        A :class:`FrameRegistration` with status ``"ok"`` and the pose, or the reason for rejection.
    """
    obj = detection.object_points.astype(np.float64)
    img = detection.image_points.astype(np.float64)
    n = len(obj)
    if n < min_points:
        return FrameRegistration("", f"too few board corners ({n} < {min_points})", num_points=n)
    ok, rvecs, tvecs, errors = cv2.solvePnPGeneric(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok or not len(rvecs):
        return FrameRegistration("", "solvePnP failed", num_points=n)
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, rvecs[0], tvecs[0])
    proj, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))
    R = cv2.Rodrigues(rvec)[0]
    t = tvec.reshape(3)
    if t[2] <= 0:
        return FrameRegistration("", "board behind the camera", rms, n)
    if rms > max_rms_px:
        return FrameRegistration("", f"reprojection error {rms:.2f} px > {max_rms_px:g} px", rms, n)
    errors = np.asarray(errors, float).ravel()
    if len(errors) > 1 and errors[1] < MIN_AMBIGUITY_RATIO * max(errors[0], 1e-3):
        return FrameRegistration(
            "", f"ambiguous planar pose (second solution error {errors[1]:.2f} px vs {errors[0]:.2f} px)", rms, n
        )
    return FrameRegistration("", "ok", rms, n, R_w2c=R, t_w2c=t)


def _write_outputs(
    tmp: Path,
    reg: Registration,
    points3d: Sequence[ColmapPoint3D] | None = None,
    images: Sequence[ColmapImage] | None = None,
) -> None:
    """scene_camera.json (+ empty scene_gt.json), colmap/, registration.json and registration.png."""
    from .report import plot_registration

    kept = reg.registered
    frames = [
        BopFrame(f.image_id, tmp / "rgb" / f"{f.image_id:06d}.png", reg.K, 1.0, [], f.R_w2c, f.t_w2c) for f in kept
    ]
    bop.write_scene(tmp, frames)
    cameras, bop_images = colmap_from_bop_frames(frames, reg.image_size)
    units = reg.units if reg.units != ARBITRARY_UNITS else None
    write_text_model(tmp / "colmap", cameras, bop_images if images is None else images, points3d, units=units)
    write_json(
        tmp / "registration.json",
        {
            "units": reg.units,
            "image_size": list(reg.image_size),
            "cam_K": reg.K.reshape(-1).tolist(),
            "colmap_image_path": "rgb",
            "num_frames": len(reg.frames),
            "num_registered": len(kept),
            "frames": [
                {
                    "name": f.name,
                    "status": f.status,
                    "image_id": f.image_id,
                    "rms_px": None if not np.isfinite(f.rms_px) else round(float(f.rms_px), 4),
                    "num_points": f.num_points,
                }
                for f in reg.frames
            ],
        },
    )
    centers = np.array([-f.R_w2c.T @ f.t_w2c for f in kept]).reshape(-1, 3)
    plot_registration(
        [f.name for f in reg.frames],
        [f.rms_px for f in reg.frames],
        [f.status == "ok" for f in reg.frames],
        centers,
        tmp / "registration.png",
        title=f"{len(kept)} of {len(reg.frames)} frames registered ({reg.units})",
    )


def _check_enough(reg: Registration, hint: str) -> None:
    if len(reg.registered) < MIN_REGISTERED:
        reasons: dict[str, int] = {}
        for f in reg.dropped:
            reasons[f.status] = reasons.get(f.status, 0) + 1
        listing = "; ".join(f"{n} x {r}" for r, n in sorted(reasons.items(), key=lambda kv: -kv[1])[:4])
        raise InputError(
            f"only {len(reg.registered)} of {len(reg.frames)} frames registered (at least "
            f"{MIN_REGISTERED} needed); dropped: {listing or 'none'}. {hint}"
        )


def register_charuco(
    source: str | os.PathLike,
    out_dir: str | os.PathLike,
    calib: Calibration,
    board: BoardSpec,
    step: int = 1,
    max_frames: int | None = None,
    min_points: int = 8,
    max_rms_px: float = 1.0,
    overwrite: bool = False,
    progress: bool = True,
) -> Registration:
    """Register a sequence (folder of images or video) with a ChArUco board in view.

    Args:
        source: folder of images or a video.
        out_dir: output folder (see the module docstring); must not exist unless ``overwrite``.
        calib: intrinsics of the camera (``alcn calib camera``); frames must have its size.
        board: the ChArUco board in the scene (its square size in mm sets the units).
        step, max_frames: use every ``step``-th frame, at most ``max_frames``.
        min_points, max_rms_px: reliability thresholds of :func:`board_pose`.
        overwrite: replace an existing ``out_dir``.

    Returns:
        The registration; dropped frames and their reasons are logged and written.

    Raises:
        InputError: not a ChArUco board, ``out_dir`` under a file, frames of another size than the
            calibration, the board found in no frame (with a diagnosis: :func:`calib.camera.explain_no_board`), or
            fewer than :data:`MIN_REGISTERED` frames registered.
        FileExistsError: ``out_dir`` exists (without ``overwrite``, or not an earlier output).
    """
    if board.kind != "charuco":
        raise InputError(
            "registration with a board needs a ChArUco board (partial views, identified corners); "
            "a chessboard's pose is ambiguous under rotation by 180 degrees"
        )
    source = Path(source)
    detector = board.detector()
    undistort = Undistorter(calib, keep_K=True)
    K = np.asarray(calib.K, float)
    reg = Registration(K, tuple(calib.image_size))
    found = markers = foreign = 0  # the board, and the ArUco markers seen: all of them, and those not on the board
    with atomic_output_dir(out_dir, overwrite=overwrite, marker="registration.json") as tmp:
        (tmp / "rgb").mkdir()
        frames = iter_frames(source, step, max_frames)
        for name, image in frame_progress(
            frames, count_frames(source, step, max_frames), desc="registering", disable=not progress
        ):
            image = undistort(image, name)
            det = detector(image)  # detect on the undistorted frame: the corners then follow K exactly
            markers += detector.last_num_markers
            foreign += detector.last_foreign_markers
            if det is None:
                others = detector.last_foreign_markers
                reason = "board not found" + (f" ({others} markers not on this board)" if others else "")
                reg.frames.append(FrameRegistration(name, reason))
                continue
            found += 1
            result = board_pose(det, K, None, min_points=min_points, max_rms_px=max_rms_px)
            result.name = name
            if result.status == "ok":
                result.image_id = len(reg.registered)
                write_image(tmp / "rgb" / f"{result.image_id:06d}.png", image)
            else:
                logger.info("%s dropped: %s", name, result.status)
            reg.frames.append(result)
        if reg.frames and not found:
            raise InputError(
                explain_no_board(board, None, len(reg.frames), foreign, markers, frames="frame(s)", charuco_only=True)
            )
        too_far = any(f.rms_px > max_rms_px for f in reg.dropped)
        _check_enough(
            reg,
            "Check that the board is in view, in focus, and matches --cols/--rows/--dictionary"
            + ("; or relax --max-rms." if too_far else "."),
        )
        _write_outputs(tmp, reg)
    errs = np.array([f.rms_px for f in reg.registered])
    logger.info(
        "registered %d of %d frames (median board RMS %.3f px); dropped %d",
        len(reg.registered),
        len(reg.frames),
        float(np.median(errs)),
        len(reg.dropped),
    )
    return reg


# -- COLMAP path -------------------------------------------------------------------------


def similarity_from_poses(
    R_src: np.ndarray, C_src: np.ndarray, R_dst: np.ndarray, C_dst: np.ndarray
) -> tuple[float, np.ndarray, np.ndarray]:
    """Similarity ``x_dst = s R x_src + t`` that maps cameras of one frame onto another.

    The rotation is the chordal L2 mean (``scipy``'s ``Rotation.mean``) of ``R_dst_i^T R_src_i`` over cameras,
    so it is well defined from the orientations alone even when the centres are nearly
    collinear; then ``s`` and ``t`` are the least-squares fit of the centres with R fixed.

    Args:
        R_src, R_dst: float (N, 3, 3) world-to-camera rotations of the same N cameras.
        C_src, C_dst: float (N, 3) their centres, N >= 2 with distinct centres.

    Returns:
        ``(s, R (3, 3), t (3,))``.
    """
    R_src, R_dst = np.asarray(R_src, float), np.asarray(R_dst, float)
    C_src, C_dst = np.asarray(C_src, float), np.asarray(C_dst, float)
    if len(C_src) < 2 or R_src.shape != R_dst.shape or C_src.shape != C_dst.shape:
        raise InputError("a similarity needs at least 2 cameras known in both frames")
    from scipy.spatial.transform import Rotation  # here: scipy.spatial takes 0.2 s to import (every `alcn` start)

    R = Rotation.from_matrix(np.einsum("nji,njk->nik", R_dst, R_src)).mean().as_matrix()
    a = C_src - C_src.mean(0)
    b = C_dst - C_dst.mean(0)
    denom = float((a**2).sum())
    if denom < 1e-12:
        raise InputError("the reference cameras share one centre; the scale is undefined")
    s = float(np.sum(b * (a @ R.T)) / denom)
    if s <= 0:
        raise InputError("the reconstruction cannot be aligned to the reference cameras (negative scale)")
    return s, R, C_dst.mean(0) - s * R @ C_src.mean(0)


def _apply_similarity(model: ColmapModel, s: float, R: np.ndarray, t: np.ndarray) -> None:
    """x' = s R x + t on a ColmapModel, in place: points move, poses follow."""
    for p in model.points3d.values():
        p.xyz = s * R @ p.xyz + t
    for im in model.images.values():
        # x_cam = R_i x + t_i = R_i (R^T (x' - t) / s) + t_i  ->  scale the camera frame by s.
        R_new = im.R_w2c @ R.T
        im.t_w2c = s * im.t_w2c - R_new @ t
        im.R_w2c = R_new


@dataclass(frozen=True)
class SfmSettings:
    """Settings of the reconstruction of :func:`register_colmap`.

    Attributes:
        step, max_frames: use every ``step``-th input frame, at most ``max_frames``.
        n_features: SIFT keypoints per image (``alcn calib register --n-features``, as the pose commands name
            the keypoints per image).
        num_threads: threads for pycolmap (-1 or 0: all).
        seed: random seed of the reconstruction.

    Raises:
        InputError: ``n_features`` below 1 or ``num_threads`` below -1, which pycolmap refuses only after the frames
            are written.
    """

    step: int = 1
    max_frames: int | None = None
    n_features: int = 4096
    num_threads: int = -1
    seed: int = 0

    def __post_init__(self) -> None:
        if self.n_features < 1:
            raise InputError(f"n_features must be at least 1 (SIFT keypoints per image), got {self.n_features}")
        if self.num_threads < -1:
            raise InputError(f"num_threads must be at least -1 (-1 or 0: all), got {self.num_threads}")


@dataclass
class _SfmFrames:
    """The input frames written for SfM: input names and output names (``000000.png`` ...), in input order."""

    names: list[str]
    out_names: list[str]
    size: tuple[int, int]

    def input_name(self, name: str) -> str | None:
        """The input frame that ``name`` means (its name, or a file name for its stem), or None."""
        for candidate in (name, Path(name).stem):
            if candidate in self.names:
                return candidate
        return None


def _listing(names: Sequence[str], most: int = 5) -> str:
    return ", ".join(names[:most]) + (" ..." if len(names) > most else "")


def _by_input_names(
    frames: _SfmFrames,
    known_distance: tuple[str, str, float] | None,
    reference: dict[str, tuple[np.ndarray, np.ndarray]] | None,
) -> tuple[tuple[str, str, float] | None, dict[str, tuple[np.ndarray, np.ndarray]] | None]:
    """``known_distance`` and ``reference`` with the names of the input frames they mean, checked before the
    reconstruction: a wrong name fails in seconds, not after the minutes of SfM.

    Raises:
        InputError: a ``known_distance`` frame that is no input frame or a distance that is not positive, or fewer
            than 2 ``reference`` poses of input frames.
    """
    after = "input frames, after --step/--max-frames"
    if known_distance is not None:
        a, b, mm = known_distance
        if not mm > 0:
            raise InputError(f"--known-distance: the distance {mm:g} mm must be positive")
        names = []
        for name in (a, b):
            found = frames.input_name(name)
            if found is None:
                raise InputError(
                    f"--known-distance: {name!r} is not an input frame ({after}: {_listing(frames.names)}); "
                    "give the file name or stem of one of them"
                )
            names.append(found)
        known_distance = (names[0], names[1], mm)
    if reference:
        found_names = {name: frames.input_name(name) for name in reference}
        matched = {found: reference[name] for name, found in found_names.items() if found is not None}
        if len(matched) < 2:
            raise InputError(
                f"--reference: {len(matched)} of its {len(reference)} poses ({_listing(list(reference))}) are of "
                f"input frames ({after}: {_listing(frames.names)}); the alignment needs 2"
            )
        reference = matched
    return known_distance, reference


def _write_sfm_frames(
    source: Path, rgb: Path, calib: Calibration | None, settings: SfmSettings, progress: bool
) -> _SfmFrames:
    """Undistort (with a calibration) and write the input frames to ``rgb/``; all must have one size."""
    undistort = Undistorter(calib, keep_K=True) if calib is not None else None
    names: list[str] = []
    size = None
    frames = iter_frames(source, settings.step, settings.max_frames)
    for name, image in frame_progress(
        frames,
        count_frames(source, settings.step, settings.max_frames),
        desc="preparing frames",
        disable=not progress,
    ):
        if undistort is not None:
            image = undistort(image, name)
        if size is None:
            size = (image.shape[1], image.shape[0])
        elif size != (image.shape[1], image.shape[0]):
            raise InputError(
                f"{name} is {image.shape[1]}x{image.shape[0]} but earlier frames are "
                f"{size[0]}x{size[1]}; all frames must have one size"
            )
        write_image(rgb / f"{len(names):06d}.png", image)
        names.append(name)
    if len(names) < 3:
        raise InputError(f"only {len(names)} frame(s); SfM needs at least 3 overlapping views")
    return _SfmFrames(names, [f"{i:06d}.png" for i in range(len(names))], size)


def _reconstruct(
    frames: _SfmFrames, rgb: Path, work: Path, calib: Calibration | None, settings: SfmSettings
) -> ColmapModel:
    """pycolmap SIFT extraction, exhaustive matching and incremental mapping; the largest model.

    With a calibration its shared ``PINHOLE`` camera is held fixed; without, one shared ``SIMPLE_PINHOLE``
    camera (one focal length) is estimated, its principal point held at the image centre.
    """
    import pycolmap

    reader = pycolmap.ImageReaderOptions()
    if calib is not None:
        cam = camera_from_opencv(calib.K, None, *frames.size)
        reader.camera_model = cam.model
        reader.camera_params = ",".join(repr(float(p)) for p in cam.params)
    else:
        # Square pixels, as in nearly every camera: with fx and fy both free, SfM trades one against the poses
        # (Middlebury's temple: fx 1383, fy 1514 for a true 1520, 1526; one focal length: 1516).
        reader.camera_model = "SIMPLE_PINHOLE"
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.sift.max_num_features = int(settings.n_features)
    extraction.num_threads = int(settings.num_threads)
    extraction.use_gpu = False
    db = work / "database.db"
    pycolmap.set_random_seed(int(settings.seed))
    n = len(frames.names)
    logger.info("extracting SIFT features from %d frames", n)
    pycolmap.extract_features(
        db,
        rgb,
        image_names=frames.out_names,
        camera_mode=pycolmap.CameraMode.SINGLE,
        reader_options=reader,
        extraction_options=extraction,
        device=pycolmap.Device.cpu,
    )
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = int(settings.num_threads)
    matching.use_gpu = False
    logger.info("matching %d pairs", n * (n - 1) // 2)
    pycolmap.match_exhaustive(db, matching_options=matching, device=pycolmap.Device.cpu)
    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = int(settings.num_threads)
    options.random_seed = int(settings.seed)
    options.multiple_models = False
    options.min_model_size = 3
    options.extract_colors = True
    if calib is not None:
        options.ba_refine_focal_length = False
        options.ba_refine_principal_point = False
        options.ba_refine_extra_params = False
        options.mapper.abs_pose_refine_focal_length = False
        options.mapper.abs_pose_refine_extra_params = False
    logger.info("incremental reconstruction")
    recs = pycolmap.incremental_mapping(db, rgb, work / "sparse", options=options)
    if not recs:
        raise InputError(
            f"pycolmap found no reconstruction in {n} frames: the frames need more "
            "overlap and texture (or use a ChArUco board and --method board)"
        )
    model = model_from_pycolmap(max(recs.values(), key=lambda r: r.num_reg_images()))
    if len(model.cameras) != 1:
        raise InputError("the reconstruction has several cameras; expected one shared camera")
    return model


def _scale_to_mm(
    model: ColmapModel,
    frames: _SfmFrames,
    known_distance: tuple[str, str, float] | None,
    reference: dict[str, tuple[np.ndarray, np.ndarray]] | None,
) -> None:
    """Bring the model to millimetres, in place: a similarity to reference poses, or a scale from a
    known distance between two camera centres; without either the units stay arbitrary (warned).
    The frames are named by their input names (:func:`_by_input_names`)."""
    by_out = {im.name: im for im in model.images.values()}
    registered = {name: by_out[out] for name, out in zip(frames.names, frames.out_names) if out in by_out}

    def image_of(name: str) -> ColmapImage:
        image = registered.get(name)
        if image is None:
            raise InputError(f"frame {name!r} was not registered by SfM; choose another frame as reference")
        return image

    if reference:
        known = [n for n in reference if n in registered]
        if len(known) < 2:
            raise InputError(
                f"only {len(known)} reference frame(s) were registered by SfM; the alignment "
                "needs 2 (give more reference poses)"
            )
        R_ref = np.array([reference[n][0] for n in known], float)
        C_ref = np.array(
            [-np.asarray(reference[n][0], float).T @ np.asarray(reference[n][1], float).reshape(3) for n in known]
        )
        s, R, t = similarity_from_poses(
            np.array([image_of(n).R_w2c for n in known]), np.array([image_of(n).center for n in known]), R_ref, C_ref
        )
        _apply_similarity(model, s, R, t)
    elif known_distance:
        a, b, mm = known_distance
        d = np.linalg.norm(image_of(a).center - image_of(b).center)
        if d < 1e-9:
            raise InputError(f"--known-distance: frames {a} and {b} have the same centre; choose two apart")
        _apply_similarity(model, float(mm) / d, np.eye(3), np.zeros(3))
    else:
        logger.warning(
            "no known length given: poses are in the arbitrary units of the reconstruction; pass "
            "--known-distance (or --reference) for millimetres"
        )


def _renumber_registered(
    model: ColmapModel,
    frames: _SfmFrames,
    rgb: Path,
    reg: Registration,
) -> tuple[list[ColmapPoint3D], list[ColmapImage]]:
    """Record every frame in ``reg`` and keep output ids contiguous: registered images are renamed
    in input order, the others removed; returns the model's points and images with the new ids."""
    K = reg.K
    by_out = {im.name: im for im in model.images.values()}
    new_id = {}
    for name, old in zip(frames.names, frames.out_names):
        image = by_out.get(old)
        if image is None:
            reg.frames.append(FrameRegistration(name, "not registered by SfM"))
            (rgb / old).unlink()
            continue
        image_id = len(new_id)
        new_id[image.image_id] = image_id
        obs = image.point3d_ids >= 0
        rms = _sfm_rms(model, image, K)
        reg.frames.append(FrameRegistration(name, "ok", rms, int(obs.sum()), image_id, image.R_w2c, image.t_w2c))
        if old != f"{image_id:06d}.png":
            os.replace(rgb / old, rgb / f"{image_id:06d}.png")
    images = []
    for im in model.images.values():
        images.append(
            ColmapImage(
                new_id[im.image_id] + 1,
                f"{new_id[im.image_id]:06d}.png",
                1,
                im.R_w2c,
                im.t_w2c,
                im.points2d,
                im.point3d_ids,
            )
        )
    points = list(model.points3d.values())
    for p in points:
        p.track = np.array([(new_id[i] + 1, k) for i, k in p.track], dtype=np.int64).reshape(-1, 2)
    return points, images


def register_colmap(
    source: str | os.PathLike,
    out_dir: str | os.PathLike,
    calib: Calibration | None = None,
    known_distance: tuple[str, str, float] | None = None,
    reference: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
    settings: SfmSettings = SfmSettings(),
    overwrite: bool = False,
    progress: bool = True,
) -> Registration:
    """Register a sequence without a board: pycolmap SfM, then a similarity to millimetres.

    The steps: write the (undistorted) frames, reconstruct (:func:`_reconstruct`), scale to
    millimetres (:func:`_scale_to_mm`), renumber the registered frames and write the outputs.

    Args:
        source: folder of images or a video.
        out_dir: output folder (see the module docstring).
        calib: known intrinsics (held fixed; frames are undistorted first). Without it, one
            shared ``SIMPLE_PINHOLE`` camera (one focal length: square pixels) is estimated, its
            principal point at the image centre — calibrate first if the lens distorts.
        known_distance: ``(name_a, name_b, mm)``: the distance between the centres of two
            input frames (names as :func:`alcn_cv.io.iter_frames` gives them, ``frame_000123``
            for videos; a file name with its suffix is accepted too). Sets the scale.
        reference: ``{input name: (R_w2c (3, 3), t_w2c (3,) in mm)}`` known poses of at least
            2 frames (names as for ``known_distance``): a full similarity
            (:func:`similarity_from_poses`) puts the model in that world frame, in mm.
        settings: frame sampling and reconstruction settings.
        overwrite: replace an existing ``out_dir``.

    Without ``known_distance`` or ``reference`` the units stay arbitrary (warned and
    recorded as ``"units": "arbitrary"`` (:data:`calib.conventions.ARBITRARY_UNITS`) in ``registration.json``;
    ``colmap/`` then has no ``# Units:`` header).

    Raises:
        InputError: ``out_dir`` under a file, fewer than 3 frames, a ``known_distance`` or fewer than 2
            ``reference`` frames that are no input frames (before the reconstruction), or no reconstruction.
        FileExistsError: ``out_dir`` exists (without ``overwrite``, or not an earlier output).
    """
    source = Path(source)
    units = "mm" if (known_distance or reference) else ARBITRARY_UNITS
    with (
        atomic_output_dir(out_dir, overwrite=overwrite, marker="registration.json") as tmp,
        tempfile.TemporaryDirectory() as work,
        pycolmap_log(logger),
    ):
        rgb = tmp / "rgb"
        rgb.mkdir()
        frames = _write_sfm_frames(source, rgb, calib, settings, progress)
        known_distance, reference = _by_input_names(frames, known_distance, reference)
        model = _reconstruct(frames, rgb, Path(work), calib, settings)
        _scale_to_mm(model, frames, known_distance, reference)
        (camera,) = model.cameras.values()
        K, _ = camera.to_opencv()
        reg = Registration(K, frames.size, units=units)
        points, images = _renumber_registered(model, frames, rgb, reg)
        _check_enough(reg, "The frames need more overlap and texture.")
        _write_outputs(tmp, reg, points, images)
    logger.info(
        "SfM registered %d of %d frames, %d points (units: %s)",
        len(reg.registered),
        len(reg.frames),
        len(points),
        reg.units,
    )
    return reg


def _sfm_rms(model: ColmapModel, image: ColmapImage, K: np.ndarray) -> float:
    """RMS reprojection error (px) of an image's triangulated keypoints."""
    idx = np.flatnonzero(image.point3d_ids >= 0)
    if not len(idx):
        return float("nan")
    X = np.array([model.points3d[int(i)].xyz for i in image.point3d_ids[idx]])
    uv = cv2.projectPoints(X, cv2.Rodrigues(image.R_w2c)[0], image.t_w2c, K, None)[0].reshape(-1, 2)
    err = uv - points_colmap_to_opencv(image.points2d[idx])
    return float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
