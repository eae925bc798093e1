"""``alcn`` in a light install (no OpenCV, no torch): each missing package ends the command with one line and exit
code 2, and the line that asks for torch says how to install its CPU build (PyPI's torch is the CUDA build)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from alcn_cv import extras
from alcn_cv.extras import TORCH_CPU_INDEX, missing_dependency

NO_OPENCV = (
    'alcn-cv needs OpenCV (the cv2 module), which is not installed: pip install "alcn-cv[opencv]" (or any one of '
    "opencv-python, opencv-python-headless, opencv-contrib-python, opencv-contrib-python-headless)"
)
TORCH_FIRST = f"without a GPU, first pip install torch --index-url {TORCH_CPU_INDEX}; then "
#: The command's script as pip writes it, with ``argv[0]`` its path, in a process where cv2 is not installed.
SCRIPT_WITHOUT_CV2 = """
import sys
sys.modules["cv2"] = None  # as where no OpenCV wheel is installed
sys.argv[0] = "/venv/bin/alcn"
from alcn_cv.cli import main
sys.exit(main())
"""
ALCN = "import sys; from alcn_cv.cli import main; sys.exit(main(sys.argv[1:]))"


def _python(code: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("args", [["--help"], ["normalize", "in.png", "out.png"], []])
def test_the_command_without_opencv_ends_with_one_line(args):
    proc = _python(SCRIPT_WITHOUT_CV2, *args)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.splitlines() == [NO_OPENCV] and not proc.stdout


def test_the_command_without_opencv_prints_the_traceback_with_debug():
    proc = _python(SCRIPT_WITHOUT_CV2, "--debug", "--help")
    assert proc.returncode == 2
    assert "Traceback" in proc.stderr and proc.stderr.splitlines()[-1] == NO_OPENCV, proc.stderr


def test_importing_the_package_without_opencv_still_raises():
    """A program that imports alcn_cv (here ``python -c``) gets the error, not an exit."""
    proc = _python(
        "import sys; sys.modules['cv2'] = None\n"
        "try:\n    import alcn_cv\nexcept ImportError as exc:\n    print(type(exc).__name__, exc.extra, exc)\n"
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"MissingDependencyError opencv {NO_OPENCV}"


def test_the_installed_script_without_opencv_ends_with_one_line(tmp_path):
    script = Path(sys.executable).parent / ("alcn.exe" if os.name == "nt" else "alcn")
    if not script.exists():
        pytest.skip(f"no console script {script}")
    (tmp_path / "sitecustomize.py").write_text("import sys\nsys.modules['cv2'] = None\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(tmp_path), os.environ.get("PYTHONPATH")]))}
    proc = subprocess.run([str(script), "--help"], capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 2 and proc.stderr.splitlines() == [NO_OPENCV], proc.stderr


def test_an_opencv_that_fails_to_import_ends_with_one_line_that_says_why(tmp_path):
    """OpenCV before 4.10 was built for NumPy 1, which pip does not keep (numpy>=1.26): under NumPy 2 its import
    failed with a traceback out of alcn_cv. The command ends with one line, and the NumPy it needs."""
    (tmp_path / "cv2").mkdir()
    (tmp_path / "cv2" / "__init__.py").write_text('raise ImportError("numpy.core.multiarray failed to import")\n')
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(tmp_path), os.environ.get("PYTHONPATH")]))}
    script = "import sys\nsys.argv[0] = '/venv/bin/alcn'\nfrom alcn_cv.cli import main\nsys.exit(main())\n"
    proc = subprocess.run(
        [sys.executable, "-c", script, "--help"], capture_output=True, text=True, timeout=120, env=env
    )
    assert proc.returncode == 2 and len(proc.stderr.splitlines()) == 1, proc.stderr
    assert proc.stderr.startswith("OpenCV (the cv2 module) fails to import (numpy.core.multiarray failed to import): ")
    if int(np.__version__.split(".")[0]) >= 2:
        assert f'built for NumPy 1, found {np.__version__}: pip install "numpy<2", or pip install' in proc.stderr


def test_the_extras_that_bring_torch_say_how_to_install_its_cpu_build(monkeypatch):
    monkeypatch.setattr(extras, "is_installed", lambda module: module != "torch")
    assert str(missing_dependency("torch", "alcn train", preferred="train")) == (
        f'alcn train: needs the [train] extra (torch is not installed): {TORCH_FIRST}pip install "alcn-cv[train]"'
    )
    # [bench] brings torch with skimage
    assert str(missing_dependency("skimage", "alcn demo", preferred="bench")) == (
        f'alcn demo: needs the [bench] extra (skimage is not installed): {TORCH_FIRST}pip install "alcn-cv[bench]"'
    )
    # [data] brings no torch
    assert str(missing_dependency("skimage", "alcn data phos", preferred="data")) == (
        'alcn data phos: needs the [data] extra (skimage is not installed): pip install "alcn-cv[data]"'
    )
    monkeypatch.setattr(extras, "_extras_requirements", dict)  # alcn-cv not installed: the package named
    assert (
        str(missing_dependency("torch", "f"))
        == f"f: needs torch, which is not installed: pip install torch (without a GPU: --index-url {TORCH_CPU_INDEX})"
    )
    assert "\n" not in TORCH_FIRST


def test_with_torch_installed_the_line_only_names_the_extra(monkeypatch):
    monkeypatch.setattr(extras, "is_installed", lambda module: module == "torch")
    assert str(missing_dependency("kornia", "alcn train", preferred="train")) == (
        'alcn train: needs the [train] extra (kornia is not installed): pip install "alcn-cv[train]"'
    )


@pytest.mark.parametrize(
    ("options", "line"),
    [
        (["--device", "cpu"], "alcn normalize --device: needs the [train] extra (torch, kornia are not installed): "),
        (
            ["-p", "backend=fast"],
            "alcn normalize: ALCN(backend='fast'): needs the [train] extra (torch, kornia are not installed): ",
        ),
    ],
    ids=["device", "backend"],
)
def test_normalize_needing_torch_names_the_command(run_python, tmp_path, options, line):
    image = tmp_path / "in.png"
    cv2.imwrite(str(image), np.random.default_rng(0).integers(0, 256, (48, 64), np.uint8))
    proc = run_python(ALCN, "normalize", image, tmp_path / "out.png", *options, blocked=("torch", "kornia"))
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.strip().splitlines() == [f'{line}{TORCH_FIRST}pip install "alcn-cv[train]"']
    assert not (tmp_path / "out.png").exists()


def test_the_pytorch_module_without_torch_names_its_extra():
    """``from alcn_cv.nn import ALCN2d``, the README's first PyTorch line, in an install without torch."""
    proc = _python(
        "import sys; sys.modules['torch'] = None\n"
        "try:\n    import alcn_cv.nn\nexcept ImportError as exc:\n    print(type(exc).__name__, exc.extra, exc)\n"
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("MissingDependencyError train alcn_cv.nn: needs the [train] extra"), proc.stdout


def test_the_command_run_as_a_module_without_opencv_ends_with_one_line(tmp_path):
    """``python -m alcn_cv.cli`` (the form of experiments/gpu_check.sh), whose ``sys.argv[0]`` is ``-m`` while the
    package is imported."""
    (tmp_path / "sitecustomize.py").write_text("import sys\nsys.modules['cv2'] = None\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(tmp_path), os.environ.get("PYTHONPATH")]))}
    proc = subprocess.run(
        [sys.executable, "-m", "alcn_cv.cli", "--help"], capture_output=True, text=True, timeout=120, env=env
    )
    assert proc.returncode == 2 and proc.stderr.splitlines() == [NO_OPENCV], proc.stderr
