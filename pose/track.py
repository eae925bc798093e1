"""``alcn pose track``: the box's pose in every frame of a video or image folder.

Each frame is normalized, its parts are detected (``detector="features"``: :mod:`pose.parts`
with a part model; ``detector="corners"``: the corner CNN of :mod:`pose.corners`, whose ONNX
file replaces the part model) and the pose solved (:mod:`pose.solver`) with the previous
frame's pose as prior. Output:

* poses per frame as BOP ``scene_gt``-style JSON: ``{"<frame>": [{"obj_id": 1, "cam_R_m2c": [9 floats],
  "cam_t_m2c": [3 floats]}]}`` (the model's units; a lost frame has an empty list), plus a
  ``<name>_info.json`` with per-frame inlier counts, timings and the lost/recovered events;
* with ``overlay``, a video (``.mp4``/``.avi``) or a folder of PNGs with the box drawn in the
  colours of the paper's Fig. 1: ground truth green, ALCN blue, no normalization red
  (:data:`COLORS`; any other normalization yellow).
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import re
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from alcn_cv import io
from alcn_cv.enhance.registry import same_method
from alcn_cv.errors import InputError
from alcn_cv.io import check_writable, make_folder, output_path, write_json
from alcn_cv.report import machine
from pose import model as part_model
from pose.model import BOX_EDGES
from pose.parts import FeaturePartDetector, PartDetector
from pose.solver import PoseEstimate, PoseSolver, PoseTracker, project

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
    """Draw the 12 edges of the box ``corners (8, 3)`` under pose ``rvec, tvec`` on ``image`` in place."""
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


class OverlayWriter:
    """Writes overlay frames to a video (``.mp4``, ``.avi``, ...) or to a folder of PNGs named by frame (a path
    without a suffix, or an existing folder).

    A video is written under a temporary name (:func:`alcn_cv.io.atomic_path`) and renamed by
    :meth:`close`; used as a context manager, a video unfinished by an error is removed.

    Raises:
        InputError: a path with another suffix.
    """

    def __init__(self, path: str | Path, fps: float = 30.0) -> None:
        self.path = Path(path)
        self.fps = fps
        self._is_video = _overlay_is_video(self.path)
        self._video: cv2.VideoWriter | None = None
        self._stack = contextlib.ExitStack()

    def write(self, name: str, frame: np.ndarray) -> None:
        if self._is_video:
            if self._video is None:
                tmp = self._stack.enter_context(io.atomic_path(self.path))
                self._video = io.open_video_writer(tmp, self.fps, frame.shape[1::-1])
                self._stack.callback(self._video.release)  # runs before the rename
            self._video.write(frame)
        else:
            io.write_image(self.path / f"{name}.png", frame)

    def close(self) -> None:
        """Finish the video: :attr:`path` appears complete."""
        self._stack.close()
        self._video = None

    def __enter__(self) -> OverlayWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.__exit__(*exc)
        self._video = None


@dataclass
class TrackedFrame:
    """The pose found in one frame, the time it took and the keypoints detected."""

    name: str
    estimate: PoseEstimate
    seconds: float
    keypoints: int


def pose_to_bop(est: PoseEstimate, obj_id: int = 1) -> list[dict]:
    """One frame's entry of a BOP ``scene_gt``: ``[]`` when lost."""
    if not est.ok:
        return []
    return [{"obj_id": obj_id, "cam_R_m2c": est.R.ravel().tolist(), "cam_t_m2c": est.tvec.ravel().tolist()}]


