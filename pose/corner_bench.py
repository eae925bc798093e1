"""``alcn pose bench-corners`` and ``alcn pose corner-recall``: the corner detector's speed and recall.

:func:`benchmark` times :class:`pose.corners.CornerDetector` (normalization, ``cv2.dnn`` network,
peaks) and the pose solver over the frames of a video or image folder, in a tracking loop as
``alcn pose track`` runs it, and reports the stages, the frames per second (wall clock), the CPU
time per frame (all threads; on a machine shared with other jobs the wall clock also counts their
share), the machine's load and whether torch was imported.

:func:`corner_recall` measures the detections against the true corners of a BOP scene before
PnP, optionally with everything but the object replaced by grey: the measurement that tells a
detector that misses corners (recall) from one that places them badly or a solver that fails.
"""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from alcn_cv import io
from alcn_cv.errors import InputError
from alcn_cv.io import (
    atomic_paths,
    atomic_write,
    check_no_earlier_output,
    check_writable,
    make_folder,
    to_gray,
    write_json,
)
from alcn_cv.report import describe_machine, machine, markdown_table

logger = logging.getLogger(__name__)

#: The sides (pixels) :func:`benchmark` resizes frames to, each from :data:`MIN_SIDE` (the network's window,
#: :data:`pose.corners.WINDOW`) to :data:`MAX_SIDE` (4K; the frames are held in memory, 60 of 4096x4096 take 3 GB).
MIN_SIDE, MAX_SIDE = 32, 4096
#: The files ``alcn pose bench-corners --out`` writes.
REPORT_FILES = ("bench_corners.md", "bench_corners.json")


def benchmark(
    onnx_path: str | Path,
    source: str | Path,
    K: np.ndarray,
    *,
    size: tuple[int, int] = (640, 480),
    max_frames: int = 60,
    repeats: int = 2,
    threads: int | None = None,
) -> dict[str, Any]:
    """Track through the first ``max_frames`` frames of ``source`` (resized to ``size``, ``K`` scaled
    alike) ``repeats`` times after one warm-up frame; per-stage milliseconds and frames per second.

    Args:
        onnx_path: a corner detector (``alcn pose train-corners``).
        source: a video or an image folder (:func:`alcn_cv.io.iter_frames`).
        K: intrinsics of ``source``'s frames at their own size.
        size: ``(width, height)`` the frames are resized to, each side from :data:`MIN_SIDE` to :data:`MAX_SIDE`.
        max_frames, repeats: at least 1.
        threads: ``cv2.setNumThreads`` (default: OpenCV's).

    Raises:
        InputError: ``size``, ``max_frames`` or ``repeats`` out of range (before the frames are read), or a source
            without frames.
    """
    from pose.corners import CornerDetector, scaled_camera
    from pose.track import make_tracker

    check_settings(size, max_frames, repeats)
    if threads is not None:
        cv2.setNumThreads(threads)
    frames = [f for _, f in io.iter_frames(source, max_frames=max_frames)]
    if not frames:
        raise InputError(f"{source}: no frame")
    h0, w0 = frames[0].shape[:2]
    K = scaled_camera(K, size[0] / w0, size[1] / h0)
    frames = [cv2.resize(f, size, interpolation=cv2.INTER_AREA) for f in frames]
    det = CornerDetector(onnx_path)
    # warm-up: cv2.dnn allocates on the first run; on the first frame mirrored, other pixels, so that the first
    # frame timed is not served from the detector's cache of the last frame's maps (parts.same_frame)
    det.detect(cv2.flip(frames[0], 1))
    total, posed = [], 0
    cpu0 = time.process_time()
    for _ in range(repeats):
        tracker = make_tracker("corners", K, det.corners)
        for i, frame in enumerate(frames):
            t0 = time.perf_counter()
            est, _ = tracker.step(i, frame, det)
            total.append(time.perf_counter() - t0)
            posed += est.ok
    cpu = (time.process_time() - cpu0) / len(total)  # CPU seconds of all threads per frame
    stages = {"normalize": [], "network": []}  # the two stages alone, once more over the frames
    for frame in frames:
        t0 = time.perf_counter()
        normalized = det.normalize(frame)
        t1 = time.perf_counter()
        det.outputs(normalized)
        stages["normalize"].append(t1 - t0)
        stages["network"].append(time.perf_counter() - t1)
    per_frame = float(np.mean(total))
    ms = {k: 1000 * float(np.mean(v)) for k, v in stages.items()}
    ms["peaks_and_pose"] = 1000 * per_frame - ms["normalize"] - ms["network"]
    return {
        "detector": str(onnx_path),
        "normalization": det.normalization_spec,
        "source": str(source),
        "size": list(size),
        "frames": len(frames),
        "repeats": repeats,
        "posed": posed / repeats,
        "ms": ms,
        "ms_per_frame": 1000 * per_frame,
        "cpu_ms_per_frame": 1000 * cpu,
        "fps": 1.0 / per_frame,
        "opencv_threads": cv2.getNumThreads(),
        "torch_imported": "torch" in sys.modules,
        "machine": machine(),
    }


