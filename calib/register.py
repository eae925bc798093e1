"""Registration of a training sequence: a camera pose for every frame, in millimetres.

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
- ``scene_camera.json``: BOP ``cam_K``, ``cam_R_w2c``, ``cam_t_w2c`` (mm) per image id, and an
  empty ``scene_gt.json`` (no objects annotated), written by :mod:`alcn_cv.formats.bop`;
- ``colmap/``: COLMAP text model (``PINHOLE`` camera, poses in mm with a ``# Units: mm``
  header, image names relative to ``rgb/``; ``points3D.txt`` holds the SfM points on the
  COLMAP path and is empty on the ChArUco path) — what ``alcn pose build`` reads;
- ``registration.json``: every input frame with its status, error and output id;
- ``registration.png``: per-frame errors and camera centres.

The folder is written under a temporary name and renamed when complete.
"""

from __future__ import annotations

import contextlib
import logging
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Sequence

import cv2
import numpy as np
from tqdm import tqdm

from alcn_cv.io import write_json
from alcn_cv.data.manifest import atomic_output_dir
from alcn_cv.errors import InputError
from alcn_cv.formats import bop
from alcn_cv.formats.bop import BopFrame
from alcn_cv.formats.colmap import ColmapImage, camera_from_opencv, model_from_pycolmap, write_text_model
from alcn_cv.io import IMAGE_SUFFIXES, VIDEO_SUFFIXES, is_video, list_images

from .board import BoardSpec, Detection
from .camera import Calibration, video_frame_count
from .conventions import colmap_from_bop_frames
from .undistort import Undistorter

logger = logging.getLogger(__name__)

__all__ = [
    "FrameResult",
    "Registration",
    "board_pose",
    "iter_frames",
    "register_charuco",
    "register_colmap",
    "similarity_from_poses",
    "MIN_REGISTERED",
]

#: Fewest registered frames for a usable training sequence.
MIN_REGISTERED = 2