#: fewer inliers than this loses a frame, per detector (the corner detector has at most 7 parts)
MIN_INLIERS = {"features": 12, "corners": 5}
#: a pose close to the tracker's prediction needs only this many (:class:`pose.solver.PoseSolver`'s
#: ``min_inliers_near_prior``). Measured on the data engine's sequences #1-#8 (SIFT, ALCN lite):
#: 10 near the prediction (5 deg, 5% of the distance) raised #8, the overexposed one, from
#: 56.7 to 76.7% correct poses and changed nothing else, with or without normalization; 8 inliers
#: anywhere also gave 80.0 on #8 but let wrong poses through on #1 without normalization (93.3 -> 80.0).
MIN_INLIERS_NEAR_PRIOR = {"features": 10, "corners": 4}
#: A pose found around the tracker's prediction with fewer than this share of the matches found there as
#: inliers is checked against the whole frame, whose pose replaces it (:class:`pose.solver.PoseTracker`'s
#: ``trusted_guided_ratio``); without one it is kept only with at least :data:`MIN_GUIDED_RATIO`. The
#: matches found around a wrong prediction lean toward it, and the pose solved from them stays near it:
#: on the data engine's sequences #1-#8 (`alcn data pose --frames 30`, seeds 0, 1, 2; ORB, 1000 keypoints,
#: as `track`, and SIFT, 2000, as `pose eval`; no normalization or ALCN lite: 8 runs, 1920 frames), the
#: wrong poses found there (> 10 deg or > 10% of the distance off) had a median of 43% of their matches as
#: inliers, the right ones 82%, but as few as 35% on the overexposed #8. Correct / wrong / lost frames: 1614 /
#: 145 / 161 without the check, 1724 / 44 / 152 with 0.6 and 0.3, no run with fewer correct ones. On five
#: of the runs (1009 / 83 / 108 without): 0.5 and 0.3 1049 / 44 / 107, 0.6 and 0.3 1063 / 32 / 105;
#: a single threshold loses right poses of #8: 0.5 1028 / 25 / 147, 0.4 1034 / 34 / 132, 0.3 1029 /
#: 49 / 122. The cookie box video tracked with ORB: 455 of 455 frames either way, the drawn box as close
#: to the image's edges (`alcn pose overlay-error`); 26 of its frames searched whole as well, 0.3 s each
#: (13 -> 10 fps on 2 cores; none with 0.5), and #1-#8 of seed 0 with ORB took 131 s instead of 76. The
#: corner detector is not checked: up to 4 candidates per corner, most of them wrong
#: (:data:`RANSAC_ITERATIONS`), leave its right poses a small share too.
TRUSTED_GUIDED_RATIO = {"features": 0.6, "corners": 0.0}
#: See :data:`TRUSTED_GUIDED_RATIO`.
MIN_GUIDED_RATIO = {"features": 0.3, "corners": 0.0}
#: RANSAC iterations per detector (a cap: USAC stops once confident). The corner detector's
#: candidates are few but mostly wrong (up to 4 per corner): on the data engine's sequences #1-#8
#: (no normalization) 5000 iterations raised the sum over the sequences of the % of correct poses
#: from 73 to 110. Features matched in the whole frame (first frame, lost tracking) can be 90%
#: wrong (24 correct of 270 on #5's first frame): 5000 iterations instead of 500 raised ALCN lite
#: on #5 from 93.3 to 100% (no other change) and no normalization on #2 86.7 -> 96.7, #8 0 -> 13.3,
#: #7 73.3 -> 70.0 (SIFT).
RANSAC_ITERATIONS = {"features": 5000, "corners": 5000}


def track(
    frames: Iterator[tuple[str, np.ndarray]],
    detector: PartDetector,
    tracker: PoseTracker,
    total: int | None = None,
    progress: bool = True,
) -> Iterator[tuple[TrackedFrame, np.ndarray]]:
    """Track the model through ``frames``; yields each frame's result and the frame itself.

    ``tracker.events`` collects the lost/recovered events.
    """
    for i, (name, frame) in enumerate(
        tqdm(frames, total=total, desc="track", unit="frame", leave=False, disable=not progress)
    ):
        t0 = time.perf_counter()
        est, corr = tracker.step(i, frame, detector)
        yield TrackedFrame(name, est, time.perf_counter() - t0, corr.keypoints), frame