def check_settings(size: tuple[int, int], max_frames: int, repeats: int) -> None:
    """Check :func:`benchmark`'s ``size``, ``max_frames`` and ``repeats`` (the message names the options of ``alcn
    pose bench-corners``, which checks them as it parses them).

    Raises:
        InputError: a side of ``size`` outside :data:`MIN_SIDE` to :data:`MAX_SIDE`, or ``max_frames`` or
            ``repeats`` below 1.
    """
    if len(size) != 2 or not all(MIN_SIDE <= int(side) <= MAX_SIDE for side in size):
        raise InputError(f"--frame-size W H: each {MIN_SIDE} to {MAX_SIDE} pixels, got {' '.join(map(str, size))}")
    if max_frames < 1 or repeats < 1:
        raise InputError(f"--max-frames and --repeats must be at least 1, got {max_frames} and {repeats}")


def main(
    onnx_path: str | Path,
    source: str | Path,
    K: np.ndarray,
    out: str | Path | None = None,
    command: str | None = None,
    overwrite: bool = False,
    **kwargs: Any,
) -> dict[str, Any]:
    """:func:`benchmark`, logged and, with ``out``, written as ``out/bench_corners.{md,json}``.

    Args:
        onnx_path, source, K, kwargs: :func:`benchmark`'s.
        out: the report's folder (none: no report).
        command: the command line the report records.
        overwrite: replace the report of an earlier run in ``out``.

    Raises:
        InputError: a report in ``out`` without ``overwrite``, or an ``out`` that cannot be written (before the work),
            and :func:`benchmark`'s.
    """
    if out is not None:
        check_no_earlier_output([Path(out) / name for name in REPORT_FILES], overwrite)
        check_writable(Path(out) / REPORT_FILES[0])  # an --out under a file: refused now, not after the benchmark
    result = benchmark(onnx_path, source, K, **kwargs)
    logger.info(
        "corner detector (%s) at %dx%d: %.1f fps (%.1f ms: normalize %.1f, network %.1f, peaks + pose "
        "%.1f), torch imported: %s",
        result["normalization"],
        *result["size"],
        result["fps"],
        result["ms_per_frame"],
        *result["ms"].values(),
        result["torch_imported"],
    )
    if out is not None:
        out = Path(out)
        make_folder(out)
        md = (
            f"# Corner detector speed\n\nDetector `{onnx_path}` ({result['normalization']} in front), "
            f"{result['frames']} frames of `{source}` at {result['size'][0]}x{result['size'][1]}, "
            f"{result['repeats']} passes, OpenCV threads {result['opencv_threads']}, torch imported: "
            f"{result['torch_imported']}.\n\nMachine: {describe_machine(result['machine'])}.\n\n"
            + (f"Command: `{command}`\n\n" if command else "")
            + markdown_table(
                [
                    "normalize (ms)",
                    "network (ms)",
                    "peaks + pose (ms)",
                    "per frame (ms)",
                    "fps",
                    "CPU per frame (ms, all threads)",
                ],
                [[*result["ms"].values(), result["ms_per_frame"], result["fps"], result["cpu_ms_per_frame"]]],
                digits=1,
            )
        )
        with atomic_paths(*(out / name for name in REPORT_FILES)) as (md_path, json_path):  # both or neither
            atomic_write(md_path, md)
            write_json(json_path, {**result, "command": command})
    return result


