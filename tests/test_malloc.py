"""alcn_cv.malloc: glibc's malloc keeps the memory one frame frees for the next."""

import json
import subprocess
import sys

import pytest

from alcn_cv import malloc

# A frame's temporary arrays, freed after each call, in a fresh process.
_FRAMES = """
import json, resource, sys
import numpy as np
if sys.argv[1] == "kept":
    import alcn_cv
    assert alcn_cv.keep_freed_memory()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    temporaries = [np.ones((800, 1280), np.float32) for _ in range(6)]
    del temporaries
print(json.dumps((resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 20))
"""


@pytest.mark.skipif(malloc._glibc() is None, reason="glibc only: elsewhere keep_freed_memory changes nothing")
def test_freed_memory_is_reused_without_page_faults():
    faults = {
        mode: json.loads(
            subprocess.run([sys.executable, "-c", _FRAMES, mode], capture_output=True, text=True, check=True).stdout
        )
        for mode in ("glibc", "kept")
    }
    assert faults["kept"] < faults["glibc"] / 4, faults


def test_the_thresholds_are_recorded_and_nothing_changes_without_glibc(monkeypatch):
    monkeypatch.setattr(malloc, "_kept", None)
    monkeypatch.setattr(malloc, "_glibc", lambda: None)
    assert malloc.keep_freed_memory() is False and malloc.kept_freed_memory() is None
    monkeypatch.undo()
    if malloc._glibc() is not None:
        assert malloc.keep_freed_memory(16 * 2**20, 64 * 2**20)
        assert malloc.kept_freed_memory() == (16 * 2**20, 64 * 2**20)
        assert malloc.keep_freed_memory()  # back to the defaults, as the alcn command sets them
        assert malloc.kept_freed_memory() == (malloc.MMAP_THRESHOLD, malloc.TRIM_THRESHOLD)
