"""An image's rows cut into parts computed on OpenCV's threads, for the OpenCV runtimes.

OpenCV's separable filters on float images (``cv2.sepFilter2D``, most of ALCN's time) run on one thread. The
gain runtime (:class:`~alcn_cv.runtime.GainRuntime`) cuts the image into one horizontal part per thread of
``cv2.getNumThreads()`` and computes each part, with the rows around it that it depends on, on a thread of its
own: the result is the whole image's, bit for bit, whatever the number of parts, and ``cv2.setNumThreads(1)``
makes the work sequential again, as for OpenCV's own parallel functions. OpenCV and NumPy release the GIL in
the calls that take the time. The threads are a pool shared by every runtime of the process (recreated in a
forked child).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TypeVar

import cv2

__all__ = ["MIN_PART_PIXELS", "MIN_PART_ROWS", "row_parts", "run_parts", "submit"]

#: The fewest rows a part may have (its blurs' margins are computed twice).
MIN_PART_ROWS = 64
#: The fewest pixels a part may have: below this the threads' hand-offs cost what the part saves (640x480 frames
#: ran slower in two parts than in one on the 2-core VM, 1280x800 frames faster).
MIN_PART_PIXELS = 2**18

T = TypeVar("T")
_pool: ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()


def _forget_pool() -> None:
    global _pool
    _pool = None  # a forked child has none of the parent's threads


if hasattr(os, "register_at_fork"):  # not on Windows, which has no fork
    os.register_at_fork(after_in_child=_forget_pool)


def _executor() -> ThreadPoolExecutor:
    global _pool
    with _pool_lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(max_workers=max(1, os.cpu_count() or 1), thread_name_prefix="alcn")
        return _pool


def row_parts(shape: tuple[int, int], step: int, count: int | None = None) -> list[tuple[int, int]]:
    """``[(start, stop), ...]``: the rows of an image of ``shape`` ``(H, W)`` cut into ``count`` parts (default: one
    per thread of ``cv2.getNumThreads()``; fewer where a part would have less than :data:`MIN_PART_ROWS` rows or
    :data:`MIN_PART_PIXELS` pixels), each starting on a multiple of ``step``.

    Example:
        >>> row_parts((800, 1280), 8, count=2)
        [(0, 400), (400, 800)]
    """
    height, width = shape
    most = min(height // MIN_PART_ROWS, height * width // MIN_PART_PIXELS)
    count = max(1, min(cv2.getNumThreads() if count is None else count, most))
    starts = sorted({round(height * i / count / step) * step for i in range(count)})
    return list(zip(starts, [*starts[1:], height]))


def run_parts(work: Callable[[int, int], T], parts: list[tuple[int, int]]) -> list[T]:
    """``[work(start, stop) for each part]``, the first part on the caller's thread, the others on the pool's."""
    futures = [_executor().submit(work, *part) for part in parts[1:]]
    first = work(*parts[0])
    return [first, *(future.result() for future in futures)]


def submit(work: Callable[..., T], *args: object) -> Future[T]:
    """``work(*args)`` on a thread of the pool, while the caller goes on."""
    return _executor().submit(work, *args)
