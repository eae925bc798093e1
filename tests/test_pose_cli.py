"""`alcn pose build|track|eval` command line."""

from __future__ import annotations

import pytest

from alcn_cv.cli import main


@pytest.mark.parametrize("step", ["build", "track", "eval"])
def test_help(step, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["pose", step, "--help"])
    assert exc.value.code == 0
    assert "usage" in capsys.readouterr().out


def test_errors_are_one_line(tmp_path, capsys):
    assert main(["pose", "build", str(tmp_path), str(tmp_path / "m.npz")]) == 2
    assert "not a BOP scene" in capsys.readouterr().err
    assert main(["pose", "track", str(tmp_path / "missing.npz"), str(tmp_path), str(tmp_path / "p.json"),
                 "--K", "500", "500", "320", "240"]) == 2
    assert "part model not found" in capsys.readouterr().err
    assert main(["pose", "eval", "--out", str(tmp_path / "r")]) == 2
