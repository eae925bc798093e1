"""``alcn pose bench-corners``: frames per second of the corner detector, torch-free.

Times :class:`pose.corners.CornerDetector` (normalization, ``cv2.dnn`` network, peaks) and the pose
solver over the frames of a video or image folder, in a tracking loop as ``alcn pose track`` runs
it, and reports the stages, the frames per second (wall clock), the CPU time per frame (all threads;
on a machine shared with other jobs the wall clock also counts their share), the machine's load and
whether torch was imported.
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
from alcn_cv.io import atomic_write, write_json
from alcn_cv.report import describe_machine, machine, markdown_table

logger = logging.getLogger(__name__)


def benchmark(onnx_path: str | Path, source: str | Path, K: np.ndarray, *, size: tuple[int, int] = (640, 480),
              max_frames: int = 60, repeats: int = 2, threads: int | None = None) -> dict[str, Any]:
    """Track through the first ``max_frames`` frames of ``source`` (resized to ``size``, ``K`` scaled
    alike) ``repeats`` times after one warm-up frame; per-stage milliseconds and frames per second.

    Args:
        onnx_path: a corner detector (``alcn pose train-corners``).
        source: a video or an image folder (:func:`alcn_cv.io.iter_frames`).
        K: intrinsics of ``source``'s frames at their own size.
        size: ``(width, height)`` the frames are resized to.
        threads: ``cv2.setNumThreads`` (default: OpenCV's).
    """
    from pose.corners import CornerDetector
    from pose.solver import PoseSolver, PoseTracker
    from pose.track import MIN_INLIERS, MIN_INLIERS_NEAR_PRIOR, RANSAC_ITERATIONS

    if threads is not None:
        cv2.setNumThreads(threads)
    frames = [f for _, f in io.iter_frames(source, max_frames=max_frames)]
    if not frames:
        raise InputError(f"{source}: no frame")
    h0, w0 = frames[0].shape[:2]
    K = np.asarray(K, np.float64).copy()
    K[0] *= size[0] / w0
    K[1] *= size[1] / h0
    frames = [cv2.resize(f, size, interpolation=cv2.INTER_AREA) for f in frames]
    det = CornerDetector(onnx_path)
    det.detect(frames[0])  # warm-up: cv2.dnn allocates on the first run
    total, posed = [], 0
    cpu0 = time.process_time()
    for _ in range(repeats):
        tracker = PoseTracker(PoseSolver(K, min_inliers=MIN_INLIERS["corners"], iterations=RANSAC_ITERATIONS["corners"],
                                         min_inliers_near_prior=MIN_INLIERS_NEAR_PRIOR["corners"], outline=det.corners))
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
    return {"detector": str(onnx_path), "normalizer": det.normalizer_name, "source": str(source),
            "size": list(size), "frames": len(frames), "repeats": repeats, "posed": posed / repeats,
            "ms": ms, "ms_per_frame": 1000 * per_frame, "cpu_ms_per_frame": 1000 * cpu,
            "fps": 1.0 / per_frame, "opencv_threads": cv2.getNumThreads(), "torch_imported": "torch" in sys.modules,
            "machine": machine()}


def main(onnx_path: str | Path, source: str | Path, K: np.ndarray, out: str | Path | None = None,
         command: str | None = None, **kwargs: Any) -> dict[str, Any]:
    """:func:`benchmark`, logged and, with ``out``, written as ``out/bench_corners.{md,json}``."""
    result = benchmark(onnx_path, source, K, **kwargs)
    logger.info("corner detector (%s) at %dx%d: %.1f fps (%.1f ms: normalize %.1f, network %.1f, peaks + pose "
                "%.1f), torch imported: %s", result["normalizer"], *result["size"], result["fps"],
                result["ms_per_frame"], *result["ms"].values(), result["torch_imported"])
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        md = (f"# Corner detector speed\n\nDetector `{onnx_path}` ({result['normalizer']} in front), "
              f"{result['frames']} frames of `{source}` at {result['size'][0]}x{result['size'][1]}, "
              f"{result['repeats']} passes, OpenCV threads {result['opencv_threads']}, torch imported: "
              f"{result['torch_imported']}.\n\nMachine: {describe_machine(result['machine'])}.\n\n"
              + (f"Command: `{command}`\n\n" if command else "")
              + markdown_table(["normalize (ms)", "network (ms)", "peaks + pose (ms)", "per frame (ms)", "fps",
                                "CPU per frame (ms, all threads)"],
                               [[*result["ms"].values(), result["ms_per_frame"], result["fps"],
                                 result["cpu_ms_per_frame"]]], digits=1))
        atomic_write(out / "bench_corners.md", md)
        write_json(out / "bench_corners.json", {**result, "command": command})
    return result
