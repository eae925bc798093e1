from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

# Two cores: keep torch from oversubscribing when tests run in parallel.
os.environ.setdefault("OMP_NUM_THREADS", "1")

from alcn_cv.shared_data import ENV_VAR, shared_data_dir  # noqa: E402


@pytest.fixture(autouse=True)
def _seeded_torch() -> None:
    """torch's global generator seeded before each test: a test drawing its data with torch.rand draws the same
    whatever ran before it in its process (pytest-xdist's workers run the tests in another order each time; an
    unseeded draw failed once). Where torch is imported only: the base install's tests run without it."""
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.manual_seed(0)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The real photographs of ``../shared/data``; skips the test when they are absent."""
    root = shared_data_dir()
    if not (root / "README.md").is_file():
        pytest.skip(f"real data not found at {root} (set {ENV_VAR} to its folder)")
    return root


#: The packages of the extras (import names), missing where only the base install is.
OPTIONAL_MODULES = ("torch", "kornia", "onnx", "matplotlib", "skimage", "PIL", "jsonschema", "pycolmap", "open3d")

_BLOCK = """
import importlib.abc, sys
class _Block(importlib.abc.MetaPathFinder):
    # Imports of these fail as they do where the package is not installed.
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {blocked!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}} (blocked in this test)", name=name)
sys.meta_path.insert(0, _Block())
"""


@pytest.fixture(scope="session")
def extras_modules() -> tuple[str, ...]:
    """The import names of the packages the extras install (absent from the base install)."""
    return OPTIONAL_MODULES


@pytest.fixture(scope="session")
def run_python():
    """Run Python ``code`` (with ``args`` as sys.argv[1:]) in a fresh interpreter where importing
    any of ``blocked`` (default: the packages of every extra) fails as if it were not installed;
    returns the finished process (text output)."""

    def run(code: str, *args: str, blocked: tuple[str, ...] = OPTIONAL_MODULES) -> subprocess.CompletedProcess:
        script = _BLOCK.format(blocked=tuple(blocked)) + textwrap.dedent(code)
        return subprocess.run(
            [sys.executable, "-c", script, *map(str, args)], capture_output=True, text=True, timeout=120
        )

    return run


@pytest.fixture(scope="session")
def run_without_torch(run_python):
    """Run Python ``code`` (with ``args`` as sys.argv[1:]) in a fresh interpreter where importing
    torch or kornia fails; fails the test if it errors or if torch got imported anyway."""

    def run(code: str, *args: str) -> None:
        proc = run_python(
            textwrap.dedent(code) + "\nassert 'torch' not in sys.modules\n", *args, blocked=("torch", "kornia")
        )
        assert proc.returncode == 0, proc.stdout + proc.stderr

    return run


@pytest.fixture(params=["opencv", "torch"])
def cpu_route(request, monkeypatch) -> str:
    """Both routes of ALCN2d's CPU inference for the gain models: ``"opencv"``, apply()'s own runtime (what the CPU
    runs), and ``"torch"``, the module's torch filters (what CUDA, autograd, traces and exports run), forced here."""
    if request.param == "torch":
        nn = pytest.importorskip("alcn_cv.nn")
        monkeypatch.setattr(nn.ALCN2d, "_runs_opencv", lambda self, image: False)
    return request.param