@dataclass
class FrameResult:
    """What happened to one input frame.

    Attributes:
        name: input name (file name, or ``frame_000123`` for videos).
        status: ``"ok"`` or the reason the frame was dropped.
        rms_px: RMS reprojection error of the pose (board corners or SfM points), px; NaN
            when no pose was estimated.
        num_points: corners or 3D points behind the pose.
        image_id: id in the output (``rgb/{id:06d}.png``) when registered.
        R_w2c, t_w2c: pose world -> camera (mm) when registered.
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
    """A registered sequence: intrinsics of the output images and the per-frame results."""

    K: np.ndarray
    image_size: tuple[int, int]
    frames: list[FrameResult] = field(default_factory=list)
    units: str = "mm"
    out_dir: Path | None = None

    @property
    def registered(self) -> list[FrameResult]:
        return [f for f in self.frames if f.status == "ok"]

    @property
    def dropped(self) -> list[FrameResult]:
        return [f for f in self.frames if f.status != "ok"]


# -- input frames ------------------------------------------------------------------------

def iter_frames(source: str | os.PathLike, step: int = 1, max_frames: int | None = None) -> Iterator[tuple[str, np.ndarray]]:
    """Yield ``(name, BGR uint8 image)`` from a folder of images or a video, every ``step``-th
    frame, at most ``max_frames``."""
    source = Path(source)
    if step < 1:
        raise InputError(f"step must be >= 1, got {step}")
    count = 0
    if source.is_dir():
        for path in list_images(source)[::step]:
            if max_frames is not None and count >= max_frames:
                return
            image = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if image is None:
                raise InputError(f"{path}: cannot read this image (corrupt or unsupported format)")
            count += 1
            yield path.name, image
    elif source.is_file() and is_video(source):
        cap = cv2.VideoCapture(str(source))
        if not cap.isOpened():
            raise InputError(f"{source}: cannot open this video")
        try:
            index = 0
            while max_frames is None or count < max_frames:
                if not cap.grab():
                    break
                if index % step == 0:
                    ok, frame = cap.retrieve()
                    if not ok:
                        break
                    count += 1
                    yield f"frame_{index:06d}", frame
                index += 1
        finally:
            cap.release()
        if count == 0:
            raise InputError(f"{source}: the video has no readable frame")
    elif source.exists():
        raise InputError(f"{source}: expected a folder of images ({', '.join(sorted(IMAGE_SUFFIXES))}) or a video "
                         f"({', '.join(sorted(VIDEO_SUFFIXES))})")
    else:
        raise InputError(f"{source}: no such file or folder")


def _num_frames(source: Path, step: int, max_frames: int | None) -> int | None:
    if source.is_dir():
        n = -(-len(list_images(source)) // step)
    else:
        total = video_frame_count(source)
        n = -(-total // step) if total else None
    return n if max_frames is None or n is None else min(n, max_frames)


# -- ChArUco path ------------------------------------------------------------------------

def board_pose(detection: Detection, K: np.ndarray, dist: np.ndarray | None, min_points: int = 8,
               max_rms_px: float = 1.0, min_ambiguity_ratio: float = 1.5) -> FrameResult:
    """Pose of the board (board -> camera, board units) from one detection.

    Args:
        detection: corners of the board (>= 4, not collinear).
        K, dist: intrinsics of the image the corners were found in.
        min_points: fewest corners accepted.
        max_rms_px: largest RMS reprojection error accepted.
        min_ambiguity_ratio: the second IPPE solution must have at least this times the
            reprojection error of the first; below, the pose is ambiguous (nearly
            fronto-parallel or small board) and rejected.

    Returns:
        A :class:`FrameResult` with status ``"ok"`` and the pose, or the reason for rejection.
    """
    obj = detection.object_points.astype(np.float64)
    img = detection.image_points.astype(np.float64)
    n = len(obj)
    if n < min_points:
        return FrameResult("", f"too few board corners ({n} < {min_points})", num_points=n)
    ok, rvecs, tvecs, errors = cv2.solvePnPGeneric(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok or not len(rvecs):
        return FrameResult("", "solvePnP failed", num_points=n)
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, rvecs[0], tvecs[0])
    proj, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))
    R = cv2.Rodrigues(rvec)[0]
    t = tvec.reshape(3)
    if t[2] <= 0:
        return FrameResult("", "board behind the camera", rms, n)
    if rms > max_rms_px:
        return FrameResult("", f"reprojection error {rms:.2f} px > {max_rms_px:g} px", rms, n)
    errors = np.asarray(errors, float).ravel()
    if len(errors) > 1 and errors[1] < min_ambiguity_ratio * max(errors[0], 1e-3):
        return FrameResult("", f"ambiguous planar pose (second solution error {errors[1]:.2f} px vs "
                               f"{errors[0]:.2f} px)", rms, n)
    return FrameResult("", "ok", rms, n, R_w2c=R, t_w2c=t)


def _write_outputs(tmp: Path, reg: Registration, points3d=None, images: Sequence[ColmapImage] | None = None) -> None:
    """scene_camera.json (+ empty scene_gt.json), colmap/, registration.json and registration.png."""
    from .report import plot_registration

    kept = reg.registered
    frames = [BopFrame(f.image_id, tmp / "rgb" / f"{f.image_id:06d}.png", reg.K, 1.0, [], f.R_w2c, f.t_w2c)
              for f in kept]
    bop.write_scene(tmp, frames)
    cameras, bop_images = colmap_from_bop_frames(frames, reg.image_size)
    units = reg.units if reg.units != "arbitrary" else None
    write_text_model(tmp / "colmap", cameras, bop_images if images is None else images, points3d, units=units)
    write_json(tmp / "registration.json", {
        "units": reg.units,
        "image_size": list(reg.image_size),
        "cam_K": reg.K.reshape(-1).tolist(),
        "colmap_image_path": "rgb",
        "num_frames": len(reg.frames),
        "num_registered": len(kept),
        "frames": [
            {"name": f.name, "status": f.status, "image_id": f.image_id,
             "rms_px": None if not np.isfinite(f.rms_px) else round(float(f.rms_px), 4), "num_points": f.num_points}
            for f in reg.frames
        ],
    })
    centers = np.array([-f.R_w2c.T @ f.t_w2c for f in kept]).reshape(-1, 3)
    plot_registration([f.name for f in reg.frames], [f.rms_px for f in reg.frames],
                      [f.status == "ok" for f in reg.frames], centers, tmp / "registration.png",
                      title=f"{len(kept)} of {len(reg.frames)} frames registered ({reg.units})")


def _check_enough(reg: Registration, hint: str) -> None:
    if len(reg.registered) < MIN_REGISTERED:
        reasons: dict[str, int] = {}
        for f in reg.dropped:
            reasons[f.status] = reasons.get(f.status, 0) + 1
        listing = "; ".join(f"{n} x {r}" for r, n in sorted(reasons.items(), key=lambda kv: -kv[1])[:4])
        raise InputError(f"only {len(reg.registered)} of {len(reg.frames)} frames registered (at least "
                         f"{MIN_REGISTERED} needed); dropped: {listing or 'none'}. {hint}")


def register_charuco(source: str | os.PathLike, out_dir: str | os.PathLike, calib: Calibration, board: BoardSpec,
                     step: int = 1, max_frames: int | None = None, min_points: int = 8, max_rms_px: float = 1.0,
                     overwrite: bool = False) -> Registration:
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
        InputError: not a ChArUco board, frames of another size than the calibration, or
            fewer than :data:`MIN_REGISTERED` frames registered.
    """
    if board.kind != "charuco":
        raise InputError("registration with a board needs a ChArUco board (partial views, identified corners); "
                         "a chessboard's pose is ambiguous under rotation by 180 degrees")
    source = Path(source)
    detector = board.detector()
    undistort = Undistorter(calib, keep_K=True)
    K = np.asarray(calib.K, float)
    reg = Registration(K, tuple(calib.image_size))
    with atomic_output_dir(out_dir, overwrite=overwrite) as tmp:
        (tmp / "rgb").mkdir()
        frames = iter_frames(source, step, max_frames)
        for name, image in tqdm(frames, total=_num_frames(source, step, max_frames), desc="registering", unit="frame"):
            image = undistort(image, name)
            det = detector(image)  # detect on the undistorted frame: the corners then follow K exactly
            if det is None:
                foreign = detector.last_foreign_markers
                reason = "board not found" + (f" ({foreign} markers not on this board)" if foreign else "")
                reg.frames.append(FrameResult(name, reason))
                continue
            result = board_pose(det, K, None, min_points=min_points, max_rms_px=max_rms_px)
            result.name = name
            if result.status == "ok":
                result.image_id = len(reg.registered)
                if not cv2.imwrite(str(tmp / "rgb" / f"{result.image_id:06d}.png"), image):
                    raise OSError(f"cannot write {tmp / 'rgb'}")
            else:
                logger.info("%s dropped: %s", name, result.status)
            reg.frames.append(result)
        _check_enough(reg, "Check that the board is in view, in focus, and matches --cols/--rows/--dictionary; "
                           "or relax --max-rms.")
        _write_outputs(tmp, reg)
    reg.out_dir = Path(out_dir)
    errs = np.array([f.rms_px for f in reg.registered])
    logger.info("registered %d of %d frames (median board RMS %.3f px); dropped %d",
                len(reg.registered), len(reg.frames), float(np.median(errs)), len(reg.dropped))
    return reg


