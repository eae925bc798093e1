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


_BLOCK_TORCH = """
import importlib.abc, sys
class _BlockTorch(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("torch", "kornia"):
            raise ImportError(f"{name} is blocked in this test")
sys.meta_path.insert(0, _BlockTorch())
"""


@pytest.fixture(scope="session")
def run_without_torch():
    """Run Python ``code`` (with ``args`` as sys.argv[1:]) in a fresh interpreter where importing
    torch or kornia fails; fails the test if it errors or if torch got imported anyway."""
    import subprocess
    import sys
    import textwrap

    def run(code: str, *args: str) -> None:
        script = _BLOCK_TORCH + textwrap.dedent(code) + "\nassert 'torch' not in sys.modules\n"
        subprocess.run([sys.executable, "-c", script, *map(str, args)], check=True, timeout=120)

    return run
