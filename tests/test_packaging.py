"""What the sdist and the wheel carry, built from a copy of this checkout by setuptools' own backend (no network)."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import alcn_cv

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("pyproject.toml", "MANIFEST.in", "README.md", "LICENSE", "NOTICE", "alcn_cv", "pose", "calib", "tests")
BUILD = (
    "import sys; from setuptools import build_meta as backend; out = sys.argv[1]; "  # the backend rewrites sys.argv
    "built = backend.build_sdist(out), backend.build_wheel(out); print('BUILT', *built)"
)


def test_the_sdist_and_the_wheel_carry_the_package_its_types_and_its_licence_expression(tmp_path):
    """The sdist held 106 of the suite's files, without conftest.py: a suite that could not run (now: none of it).
    The licence was the whole text in the License field, a form setuptools stops taking in 2027; the package's
    type hints had no py.typed; the version was written in pyproject.toml and in alcn_cv.__version__."""
    source = tmp_path / "src"
    source.mkdir()
    for name in SOURCES:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        else:
            shutil.copy2(ROOT / name, source / name)
    proc = subprocess.run(
        [sys.executable, "-c", BUILD, str(tmp_path / "dist")], cwd=source, capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "deprecat" not in proc.stderr.lower(), proc.stderr[-3000:]
    sdist_name, wheel_name = next(line for line in proc.stdout.splitlines() if line.startswith("BUILT ")).split()[1:]
    version = alcn_cv.__version__
    assert (sdist_name, wheel_name) == (f"alcn_cv-{version}.tar.gz", f"alcn_cv-{version}-py3-none-any.whl")
    with tarfile.open(tmp_path / "dist" / sdist_name) as sdist:
        files = {Path(*Path(n).parts[1:]).as_posix() for n in sdist.getnames()}
    assert not [f for f in files if f.startswith("tests")], "a part of the test suite is in the sdist"
    assert {
        "pyproject.toml",
        "LICENSE",
        "NOTICE",
        "alcn_cv/py.typed",
        "alcn_cv/weights/alcn_normalizer_gain.onnx",
    } <= files
    with zipfile.ZipFile(tmp_path / "dist" / wheel_name) as wheel:
        names = set(wheel.namelist())
        metadata = wheel.read(f"alcn_cv-{version}.dist-info/METADATA").decode()
    shipped = {f"alcn_normalizer{m}.{s}" for m in ("", "_lite", "_gain", "_gain_lite") for s in ("npz", "onnx")}
    assert {f"alcn_cv/weights/{name}" for name in shipped | {"MODEL_CARD.md", "alcn_normalizer_gain.md"}} <= names
    licenses = f"alcn_cv-{version}.dist-info/licenses"
    assert {"alcn_cv/py.typed", f"{licenses}/LICENSE", f"{licenses}/NOTICE"} <= names  # NOTICE: the weights' terms
    assert f"\nVersion: {version}\n" in metadata and "\nLicense-Expression: Apache-2.0\n" in metadata
    assert "\nLicense: " not in metadata and "Typing :: Typed" in metadata


def test_the_documents_give_the_packages_version():
    """The version is alcn_cv.__version__ (pyproject.toml reads it); CITATION.cff and the README's wheel name give
    it too."""
    version = alcn_cv.__version__
    citation = (ROOT / "CITATION.cff").read_text(encoding="utf-8")
    assert re.search(rf"^version: \"?{re.escape(version)}\"?$", citation, flags=re.M), "CITATION.cff"
    wheels = set(re.findall(r"alcn_cv-([\w.]+)-py3-none-any\.whl", (ROOT / "README.md").read_text(encoding="utf-8")))
    assert wheels == {version}, wheels