# -- COLMAP path -------------------------------------------------------------------------

def similarity_from_poses(R_src: np.ndarray, C_src: np.ndarray, R_dst: np.ndarray,
                          C_dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Similarity ``x_dst = s R x_src + t`` that maps cameras of one frame onto another.

    The rotation is the chordal mean (SVD projection) of ``R_dst_i^T R_src_i`` over cameras,
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
    M = np.einsum("nji,njk->ik", R_dst, R_src)  # sum of R_dst^T R_src
    U, _, Vt = np.linalg.svd(M)
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    a = C_src - C_src.mean(0)
    b = C_dst - C_dst.mean(0)
    denom = float((a ** 2).sum())
    if denom < 1e-12:
        raise InputError("the reference cameras share one centre; the scale is undefined")
    s = float(np.sum(b * (a @ R.T)) / denom)
    if s <= 0:
        raise InputError("the reconstruction cannot be aligned to the reference cameras (negative scale)")
    return s, R, C_dst.mean(0) - s * R @ C_src.mean(0)


def _apply_similarity(model, s: float, R: np.ndarray, t: np.ndarray) -> None:
    """x' = s R x + t on a ColmapModel, in place: points move, poses follow."""
    for p in model.points3d.values():
        p.xyz = s * R @ p.xyz + t
    for im in model.images.values():
        # x_cam = R_i x + t_i = R_i (R^T (x' - t) / s) + t_i  ->  scale the camera frame by s.
        R_new = im.R_w2c @ R.T
        im.t_w2c = s * im.t_w2c - R_new @ t
        im.R_w2c = R_new


@contextlib.contextmanager
def _quiet_colmap() -> Iterator[None]:
    """Keep COLMAP's (glog) INFO messages off stderr unless this module logs at DEBUG."""
    import pycolmap

    old = pycolmap.logging.minloglevel
    if not logger.isEnabledFor(logging.DEBUG):
        pycolmap.logging.minloglevel = 1  # WARNING
    try:
        yield
    finally:
        pycolmap.logging.minloglevel = old


def register_colmap(source: str | os.PathLike, out_dir: str | os.PathLike, calib: Calibration | None = None,
                    known_distance: tuple[str, str, float] | None = None,
                    reference: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
                    step: int = 1, max_frames: int | None = None, max_features: int = 4096,
                    num_threads: int = -1, seed: int = 0, overwrite: bool = False) -> Registration:
    """Register a sequence without a board: pycolmap SfM, then a similarity to millimetres.

    Args:
        source: folder of images or a video.
        out_dir: output folder (see the module docstring).
        calib: known intrinsics (held fixed; frames are undistorted first). Without it, one
            shared ``PINHOLE`` camera is estimated (principal point at the image centre) —
            calibrate first if the lens distorts.
        known_distance: ``(name_a, name_b, mm)``: the distance between the centres of two
            input frames (names as in the input: file names or ``frame_000123``). Sets the scale.
        reference: ``{input name: (R_w2c (3, 3), t_w2c (3,) in mm)}`` known poses of at least
            2 frames: a full similarity (:func:`similarity_from_poses`) puts the model in
            that world frame, in mm.
        step, max_frames: frame sampling.
        max_features: SIFT features per image.
        num_threads: threads for pycolmap (-1: all).
        seed: random seed of the reconstruction.
        overwrite: replace an existing ``out_dir``.

    Without ``known_distance`` or ``reference`` the units stay arbitrary (warned and
    recorded as ``"units": "arbitrary"`` in ``registration.json``).

    Raises:
        InputError: fewer than 3 frames, no reconstruction, or a reference naming unknown frames.
    """
    import pycolmap

    source = Path(source)
    reg_units = "mm" if (known_distance or reference) else "arbitrary"
    with (atomic_output_dir(out_dir, overwrite=overwrite) as tmp, tempfile.TemporaryDirectory() as work,
          _quiet_colmap()):
        work = Path(work)
        rgb = tmp / "rgb"
        rgb.mkdir()
        names: list[str] = []
        undistort = Undistorter(calib, keep_K=True) if calib is not None else None
        size = None
        for name, image in tqdm(iter_frames(source, step, max_frames), total=_num_frames(source, step, max_frames),
                                desc="preparing frames", unit="frame"):
            if undistort is not None:
                image = undistort(image, name)
            if size is None:
                size = (image.shape[1], image.shape[0])
            elif size != (image.shape[1], image.shape[0]):
                raise InputError(f"{name} is {image.shape[1]}x{image.shape[0]} but earlier frames are "
                                 f"{size[0]}x{size[1]}; all frames must have one size")
            cv2.imwrite(str(rgb / f"{len(names):06d}.png"), image)
            names.append(name)
        if len(names) < 3:
            raise InputError(f"only {len(names)} frame(s); SfM needs at least 3 overlapping views")
        out_names = [f"{i:06d}.png" for i in range(len(names))]
        w, h = size
        reader = pycolmap.ImageReaderOptions()
        if calib is not None:
            cam = camera_from_opencv(calib.K, None, w, h)
            reader.camera_model = "PINHOLE"
            reader.camera_params = ",".join(repr(float(p)) for p in cam.params)
        else:
            reader.camera_model = "PINHOLE"
        extraction = pycolmap.FeatureExtractionOptions()
        extraction.sift.max_num_features = int(max_features)
        extraction.num_threads = int(num_threads)
        extraction.use_gpu = False
        db = work / "database.db"
        pycolmap.set_random_seed(int(seed))
        logger.info("extracting SIFT features from %d frames", len(names))
        pycolmap.extract_features(db, rgb, image_names=out_names, camera_mode=pycolmap.CameraMode.SINGLE,
                                  reader_options=reader, extraction_options=extraction, device=pycolmap.Device.cpu)
        matching = pycolmap.FeatureMatchingOptions()
        matching.num_threads = int(num_threads)
        matching.use_gpu = False
        logger.info("matching %d pairs", len(names) * (len(names) - 1) // 2)
        pycolmap.match_exhaustive(db, matching_options=matching, device=pycolmap.Device.cpu)
        options = pycolmap.IncrementalPipelineOptions()
        options.num_threads = int(num_threads)
        options.random_seed = int(seed)
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
            raise InputError(f"pycolmap found no reconstruction in {len(names)} frames: the frames need more "
                             "overlap and texture (or use a ChArUco board and --board charuco)")
        rec = max(recs.values(), key=lambda r: r.num_reg_images())
        model = model_from_pycolmap(rec)
        (camera,) = model.cameras.values() if len(model.cameras) == 1 else (None,)
        if camera is None:
            raise InputError("the reconstruction has several cameras; expected one shared camera")
        K, _ = camera.to_opencv()

        by_out = {im.name: im for im in model.images.values()}
        to_out = dict(zip(names, out_names))

        def image_of(name: str) -> ColmapImage:
            if name not in to_out:
                raise InputError(f"{name!r} is not an input frame (known: {', '.join(names[:5])} ...)")
            image = by_out.get(to_out[name])
            if image is None:
                raise InputError(f"frame {name!r} was not registered by SfM; choose another frame as reference")
            return image

        def center_of(name: str) -> np.ndarray:
            return image_of(name).center

        if reference:
            known = [n for n in reference if to_out.get(n) in by_out]
            if len(known) < 2:
                raise InputError(f"only {len(known)} reference frame(s) were registered by SfM; the alignment "
                                 "needs 2 (give more reference poses)")
            R_ref = np.array([reference[n][0] for n in known], float)
            C_ref = np.array([-np.asarray(reference[n][0], float).T @ np.asarray(reference[n][1], float).reshape(3)
                              for n in known])
            s, R, t = similarity_from_poses(np.array([image_of(n).R_w2c for n in known]),
                                            np.array([center_of(n) for n in known]), R_ref, C_ref)
            _apply_similarity(model, s, R, t)
        elif known_distance:
            a, b, mm = known_distance
            d = np.linalg.norm(center_of(a) - center_of(b))
            if d < 1e-9 or not mm > 0:
                raise InputError(f"frames {a} and {b} have the same centre, or the distance {mm} is not positive")
            _apply_similarity(model, float(mm) / d, np.eye(3), np.zeros(3))
        else:
            logger.warning("no known length given: poses are in the arbitrary units of the reconstruction; pass "
                           "--known-distance (or --reference) for millimetres")

        reg = Registration(K, (w, h), units=reg_units)
        # Keep output ids contiguous: rename registered images in input order.
        new_id = {}
        for name, old in zip(names, out_names):
            image = by_out.get(old)
            if image is None:
                reg.frames.append(FrameResult(name, "not registered by SfM"))
                (rgb / old).unlink()
                continue
            image_id = len(new_id)
            new_id[image.image_id] = image_id
            obs = image.point3d_ids >= 0
            rms = _sfm_rms(model, image, K)
            reg.frames.append(FrameResult(name, "ok", rms, int(obs.sum()), image_id, image.R_w2c, image.t_w2c))
            if old != f"{image_id:06d}.png":
                os.replace(rgb / old, rgb / f"{image_id:06d}.png")
        images = []
        for im in model.images.values():
            images.append(ColmapImage(new_id[im.image_id] + 1, f"{new_id[im.image_id]:06d}.png", 1, im.R_w2c,
                                      im.t_w2c, im.points2d, im.point3d_ids))
        points = list(model.points3d.values())
        for p in points:
            p.track = np.array([(new_id[i] + 1, k) for i, k in p.track], dtype=np.int64).reshape(-1, 2)
        _check_enough(reg, "The frames need more overlap and texture.")
        _write_outputs(tmp, reg, points, images)
    reg.out_dir = Path(out_dir)
    logger.info("SfM registered %d of %d frames, %d points (units: %s)", len(reg.registered), len(reg.frames),
                len(points), reg.units)
    return reg


def _sfm_rms(model, image: ColmapImage, K: np.ndarray) -> float:
    """RMS reprojection error (px) of an image's triangulated keypoints."""
    idx = np.flatnonzero(image.point3d_ids >= 0)
    if not len(idx):
        return float("nan")
    X = np.array([model.points3d[int(i)].xyz for i in image.point3d_ids[idx]])
    x = (K @ (image.R_w2c @ X.T + image.t_w2c[:, None])).T
    uv = x[:, :2] / x[:, 2:]
    err = uv - (image.points2d[idx] - 0.5)
    return float(np.sqrt(np.mean(np.sum(err ** 2, axis=1))))

