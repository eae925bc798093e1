"""``alcn`` where the extras are not installed: its commands are listed, and one that needs a
missing package ends with one line naming the extra to install (exit 2, no traceback)."""

import pytest

from alcn_cv.cli import main
from alcn_cv.commands import normalize
from alcn_cv.errors import MissingDependencyError
from alcn_cv.extras import extra_providing, missing_dependency

ALCN = "import sys; from alcn_cv.cli import main; sys.exit(main(sys.argv[1:]))"


def test_help_lists_every_command_without_the_extras(run_python):
    proc = run_python(ALCN, "--help")
    assert proc.returncode == 0, proc.stderr
    for command in ("normalize", "demo", "data", "train", "bench"):
        assert f"\n    {command} " in proc.stdout, command


def test_a_command_needing_a_missing_extra_says_which(run_python, tmp_path):
    proc = run_python(ALCN, "train", "--out", tmp_path / "run")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == (
        'alcn train: needs the [train] extra (torch is not installed): pip install "alcn-cv[train]"'
    )
    assert not (tmp_path / "run" / "checkpoint.pt").exists()


def test_a_missing_module_imported_while_running_is_one_line(monkeypatch, capsys, tmp_path):
    def needs_pycolmap(*args, **kwargs):
        raise ModuleNotFoundError("No module named 'pycolmap'", name="pycolmap")

    monkeypatch.setattr(normalize, "main", needs_pycolmap)
    assert main(["normalize", str(tmp_path / "in.png"), str(tmp_path / "out.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ['alcn normalize: needs the [pose] extra (pycolmap is not installed): pip install "alcn-cv[pose]"']
    assert main(["--debug", "normalize", str(tmp_path / "in.png"), str(tmp_path / "out.png")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" in err and err.rstrip().splitlines()[-1] == (
        'alcn normalize: needs the [pose] extra (pycolmap is not installed): pip install "alcn-cv[pose]"'
    )


def test_a_bug_importing_a_module_of_no_extra_keeps_its_traceback(monkeypatch, tmp_path):
    def typo(*args, **kwargs):
        raise ModuleNotFoundError("No module named 'nump'", name="nump")

    monkeypatch.setattr(normalize, "main", typo)
    with pytest.raises(ModuleNotFoundError, match="nump"):
        main(["normalize", str(tmp_path / "in.png"), str(tmp_path / "out.png")])


def test_extras_are_read_from_the_installed_metadata():
    assert extra_providing("torch") == "train"
    assert extra_providing("torch.nn.functional", preferred="bench") == "bench"
    assert extra_providing("skimage.data") == "data"
    assert extra_providing("open3d") == extra_providing("pycolmap") == "pose"
    assert extra_providing("numpy") is None  # a base dependency
    error = missing_dependency("kornia", "alcn_cv.filters.kornia_mixture")
    assert isinstance(error, MissingDependencyError) and isinstance(error, ImportError)
    assert str(error) == (
        "alcn_cv.filters.kornia_mixture: needs the [train] extra (kornia is not installed): "
        'pip install "alcn-cv[train]"'
    )
