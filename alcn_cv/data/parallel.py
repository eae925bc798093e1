"""Ordered parallel map for the generators (processes; results identical for any worker count).

Every generator draws each item (a chunk of windows, an image, a sequence) from its own seed,
so rendering items in worker processes gives byte-identical datasets.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from typing import TypeVar

from tqdm import tqdm

from alcn_cv.errors import InputError

__all__ = ["parallel_map"]

T = TypeVar("T")
R = TypeVar("R")


def parallel_map(
    fn: Callable[[T], R],
    items: Iterable[T],
    *,
    workers: int = 1,
    desc: str = "",
    unit: str = "it",
    progress: bool = False,
) -> Iterator[R]:
    """Yield ``fn(item)`` for every item, in order, with a progress bar.

    Args:
        fn: a module-level function (it is pickled for the workers).
        items: its arguments (picklable).
        workers: processes; 1 runs in this process.
        desc, unit, progress: the progress bar.
    """
    if workers < 1:
        raise InputError(f"workers must be >= 1, got {workers}")
    items = list(items)
    with tqdm(total=len(items), desc=desc, unit=unit, disable=not progress) as bar:
        if workers == 1 or len(items) <= 1:
            for it in items:
                result = fn(it)
                bar.update()  # before the yield: a consumer that stops at the last item still sees it done
                yield result
            return
        # "spawn": no fork of a process that may hold OpenCV or torch threads.
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(min(workers, len(items)), mp_context=ctx) as pool:
            for result in pool.map(fn, items):
                bar.update()
                yield result
