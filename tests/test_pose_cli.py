"""`alcn pose build|track|eval` command line."""

from __future__ import annotations

import dataclasses
import re
import tomllib

import pytest

from alcn_cv.cli import main
from pose.corner_train import CONFS


@pytest.mark.parametrize("step", ["build", "track", "eval"])
def test_help(step, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["pose", step, "--help"])
    assert exc.value.code == 0
    assert "usage" in capsys.readouterr().out


def test_errors_are_one_line(tmp_path, capsys):
    assert main(["pose", "build", str(tmp_path), str(tmp_path / "m.npz")]) == 2
    assert "not a BOP scene" in capsys.readouterr().err
    assert (
        main(
            [
                "pose",
                "track",
                str(tmp_path / "missing.npz"),
                str(tmp_path),
                str(tmp_path / "p.json"),
                "--K",
                "500",
                "500",
                "320",
                "240",
            ]
        )
        == 2
    )
    assert "part model not found" in capsys.readouterr().err
    assert main(["pose", "eval", "--out", str(tmp_path / "r")]) == 2


def test_camera_that_is_not_a_calibration_is_one_line(tmp_path, capsys):
    """`--camera views.json` (what `alcn calib camera` writes beside camera.yaml) was a cv2.error traceback."""
    import json

    views = tmp_path / "views.json"
    views.write_text(
        json.dumps(
            {
                "image_size": [640, 480],
                "camera_matrix": [[500, 0, 320], [0, 500, 240], [0, 0, 1]],
                "distortion_coefficients": [0, 0, 0, 0, 0],
                "views": [],
            }
        )
    )
    code = main(
        ["pose", "track", str(tmp_path / "m.npz"), str(tmp_path), str(tmp_path / "p.json"), "--camera", str(views)]
    )
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert "not a camera calibration" in err and "camera.yaml" in err


def test_help_texts(capsys):
    with pytest.raises(SystemExit):
        main(["pose", "eval", "--help"])
    out = capsys.readouterr().out
    assert "10% of the diameter" in out and "%%" not in out
    with pytest.raises(SystemExit):
        main(["pose", "build", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    # the preset's units named: --conf cookie-box builds in cm without --box-units
    assert "--box-size (default: for a video the preset's (cookie-box: cm), else cm; for a registered" in out
    with pytest.raises(SystemExit):
        main(["pose", "track", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "docs/pose.md, Speed, gives its times" in out and "1.7 s" not in out  # the times, in one place


def test_build_help_says_what_the_box_options_and_the_camera_mean(capsys):
    """--box-ply's help said "its true size" where a registered sequence takes it as the box placed in its frame; the
    thresholds of the box fit the help gives are pose.build's."""
    from pose import build

    with pytest.raises(SystemExit):
        main(["pose", "build", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "For a registered sequence: the box placed in the sequence's world frame" in out
    assert "for poses in another frame use --box-size" in out
    assert "--K FX FY CX CY | --camera CAMERA" in out and "its lens distortion" in out
    assert f"more than {build.BOX_FIT_WARNING:.0%} off the known size is warned" in out
    assert f"more than {build.BOX_FIT_FAILURE:.0%} off on the edges its points cover, the build fails" in out


def test_build_help_lists_its_presets_one_line_each(capsys):
    """The settings of a hand-held object before a static camera were in no --help: each preset of pose.build.CONFS is
    one entry of the epilog (its line, wrapped under it) with its summary and options, and the help says that an
    option given overrides it."""
    from pose import build

    with pytest.raises(SystemExit):
        main(["pose", "build", "--help"])
    out = capsys.readouterr().out
    listed = out[out.index("presets (--conf NAME):") :]
    entries = {m[1]: " ".join(m[0].split()) for m in re.findall(r"(^  (\S+)  .*\n(?:   +\S.*\n)*)", listed, re.M)}
    assert list(entries) == list(build.CONFS)
    for name, summary in build.CONF_SUMMARIES.items():
        entry = entries[name]
        assert summary in entry and "--step 10" in entry and "--motion-mask" in entry and "--refine-focal" in entry
    assert "--K 1578.5 1771.8 320.0 240.0" in entries["cookie-box"] and "--max-frames 46" in entries["cookie-box"]
    flat = " ".join(out.split())
    assert "the options given override its values" in flat
    assert "--conf static-camera" in flat and "(default: the preset's, else 4000)" in flat
    assert "--motion-mask, --no-motion-mask" in flat


def test_an_unknown_build_preset_is_one_line(tmp_path, capsys):
    assert main(["pose", "build", str(tmp_path / "box.mp4"), str(tmp_path / "m.npz"), "--conf", "nope"]) == 2
    err = capsys.readouterr().err
    assert err == "alcn pose build: error: unknown preset 'nope'; choose one of static-camera, cookie-box\n"
    assert not (tmp_path / "m.npz").exists()


def test_building_the_command_line_imports_no_scipy_spatial(run_python):
    """`alcn normalize` built the pose steps' parsers, whose modules imported scipy.spatial at the top (0.2 s of every
    start): the COLMAP and BOP formats import it where they use it."""
    proc = run_python(
        "from alcn_cv.cli import build_parser\n"
        "build_parser()\n"
        "print(sorted(m for m in sys.modules if m.startswith('scipy.spatial')))\n",
        blocked=(),
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"


@pytest.mark.parametrize(
    ("command", "conf"),
    [
        (["pose", "train-corners", "frames", "out.onnx", "--box-ply", "box.ply"], "box"),
        (["pose", "eval", "--out", "report"], "box"),
        (["pose", "planar", "--out", "report"], "planar"),
    ],
)
def test_print_config_shows_the_corner_recipe_with_its_overrides(command, conf, tmp_path, monkeypatch, capsys):
    # the message of a malformed --set points at --print-config: every command that takes --set has it
    monkeypatch.chdir(tmp_path)
    assert main([*command, "--set", "iterations=7", "--set", "channels=[8, 16]", "--print-config"]) == 0
    printed = tomllib.loads(capsys.readouterr().out)
    expected = {**dataclasses.asdict(CONFS[conf]), "iterations": 7, "channels": [8, 16]}
    assert printed == {k: list(v) if isinstance(v, tuple) else v for k, v in expected.items()}
    assert list(tmp_path.iterdir()) == []  # printed, nothing run
    assert main([*command, "--set", "iterations", "--print-config"]) == 2
    assert "--print-config shows the keys" in capsys.readouterr().err