def camera_matrix_for(
    model_K: np.ndarray | None, K: np.ndarray | None, model_path: str | Path, rtol: float = 0.02
) -> np.ndarray:
    """The intrinsics to track with: ``K`` when given, else those stored in the model (``model_K``,
    e.g. the focal length refined by ``alcn pose build --refine-focal``).

    Warns when both are given and an entry differs by more than ``rtol`` (the drawn box would
    take the wrong shape).

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
    if model_K is not None and not np.allclose(K, model_K, rtol=rtol, atol=1e-6):
        m = np.asarray(model_K, np.float64)
        logger.warning(
            "the given intrinsics (fx %.1f fy %.1f cx %.1f cy %.1f) differ from those %s was built with "
            "(fx %.1f fy %.1f cx %.1f cy %.1f); leave out --K/--camera to track with the model's",
            K[0, 0],
            K[1, 1],
            K[0, 2],
            K[1, 2],
            model_path,
            m[0, 0],
            m[1, 1],
            m[0, 2],
            m[1, 2],
        )
    return K


def _overlay_path(overlay: str | Path, source: str | Path) -> Path:
    """The overlay's path, checked before the tracking: a video or a folder of PNGs (:class:`OverlayWriter`), not
    the input."""
    overlay = Path(overlay)
    is_video = _overlay_is_video(overlay)
    if overlay.resolve() == Path(source).resolve():
        raise InputError(f"--overlay {overlay} is the input; write the overlay elsewhere")
    if is_video:
        check_writable(overlay)
    else:
        make_folder(overlay)
    return overlay


def _check_frame_size(frame: np.ndarray, image_size: tuple[int, int], what: str, of: str) -> None:
    """Raise :class:`InputError` when ``frame`` is not ``image_size`` ``(width, height)``, the size ``of`` is for;
    ``what`` (``"the frames of X are"``) begins the message."""
    if frame.shape[1::-1] != image_size:
        raise InputError(
            f"{what} {frame.shape[1]}x{frame.shape[0]} but {of} is for {image_size[0]}x{image_size[1]}; "
            "give the intrinsics at this resolution (--K or --camera)"
        )


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


def main(
    model_path: str | Path,
    source: str | Path,
    output: str | Path,
    K: np.ndarray | None = None,
    *,
    normalization: str | None = None,
    overlay: str | Path | None = None,
    method: str | None = None,
    n_features: int = 1000,
    min_inliers: int | None = None,
    reprojection_error: float | None = None,
    dist: np.ndarray | None = None,
    detector: str = "features",
    image_size: tuple[int, int] | None = None,
    progress: bool = True,
) -> dict:
    """Track the box through ``source`` and write ``output`` (scene_gt JSON, keyed by the frame
    names of :func:`alcn_cv.io.iter_frames`: ``frame_000000``, ... for a video, the file stems for a
    folder; the overlay PNGs are named alike). Its translations are in the model's units (``units`` in the
    ``_info.json`` beside it), where BOP's own are millimetres.

    Args:
        model_path: ``detector="features"``: a part model (``.npz``, ``alcn pose build``);
            ``detector="corners"``: a corner detector (``.onnx``, ``alcn pose train-corners``).
        normalization: the normalization applied first (default: the one the model was made after, recorded in it; a
            part model tracked after another one warns, a corner detector's is an error).
        K: ``(3, 3)`` intrinsics; default: those stored in the part model (:func:`camera_matrix_for`).
        min_inliers: default :data:`MIN_INLIERS` of the detector.
        method, reprojection_error: the RANSAC variant and inlier threshold (px); default
            :class:`~pose.solver.PoseSolver`'s.
        image_size: ``(width, height)`` the calibration of ``K`` and ``dist`` is for; frames of another size are an
            error.

    Returns:
        A summary dict: frames, tracked frames, the most frequent reason a frame was lost, fps, events.

    Raises:
        InputError: an output that is the input, a suffix other than ``.json`` (the poses) or a video's (the
            overlay, unless it has none or is an existing folder), frames of another size than the camera's, or
            settings out of range.
    """
    output = output_path(output, ".json", "the poses")  # before the tracking, not after it
    if overlay is not None:
        overlay = _overlay_path(overlay, source)
    # `not > 0`: a NaN threshold fails too (every point would be an outlier)
    if (
        (reprojection_error is not None and not reprojection_error > 0)
        or n_features < 0
        or (min_inliers is not None and min_inliers < 4)
    ):
        raise InputError(
            "reprojection_error must be > 0 px, n_features >= 0 (0: all) and min_inliers >= 4 (a pose needs 4 points); "
            f"got {reprojection_error}, {n_features} and {min_inliers}"
        )
    model_size = None
    if detector == "features":
        if Path(model_path).suffix.lower() == ".onnx":
            raise InputError(f"{model_path} is a corner detector: track with it by --detector corners")
        model = part_model.load(model_path)
        det: PartDetector = FeaturePartDetector(model, normalization or model.normalization, n_features=n_features)
        if normalization is not None and not same_method(normalization, model.normalization):
            logger.warning(
                "%s was built after the normalization %r; tracking after %r, its descriptors may not match",
                model_path,
                model.normalization,
                normalization,
            )
        normalization = normalization or model.normalization
        corners, units = model.corners, model.units
        model_K, model_size = model.extra.get("K"), model.extra.get("image_size")
    elif detector == "corners":
        from pose.corners import CornerDetector

        det = CornerDetector(model_path)
        if normalization not in (None, det.normalization_spec):
            raise InputError(
                f"{model_path} was trained after the normalization {det.normalization_spec!r}, not {normalization!r}"
            )
        normalization, corners, units = det.normalization_spec, det.corners, det.units
        model_K = None
    else:
        raise InputError(f"unknown detector {detector!r}; choose 'features' or 'corners'")
    if K is None and model_size is not None:  # the model's camera: it holds for frames of its size only
        image_size = tuple(model_size)
    scene_gt, info = {}, {}
    times = []
    with contextlib.ExitStack() as stack:
        reader: io.FrameReader | None = None
        frames: Iterator[tuple[str, np.ndarray]]
        if image_size is not None:
            image_size = tuple(int(v) for v in image_size)
            of = "the calibration" if K is not None else f"the camera of {model_path}"
            # the source opened once: its first frame checked before the tracking, then tracked with the rest
            reader = stack.enter_context(io.FrameReader(source))
            first = next(reader)
            # the first frame before the tracking, a folder's others as they come
            _check_frame_size(first[1], image_size, f"the frames of {source} are", of)
            frames = itertools.chain([first], reader)
        K = camera_matrix_for(model_K, K, model_path)
        tracker = make_tracker(
            detector,
            K,
            corners,
            dist=dist,
            method=method,
            min_inliers=min_inliers,
            reprojection_error=reprojection_error,
        )
        if reader is None:
            reader = frames = stack.enter_context(io.FrameReader(source))
        # the overlay video plays at the input's frame rate; a folder of images has none: 30 fps
        writer = stack.enter_context(OverlayWriter(overlay, reader.fps or 30.0)) if overlay is not None else None
        for res, frame in track(frames, det, tracker, io.count_frames(source), progress):
            if image_size is not None:  # a folder's images may differ in size: the camera holds for one
                _check_frame_size(frame, image_size, f"frame {res.name} of {source} is", of)
            scene_gt[res.name] = pose_to_bop(res.estimate)
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
                    draw_box(vis, corners, res.estimate.rvec, res.estimate.tvec, K, color_for(normalization), dist=dist)
                writer.write(res.name, vis)
    write_json(output, scene_gt)  # its folder made by the atomic write
    tracked = sum(bool(v) for v in scene_gt.values())
    # the reasons carry their frame's counts: grouped by their words, the first of the most frequent group
    lost = [(re.sub(r"[\d.]+%?", "#", r), r) for r in (f["lost_reason"] for f in info.values()) if r]
    most = Counter(words for words, _ in lost).most_common(1)[0][0] if lost else None
    summary = {
        "frames": len(scene_gt),
        "tracked": tracked,
        "lost_reason": next((r for words, r in lost if words == most), None),
        "fps": len(times) / max(sum(times), 1e-9),
        "normalization": normalization,
        "detector": detector,
        "model": str(model_path),
        "units": units,
        "events": [{"frame": f, "event": e, "reason": r} for f, e, r in tracker.events],
    }
    write_json(output.with_name(output.stem + "_info.json"), {"summary": summary, "machine": machine(), "frames": info})
    # the caller reports the summary (`alcn pose track` prints it): logged at INFO it was printed twice
    logger.debug("tracked %d of %d frames at %.1f fps -> %s", tracked, len(scene_gt), summary["fps"], output)
    return summary