def corner_recall(
    onnx_path: str | Path,
    scene_dir: str | Path,
    *,
    obj_id: int = 1,
    background: str = "keep",
    radius: float = 5.0,
    gate: float = 20.0,
) -> dict[str, Any]:
    """Recall of the corner detector on a BOP scene (``alcn data pose``), frame by frame.

    A visible part (:func:`pose.box.part_visibility` with the scene's ``mask_visib``)
    is found when a candidate of its own lies within ``radius`` pixels of its true projection:
    the best candidate of the whole frame (``best``), any of the ``top_k`` (``candidates``, what
    the tracker's first search gets), any of the ``gated_top_k`` within ``gate`` pixels of the
    true projection (``gated``, what tracking with a right prior gets). ``background_wins`` is
    the share of visible parts where the background class outscores the part's at the
    part's best cell nearby.

    Args:
        onnx_path: a corner detector (``alcn pose train-corners``).
        scene_dir: a BOP scene with ``scene_gt.json`` and ``mask_visib/``.
        background: ``"keep"``, or ``"grey"``: the pixels outside the object's mask set to 128,
            which removes the table and the clutter from the frames and keeps the object's views.

    Returns:
        ``{"frames", "visible", "best", "candidates", "gated", "background_wins", "per_part"
        (part index -> share found among the candidates), "per_frame" (dicts)}``; shares in [0, 1].

    Raises:
        InputError: an unknown ``background``, or a frame without the object or its mask.
    """
    from alcn_cv.formats import bop
    from pose.box import part_visibility
    from pose.corners import CornerDetector, grid_cell, to_scaled

    if background not in ("keep", "grey"):
        raise InputError(f"background must be 'keep' or 'grey', got {background!r}")
    det = CornerDetector(onnx_path)
    scene_dir = Path(scene_dir)
    n = len(det.parts)
    per_frame, found = [], {k: [] for k in range(n)}
    for fr in bop.load_scene(scene_dir).frames:
        index = fr.object_index(obj_id)
        if index is None:
            raise InputError(f"{scene_dir}: object {obj_id} is not annotated in frame {fr.im_id} (scene_gt.json)")
        mask = cv2.imread(str(scene_dir / "mask_visib" / f"{fr.im_id:06d}_{index:06d}.png"), cv2.IMREAD_GRAYSCALE)
        if mask is None:
            raise InputError(f"{scene_dir}: no mask_visib of object {obj_id} in frame {fr.im_id}")
        image = to_gray(io.read_image(fr.rgb_path))
        if background == "grey":
            image = np.where(mask > 0, image, np.uint8(128))
        pose = fr.objects[index]
        uv, visible = part_visibility(det.corners, pose.R, pose.t, fr.K, image.shape, mask, parts=det.parts)
        whole, gated = det.peaks(image), det.peaks(image, uv, gate)
        prob, _ = det.maps(image)
        row = {
            "frame": fr.im_id,
            "visible": int(visible.sum()),
            "best": 0,
            "candidates": 0,
            "gated": 0,
            "background_wins": 0,
        }
        for k in np.flatnonzero(visible):
            hits = np.linalg.norm(whole[k][0] - uv[k], axis=1) <= radius
            row["best"] += bool(hits[:1].any())
            row["candidates"] += bool(hits.any())
            row["gated"] += bool((np.linalg.norm(gated[k][0] - uv[k], axis=1) <= radius).any())
            found[k].append(bool(hits.any()))
            j, i = grid_cell(to_scaled(uv[k], det.scale))
            cells = prob[:, max(i - 1, 0) : i + 2, max(j - 1, 0) : j + 2].reshape(n + 1, -1)
            if cells.size:
                at = cells[:, cells[k + 1].argmax()]
                row["background_wins"] += bool(at[0] > at[k + 1])
        per_frame.append(row)
    total = max(sum(r["visible"] for r in per_frame), 1)
    shares = {key: sum(r[key] for r in per_frame) / total for key in ("best", "candidates", "gated", "background_wins")}
    return {
        "detector": str(onnx_path),
        "scene": str(scene_dir),
        "background": background,
        "frames": len(per_frame),
        "visible": sum(r["visible"] for r in per_frame),
        **shares,
        "per_part": {k: float(np.mean(v)) for k, v in found.items() if v},
        "per_frame": per_frame,
    }
