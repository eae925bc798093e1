"""``alcn`` where the extras are not installed: its commands are listed, and one that needs a
missing package ends with one line naming the extra to install (exit 2, no traceback)."""

import functools
import os
import subprocess
import sys

import cv2
import numpy as np
import pytest

from alcn_cv.cli import main
from alcn_cv.commands import normalize
from alcn_cv.errors import MissingDependencyError
from alcn_cv.extras import TORCH_CPU_INDEX, extra_providing, missing_dependency

ALCN = "import sys; from alcn_cv.cli import main; sys.exit(main(sys.argv[1:]))"
#: Where the extra brings torch, which is not installed: the line says how to install its CPU build first.
TORCH_FIRST = f"without a GPU, first pip install torch --index-url {TORCH_CPU_INDEX}; then "


def test_help_lists_every_command_without_the_extras(run_python):
    proc = run_python(ALCN, "--help")
    assert proc.returncode == 0, proc.stderr
    for command in ("normalize", "demo", "data", "train", "bench"):
        assert f"\n    {command} " in proc.stdout, command


def test_a_command_needing_a_missing_extra_says_which(run_python, tmp_path):
    proc = run_python(ALCN, "train", "--out", tmp_path / "run")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == (
        "alcn train: needs the [train,data] extras (torch, kornia, skimage are not installed): "
        f'{TORCH_FIRST}pip install "alcn-cv[train,data]"'
    )
    assert not (tmp_path / "run" / "checkpoint.pt").exists()


@pytest.mark.parametrize(
    ("command", "line"),
    [
        (
            ["demo"],
            "alcn demo: needs the [bench] extra (skimage, matplotlib, torch, kornia are not installed): "
            f'{TORCH_FIRST}pip install "alcn-cv[bench]"',
        ),
        (
            ["pose", "build", "VIDEO", "--K", "800", "800", "320", "240", "--box-size", "19", "26", "7.5"],
            # [pose] brings no torch: no CPU-index hint
            "alcn pose build: needs the [pose] extra (pycolmap, open3d, matplotlib are not installed): "
            'pip install "alcn-cv[pose]"',
        ),
        (
            ["data", "phos"],
            'alcn data phos: needs the [data] extra (skimage is not installed): pip install "alcn-cv[data]"',
        ),
        (
            ["data", "scenes"],
            'alcn data scenes: needs the [data] extra (skimage is not installed): pip install "alcn-cv[data]"',
        ),
    ],
    ids=["demo", "pose-build", "data-phos", "data-scenes"],
)
def test_a_command_checks_its_extra_before_the_work(run_python, tmp_path, command, line):
    """`alcn demo` and `alcn data` rendered and `alcn pose build` computed its features before the missing package
    stopped them (with another extra named, for the demo): the extra is named first, and nothing is written."""
    video = tmp_path / "box.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (64, 48))
    for k in range(15):  # the 3 frames, one in 5, that a build from a video needs
        writer.write(np.random.default_rng(k).integers(0, 256, (48, 64, 3), np.uint8))
    writer.release()
    out = tmp_path / "out"
    args = [str(video) if a == "VIDEO" else a for a in command]
    args += [out / "model.npz"] if command[:2] == ["pose", "build"] else ["--out", out]
    proc = run_python(ALCN, *args)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.strip().splitlines() == [line]
    assert not out.exists()


@pytest.mark.parametrize("command", ["train", "train-real-light", "train-unet", "distill", "train-detector"])
def test_a_training_command_names_every_extra_it_lacks_before_the_work(run_python, tmp_path, command):
    """The training commands need [train] and [data] (their data are made from scikit-image's photographs): with
    [train] installed and not [data], they wrote their run folder and failed at the first photograph, naming the
    extra in another form; with neither, they named [train] and then, once it was installed, [data]."""
    out = tmp_path / ("weights.npz" if command == "distill" else "run")
    options = {"distill": ["--conf", "gain-lite"], "train-detector": [tmp_path]}
    args = [command, *options.get(command, []), "--out", out]
    proc = run_python(ALCN, *args, blocked=("skimage",))
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.strip().splitlines() == [
        f'alcn {command}: needs the [data] extra (skimage is not installed): pip install "alcn-cv[data]"'
    ]
    assert not out.exists()
    proc = run_python(ALCN, *args, blocked=("skimage", "kornia"))
    assert proc.stderr.strip().splitlines() == [
        f"alcn {command}: needs the [train,data] extras (kornia, skimage are not installed): "
        'pip install "alcn-cv[train,data]"'
    ]


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


def test_an_apps_own_calib_module_leaves_the_other_commands_running(tmp_path):
    """pose and calib are top-level packages: an app's calib.py earlier on the path made every command, normalize
    included, end in pose's import traceback (exit 1). Now the commands it hides say so in one line."""
    (tmp_path / "calib.py").write_text("LEVEL = 1\n")
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    run = functools.partial(subprocess.run, capture_output=True, text=True, timeout=120, env=env, cwd=tmp_path)
    alcn = [sys.executable, "-c", ALCN]
    listed = run([*alcn, "normalize", "--list"])
    assert listed.returncode == 0 and "tantriggs" in listed.stdout, listed.stderr
    assert "    pose            (cannot be imported here)" in run([*alcn, "--help"]).stdout
    said = run([*alcn, "calib", "--help"])  # argparse refused its --help ("unrecognized arguments")
    assert said.returncode == 0 and "hides alcn-cv's" in said.stdout, said.stderr
    for command in (["calib", "camera"], ["pose", "track", "m.npz", "v.mp4", "p.json"]):
        proc = run([*alcn, *command])
        assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
        line = proc.stderr.strip()
        assert line.startswith(f"alcn {command[0]}: cannot import {command[0]}.cli (") and "\n" not in line
        assert line.endswith(f"calib at {tmp_path / 'calib.py'} hides alcn-cv's (alcn --debug shows the traceback)")


def test_a_bug_importing_a_commands_module_keeps_its_traceback(monkeypatch):
    """Only a module hiding one of alcn-cv's packages makes a command unavailable: an import error of alcn-cv's own
    (a helper renamed) raises, as at run time, where it was listed as "(cannot be imported here)"."""
    from importlib import metadata

    from alcn_cv import cli

    broken = metadata.EntryPoint("normalize", "alcn_cv.commands.no_such_module:add_parser", cli.COMMANDS_GROUP)
    monkeypatch.setattr(cli, "command_entry_points", lambda: [broken])
    with pytest.raises(ImportError, match="no_such_module"):
        cli.build_parser()
