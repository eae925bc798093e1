"""glibc's malloc between frames: keep the memory a frame frees for the next one.

glibc serves a block above its mmap threshold with freshly mapped pages, and trims the top of its heap when more
than its trim threshold lies free there. Both thresholds start low (128 KiB) and only grow as large blocks are
freed, so a short process that normalizes frames of one size returns most of each frame's temporary arrays to
the system and faults their pages in again on the next call, one 4 KiB page at a time: thousands of page faults
per 1280x800 frame, which cost the default ALCN a third of its time and a raw DoG two thirds on the project's 2-core
VMs. A process that has already freed larger blocks (a long benchmark, say) does not see it. ``alcn bench speed``
times both in fresh processes.

:func:`keep_freed_memory` fixes both thresholds for the whole process (``mallopt``), as starting it with
:data:`GLIBC_TUNABLES` in the environment does. The ``alcn`` command calls it first; an application calls it
once, or sets the variable. The cost: up to ``trim_threshold`` of freed memory stays in the process.

Example:
    >>> import alcn_cv
    >>> alcn_cv.keep_freed_memory()  # doctest: +SKIP
    True
"""

from __future__ import annotations

import ctypes
import sys

__all__ = [
    "GLIBC_TUNABLES",
    "MMAP_THRESHOLD",
    "TRIM_THRESHOLD",
    "glibc_malloc",
    "keep_freed_memory",
    "kept_freed_memory",
]

#: Blocks up to this size come from the heap (glibc's largest mmap threshold on 64 bits).
MMAP_THRESHOLD = 32 * 2**20
#: Free memory kept at the top of the heap.
TRIM_THRESHOLD = 256 * 2**20
#: The environment variable's value that sets the same thresholds when a process starts:
#: ``GLIBC_TUNABLES=<this> python app.py``.
GLIBC_TUNABLES = f"glibc.malloc.mmap_threshold={MMAP_THRESHOLD}:glibc.malloc.trim_threshold={TRIM_THRESHOLD}"
# mallopt's parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3

_kept: tuple[int, int] | None = None


def _glibc() -> ctypes.CDLL | None:
    """The process's C library when it is glibc, else None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None)  # the symbols already loaded into the process
    except OSError:
        return None
    return libc if hasattr(libc, "gnu_get_libc_version") and hasattr(libc, "mallopt") else None


def glibc_malloc() -> bool:
    """Whether the process's C library is glibc, whose thresholds :func:`keep_freed_memory` sets (Linux)."""
    return _glibc() is not None


def keep_freed_memory(mmap_threshold: int = MMAP_THRESHOLD, trim_threshold: int = TRIM_THRESHOLD) -> bool:
    """Make glibc's malloc keep freed memory for reuse, for the whole process (see the module's docstring).

    Args:
        mmap_threshold: blocks up to this many bytes come from the heap (at most 32 MiB on 64 bits).
        trim_threshold: bytes of free memory kept at the top of the heap.

    Returns:
        True when both were set; False where the C library is not glibc (nothing is changed).
    """
    global _kept
    libc = _glibc()
    if libc is None:
        return False
    if not libc.mallopt(_M_MMAP_THRESHOLD, int(mmap_threshold)):
        return False
    if not libc.mallopt(_M_TRIM_THRESHOLD, int(trim_threshold)):
        return False
    _kept = (int(mmap_threshold), int(trim_threshold))
    return True


def kept_freed_memory() -> tuple[int, int] | None:
    """``(mmap_threshold, trim_threshold)`` set by :func:`keep_freed_memory` in this process, else None."""
    return _kept
