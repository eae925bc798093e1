from __future__ import annotations

import os
from pathlib import Path

import pytest

# Two cores: keep torch from oversubscribing when tests run in parallel.
os.environ.setdefault("OMP_NUM_THREADS", "1")

from alcn_cv.shared_data import ENV_VAR, shared_data_dir  # noqa: E402


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The real photographs of ``../shared/data``; skips the test when they are absent."""
    root = shared_data_dir()
    if not (root / "README.md").is_file():
        pytest.skip(f"real data not found at {root} (set {ENV_VAR} to its folder)")
    return root
