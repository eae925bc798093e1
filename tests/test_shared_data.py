"""Where the shared real data are looked for (alcn_cv.shared_data)."""

from pathlib import Path

from alcn_cv import shared_data
from alcn_cv.shared_data import ENV_VAR, shared_data_dir


def test_the_environment_variable_wins(monkeypatch, tmp_path):
    monkeypatch.setenv(ENV_VAR, str(tmp_path))
    assert shared_data_dir() == tmp_path


def test_beside_the_checkout(monkeypatch):
    monkeypatch.delenv(ENV_VAR, raising=False)
    checkout = Path(shared_data.__file__).resolve().parents[1]
    assert (checkout / "pyproject.toml").is_file()
    assert shared_data_dir() == checkout.parent / "shared" / "data"


def test_an_installed_package_looks_beside_the_current_folder(monkeypatch, tmp_path):
    installed = tmp_path / "site-packages" / "alcn_cv" / "shared_data.py"  # no pyproject.toml above it
    work = tmp_path / "clone"
    work.mkdir()
    monkeypatch.delenv(ENV_VAR, raising=False)
    monkeypatch.setattr(shared_data, "__file__", str(installed))
    monkeypatch.chdir(work)
    assert shared_data_dir() == tmp_path / "shared" / "data"


def test_a_missing_default_folder_says_how_to_give_another(monkeypatch, tmp_path, capsys):
    """Outside a checkout `alcn bench relight` said only "<cwd>/../shared/data/webcam: folder not found", naming
    neither --data nor the environment variable (pose planar named them in a message of its own); a folder given
    with --data that is missing is the user's typo, not the default's, and says no more than that."""
    from alcn_cv.cli import main

    monkeypatch.setenv(ENV_VAR, str(tmp_path / "data"))
    assert main(["bench", "relight", "--out", str(tmp_path / "out"), "--methods", "none", "--no-progress"]) == 2
    assert capsys.readouterr().err.strip() == (
        f"alcn bench relight: error: {tmp_path / 'data' / 'webcam'}: folder not found (the default webcam data: "
        f"give --data DIR, or set {ENV_VAR} to the folder that holds webcam/)"
    )
    given = tmp_path / "data" / "webcm"
    assert main(["bench", "relight", "--data", str(given), "--out", str(tmp_path / "o"), "--methods", "none"]) == 2
    assert capsys.readouterr().err.strip() == f"alcn bench relight: error: {given}: folder not found"
