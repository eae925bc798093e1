"""The base install (``pip install alcn-cv``, no extras) runs the drop-in without torch.

Builds a fresh virtual environment with only this checkout's base dependencies (numpy,
OpenCV, SciPy, tqdm; pip needs PyPI or its cache), then runs the runtime there: ALCN through
cv2.dnn with the shipped ONNX, every classical method, ``alcn normalize``, ``alcn --help``,
and a command of the lab, which must end with the one line naming its extra.
"""

from __future__ import annotations

import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from alcn_cv.shared_data import shared_data_dir

logger = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parents[1]
#: What the distribution is built from (a copy, so the build leaves nothing in the checkout).
SOURCES = ("pyproject.toml", "README.md", "LICENSE", "alcn_cv", "pose", "calib")
#: The base install is a few hundred MB (OpenCV, SciPy, NumPy); torch alone would exceed this.
MAX_SITE_PACKAGES_MB = 600

RUNTIME_CHECK = """
import importlib.util, sys
import cv2, numpy as np
import alcn_cv

missing = [m for m in sys.argv[2].split(",") if importlib.util.find_spec(m) is not None]
assert not missing, f"installed in the base install: {missing}"
assert alcn_cv.__file__.startswith(sys.prefix), alcn_cv.__file__  # the installed copy, not the checkout
image = cv2.imread(sys.argv[1])
alcn = alcn_cv.createALCN()
assert "backend='opencv'" in repr(alcn), repr(alcn)
out = alcn.apply(image)
assert out.shape == image.shape and out.dtype == np.uint8 and out.std() > 0
for name in alcn_cv.available():
    if name != "alcn":
        out = alcn_cv.create(name).apply(image)
        assert out.shape == image.shape, name
assert "torch" not in sys.modules
print("ok", repr(alcn))
"""


def _site_packages_mb(venv: Path) -> float:
    (site,) = (venv / "lib").glob("python*/site-packages")
    return sum(p.stat().st_size for p in site.rglob("*") if p.is_file() and not p.is_symlink()) / 2**20


def _real_image(folder: Path) -> Path:
    """A photograph of the shared data, or a textured image when they are absent."""
    photos = sorted((shared_data_dir() / "psm").glob("*/*.0.png"))
    if photos:
        return photos[0]
    rng = np.random.default_rng(0)
    path = folder / "textured.png"
    cv2.imwrite(str(path), cv2.GaussianBlur((rng.random((240, 320, 3)) * 255).astype(np.uint8), (0, 0), 3))
    return path


@pytest.mark.slow
def test_base_install_runs_the_runtime_without_torch(tmp_path, extras_modules):
    source = tmp_path / "alcn-cv"
    for name in SOURCES:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        else:
            source.mkdir(exist_ok=True)
            shutil.copy2(ROOT / name, source / name)
    venv = tmp_path / "venv"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    python, alcn = venv / "bin" / "python", venv / "bin" / "alcn"
    install = subprocess.run(
        [python, "-m", "pip", "install", "-q", "--disable-pip-version-check", str(source)],
        capture_output=True, text=True, env=env, timeout=900,
    )
    assert install.returncode == 0, install.stderr[-3000:]
    size = _site_packages_mb(venv)
    logger.info("base install: %.0f MB in site-packages", size)
    assert size < MAX_SITE_PACKAGES_MB, f"the base install takes {size:.0f} MB"

    def run(*args: object) -> subprocess.CompletedProcess:
        return subprocess.run(list(map(str, args)), capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)

    image = _real_image(tmp_path)
    proc = run(python, "-c", RUNTIME_CHECK, image, ",".join(extras_modules))
    assert proc.returncode == 0, proc.stderr
    proc = run(alcn, "normalize", image, tmp_path / "normalized.png")
    assert proc.returncode == 0, proc.stderr
    assert cv2.imread(str(tmp_path / "normalized.png")).shape == cv2.imread(str(image)).shape
    proc = run(alcn, "--help")
    assert proc.returncode == 0 and "normalize" in proc.stdout and "train" in proc.stdout, proc.stderr
    proc = run(alcn, "train", "--out", tmp_path / "run")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == (
        'alcn train: needs the [train] extra (torch is not installed): pip install "alcn-cv[train]"'
    )
