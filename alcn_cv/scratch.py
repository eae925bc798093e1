"""Work arrays kept between calls, one set per thread: the temporaries of ALCN's per-pixel steps.

glibc gives the memory of a large array back to the kernel when it is freed, so each frame's temporaries would
fault every page in again, which costs a large share of a frame on a virtual machine (``docs/journal.md``,
2026-11-28). The temporaries that never leave a function are taken from here instead, by name: the same memory
at every call from the same thread. What a function returns is never one of them. Arrays of more than
:data:`MAX_ELEMENTS` elements are allocated as usual, so that a thread keeps at most a few arrays of a 1080p
frame's size.
"""

from __future__ import annotations

import math
import threading

import numpy as np

__all__ = ["MAX_ELEMENTS", "work_array"]

#: The largest array kept, in float32 elements: a 1920x1080 frame (2^21 = 2,097,152 >= 2,073,600).
MAX_ELEMENTS = 2**21

_local = threading.local()


def work_array(name: str, shape: tuple[int, ...]) -> np.ndarray:
    """An uninitialized C-contiguous float32 array of ``shape``: the memory of this thread's previous array of
    ``name`` when it is large enough (names are their call sites: ``"module.function.what"``).

    Example:
        >>> a = work_array("doctest.example", (4, 5)); b = work_array("doctest.example", (2, 10))
        >>> np.shares_memory(a, b), b.shape
        (True, (2, 10))
    """
    size = math.prod(shape)
    if size > MAX_ELEMENTS:
        return np.empty(shape, np.float32)
    arrays: dict[str, np.ndarray] = _local.__dict__.setdefault("arrays", {})
    flat = arrays.get(name)
    if flat is None or flat.size < size:
        flat = arrays[name] = np.empty(size, np.float32)
    return flat[:size].reshape(shape)
