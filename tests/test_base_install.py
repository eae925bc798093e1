"""The base install (no extras) runs the drop-in without torch, beside the app's own OpenCV.

Each test builds a fresh virtual environment (pip needs PyPI or its cache) from a copy of this
checkout. Without any OpenCV, importing alcn_cv says in one line how to install one; with the
``[opencv]`` extra the runtime runs: ALCN through cv2.dnn with the shipped ONNX, every
classical method, ``alcn normalize``, ``alcn --help``, and a command of the lab, which must end
with the one line naming its extra. Into an environment that already has ``opencv-python``
(the GUI build; 4.x from :data:`~alcn_cv.extras.OPENCV_MINIMUM`, and 5.x), installing alcn-cv
adds no other OpenCV wheel, ``cv2.imshow`` stays the GUI one, and ``apply`` gives the output of
this environment's OpenCV.
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

import alcn_cv
from alcn_cv.extras import OPENCV_MINIMUM
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


def _source(tmp_path: Path) -> Path:
    """A copy of what the distribution is built from."""
    source = tmp_path / "alcn-cv"
    for name in SOURCES:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        else:
            source.mkdir(exist_ok=True)
            shutil.copy2(ROOT / name, source / name)
    return source


def _env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}


def _venv(tmp_path: Path) -> Path:
    """A fresh virtual environment; returns its python."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    return venv / "bin" / "python"


def _pip_install(python: Path, *requirements: object) -> None:
    install = subprocess.run(
        [python, "-m", "pip", "install", "-q", "--disable-pip-version-check", *map(str, requirements)],
        check=False,
        capture_output=True,
        text=True,
        env=_env(),
        timeout=900,
    )
    assert install.returncode == 0, install.stderr[-3000:]


def _run(cwd: Path, *args: object) -> subprocess.CompletedProcess:
    return subprocess.run(
        list(map(str, args)), check=False, capture_output=True, text=True, env=_env(), cwd=cwd, timeout=300
    )


@pytest.mark.slow
def test_base_install_runs_the_runtime_without_torch(tmp_path, extras_modules):
    source = _source(tmp_path)
    python = _venv(tmp_path)
    alcn = python.parent / "alcn"
    _pip_install(python, source)
    proc = _run(tmp_path, python, "-c", "import alcn_cv")  # no OpenCV wheel is required
    assert proc.returncode == 1 and proc.stderr.strip().splitlines()[-1] == (
        "alcn_cv.errors.MissingDependencyError: alcn-cv needs OpenCV (the cv2 module), which is not installed: pip "
        'install "alcn-cv[opencv]" (or any one of opencv-python, opencv-python-headless, opencv-contrib-python, '
        "opencv-contrib-python-headless)"
    ), proc.stderr
    _pip_install(python, f"{source}[opencv]")
    size = _site_packages_mb(python.parents[1])
    logger.info("base install: %.0f MB in site-packages", size)
    assert size < MAX_SITE_PACKAGES_MB, f"the base install takes {size:.0f} MB"

    image = _real_image(tmp_path)
    proc = _run(tmp_path, python, "-c", RUNTIME_CHECK, image, ",".join(extras_modules))
    assert proc.returncode == 0, proc.stderr
    proc = _run(tmp_path, alcn, "normalize", image, tmp_path / "normalized.png")
    assert proc.returncode == 0, proc.stderr
    assert cv2.imread(str(tmp_path / "normalized.png")).shape == cv2.imread(str(image)).shape
    proc = _run(tmp_path, alcn, "--help")
    assert proc.returncode == 0 and "normalize" in proc.stdout and "train" in proc.stdout, proc.stderr
    proc = _run(tmp_path, alcn, "train", "--out", tmp_path / "run")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == (
        "alcn train: needs the [train,data] extras (torch, kornia, skimage are not installed): without a GPU, first "
        'pip install torch --index-url https://download.pytorch.org/whl/cpu; then pip install "alcn-cv[train,data]"'
    )


BESIDE_CHECK = """
import importlib.metadata as md, sys
import cv2, numpy as np
import alcn_cv

opencv = sorted(d.metadata["Name"] for d in md.distributions() if d.metadata["Name"].lower().startswith("opencv"))
assert opencv == [sys.argv[3]], f"OpenCV wheels: {opencv}"
gui = next(line for line in cv2.getBuildInformation().splitlines() if line.strip().startswith("GUI:"))
assert gui.split(":")[1].strip() != "NONE", gui  # the GUI build, not the headless one
assert callable(cv2.imshow)
reference = np.load(sys.argv[2])
image = cv2.imread(sys.argv[1])
gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
for name in reference.files:
    method, _, model = name.partition("-")
    out = alcn_cv.createALCN(model=model).apply(image) if method == "alcn" else alcn_cv.create(method).apply(gray)
    diff = np.abs(out.astype(int) - reference[name].astype(int))
    # cv2.dnn and a few OpenCV kernels differ by a rounding between versions
    assert out.shape == reference[name].shape and diff.max() <= 1 and (diff > 0).mean() < 1e-3, (name, diff.max())
opencv = alcn_cv.extras.opencv_version()
if opencv < (4, 8):
    try:
        alcn_cv.createALCN()
    except alcn_cv.WeightFileError as exc:
        assert "use OpenCV 4.8 or newer, install torch (backend='fast') or model='lite'" in str(exc), exc
    else:
        raise AssertionError(f"the gain Normalizer ran through OpenCV {cv2.__version__}'s cv2.dnn")
elif opencv < (5, 0):  # OpenCV 4's reflect Pad pads no side by more than its length: a tiny image mirrored first
    for side in (17, 18):
        assert alcn_cv.createALCN().apply(image[:side, :side]).shape == image[:side, :side].shape
print("ok", cv2.__version__, gui)
"""

#: ``opencv-python`` releases an app may hold: the oldest 4.x the runtime supports, the last 4.x, and 5.x.
APP_OPENCV = {
    "4.5.5": ["opencv-python==4.5.5.64", "numpy<2"],  # built against NumPy 1
    "4.14": ["opencv-python==4.14.0.94"],
    "5.0": ["opencv-python==5.0.0.93"],
}


def test_oldest_app_opencv_is_the_supported_minimum():
    assert APP_OPENCV[".".join(map(str, OPENCV_MINIMUM))]


@pytest.mark.slow
@pytest.mark.parametrize("version", APP_OPENCV)
def test_install_beside_the_apps_opencv_keeps_it(tmp_path, version):
    image = _real_image(tmp_path)
    # The reference: this checkout's output in this environment. The gain Normalizers (the default
    # model) run through cv2.dnn from OpenCV 4.8 on; 4.5.5 runs the others. The classical methods
    # are compared on the gray image: Tan-Triggs' gamma amplifies the difference between OpenCV 4's
    # and 5's Lab conversion of near-black pixels (up to 18 levels on the buddha photograph).
    models = ["gain", "lite", "paper"] if version != "4.5.5" else ["lite", "paper"]
    frame = cv2.imread(str(image))
    reference = {f"alcn-{model}": alcn_cv.createALCN(model=model, backend="opencv").apply(frame) for model in models}
    gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    reference |= {name: alcn_cv.create(name).apply(gray) for name in alcn_cv.available() if name != "alcn"}
    np.savez(tmp_path / "reference.npz", **reference)
    python = _venv(tmp_path)
    _pip_install(python, *APP_OPENCV[version])  # the app's OpenCV, first
    _pip_install(python, _source(tmp_path))
    proc = _run(tmp_path, python, "-c", BESIDE_CHECK, image, tmp_path / "reference.npz", "opencv-python")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.startswith(f"ok {version}"), proc.stdout
