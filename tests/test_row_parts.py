"""The row parts of the OpenCV runtimes (:mod:`alcn_cv.row_parts`): the gain runtime gives the same output, bit for
bit, on any number of OpenCV threads."""

from __future__ import annotations

import os
import threading

import cv2
import numpy as np
import pytest

import alcn_cv.row_parts as row_parts_module
from alcn_cv.filters.gaussian_mixture import alcn_filter_grid
from alcn_cv.nets.opencv_runtime import cell_moments, cell_parts
from alcn_cv.row_parts import MIN_PART_PIXELS, MIN_PART_ROWS, row_parts, run_parts, submit


@pytest.fixture
def opencv_threads():
    """Set ``cv2.setNumThreads`` within a test, restored after it."""
    before = cv2.getNumThreads()
    yield cv2.setNumThreads
    cv2.setNumThreads(before)


@pytest.fixture
def small_parts(monkeypatch):
    """Parts of 32 rows and any number of pixels, so that the tests' small images are cut as large ones are."""
    monkeypatch.setattr(row_parts_module, "MIN_PART_ROWS", 32)
    monkeypatch.setattr(row_parts_module, "MIN_PART_PIXELS", 1)


@pytest.mark.parametrize(
    ("shape", "step", "count"),
    [((800, 1280), 8, 2), ((801, 1283), 8, 3), ((1000, 4000), 8, 5), ((120, 9000), 8, 4), ((50, 9000), 4, 2)],
)
def test_row_parts_cover_the_rows_from_multiples_of_the_step(shape, step, count):
    parts = row_parts(shape, step, count)
    assert parts[0][0] == 0 and parts[-1][1] == shape[0]
    assert all(stop == start for (_, stop), (start, _) in zip(parts, parts[1:]))
    assert all(start % step == 0 and stop > start for start, stop in parts)
    assert len(parts) == max(1, min(count, shape[0] // MIN_PART_ROWS, shape[0] * shape[1] // MIN_PART_PIXELS))


def test_row_parts_follow_opencv_threads_and_keep_small_images_whole(opencv_threads):
    opencv_threads(1)
    assert row_parts((2000, 2000), 8) == [(0, 2000)]
    opencv_threads(3)
    assert len(row_parts((2000, 2000), 8)) == 3
    assert row_parts((480, 640), 8) == [(0, 480)]  # fewer pixels than two parts need


def test_run_parts_returns_the_parts_in_order_and_raises_their_errors():
    assert run_parts(lambda start, stop: (start, stop, threading.current_thread().name), [(0, 1)])[0][2] == (
        threading.current_thread().name
    )  # the first part on the caller's thread
    assert [r[:2] for r in run_parts(lambda a, b: (a, b), [(0, 4), (4, 9), (9, 10)])] == [(0, 4), (4, 9), (9, 10)]

    def fail(start: int, stop: int) -> None:
        if start:
            raise ValueError(f"part {start}")

    with pytest.raises(ValueError, match="part 5"):
        run_parts(fail, [(0, 5), (5, 10)])
    assert submit(sum, [1, 2]).result() == 3


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork on this platform")
def test_a_forked_child_gets_threads_of_its_own():
    run_parts(lambda a, b: a, [(0, 1), (1, 2)])  # the pool exists in the parent
    pid = os.fork()
    if pid == 0:  # the child: the parent's pool threads are not here
        try:
            ok = run_parts(lambda a, b: a + b, [(0, 1), (1, 2)]) == [1, 3] and submit(int, "7").result(timeout=10) == 7
        finally:
            os._exit(0 if ok else 1)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0


@pytest.mark.parametrize("shape", [(200, 300), (203, 97)])
def test_alcn_filter_grid_rows_are_the_whole_outputs_rows(shape):
    rng = np.random.default_rng(3)
    image = rng.random(shape, dtype=np.float32)
    grid = rng.normal(size=(2, -(-(shape[0] - 1) // 8) + 1, -(-(shape[1] - 1) // 8) + 1)).astype(np.float32)
    whole = alcn_filter_grid(image, grid, 8, (1.0, 2.0))
    for rows in [(0, 100), (96, 150), (150, shape[0]), (7, 9)]:
        part = alcn_filter_grid(
            image, grid, 8, (1.0, 2.0), rows, dst=np.empty((rows[1] - rows[0], shape[1]), np.float32)
        )
        np.testing.assert_array_equal(part, whole[rows[0] : rows[1]])


@pytest.mark.parametrize("shape", [(800, 640), (801, 333), (97, 300), (200, 50)])
def test_cell_moments_in_parts_are_the_whole_images(shape, opencv_threads, small_parts):
    image = np.random.default_rng(4).random(shape, dtype=np.float32)
    opencv_threads(1)
    assert cell_parts(shape, 8) == [(0, -(-(shape[0] - 1) // 8) + 1)]
    whole = cell_moments(image, 8)
    for threads in (2, 3, 5):
        opencv_threads(threads)
        np.testing.assert_array_equal(cell_moments(image, 8), whole)


@pytest.mark.parametrize("backend", ["fast", "opencv"])
@pytest.mark.parametrize("model", ["gain", "gain-lite"])
def test_the_gain_runtime_gives_one_output_on_any_number_of_threads(backend, model, opencv_threads, small_parts):
    pytest.importorskip("torch") if backend == "fast" else None
    from alcn_cv.data.frames import synthetic_frame
    from alcn_cv.enhance.alcn import ALCN
    from alcn_cv.runtime import WindowRuntime

    runtime = ALCN(model=model, backend=backend).runtime
    for width, height in [(640, 400), (333, 251), (99, 64)]:
        gray = synthetic_frame(width, height, False, seed=width).astype(np.float32) / np.float32(255)
        sequential = WindowRuntime.normalize(runtime, gray)  # the same steps on the whole image, no parts
        floors = WindowRuntime.normalize(runtime, gray, 0.01, 0.02)
        for threads in (1, 2, 3, 4):
            opencv_threads(threads)
            assert len(row_parts(gray.shape, 8)) == min(threads, height // 32)
            np.testing.assert_array_equal(runtime.normalize(gray), sequential)
            np.testing.assert_array_equal(runtime.normalize(gray, 0.01, 0.02), floors)
