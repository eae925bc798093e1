"""The training commands and ``alcn export`` refuse a value out of range in one line that names its option or key,
before any work (a bad-input sweep found numpy's, torch's and Python identifiers' messages, and checks after the
work)."""

from __future__ import annotations

import pytest

from alcn_cv.cli import main
from alcn_cv.runtime import MODELS


def _refused(args: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """The one line with which ``alcn ARGS`` stops with exit code 2: the command's, or argparse's after its usage."""
    try:
        code = main(args)
        usage = False
    except SystemExit as stop:
        code, usage = stop.code, True
    err = capsys.readouterr().err.strip()
    assert code == 2 and (usage or "\n" not in err), err
    return err.splitlines()[-1]


@pytest.mark.parametrize(
    "command",
    [
        ["train"],
        ["train-detector", "IMAGES", "--out", "OUT"],
        ["distill", "--conf", "lite"],
        ["train-real-light"],
        ["train-unet"],
        ["demo", "--out", "OUT"],
    ],
)
def test_a_negative_seed_names_the_option_and_creates_nothing(command, tmp_path, capsys, monkeypatch):
    """``--seed -1`` ended in numpy's "expected non-negative integer" (demo left an empty folder behind)."""
    monkeypatch.chdir(tmp_path)
    err = _refused([*command, "--seed", "-1"], capsys)
    assert "argument --seed: an integer at least 0, got '-1'" in err
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("command", [["distill", "--conf", "lite"], ["train-real-light"], ["train-unet"]])
def test_threads_take_zero_as_the_help_says_and_refuse_a_negative_count(command, capsys):
    """``--threads -1`` said "threads must be a whole number >= 1 or None" where the help says 0 is the default."""
    with pytest.raises(SystemExit):
        main([*command, "--help"])
    assert "0: " in capsys.readouterr().out  # the help says what 0 means
    assert "argument --threads: an integer at least 0, got '-1'" in _refused([*command, "--threads", "-1"], capsys)
    assert main([*command, "--threads", "0", "--print-config"]) == 0


@pytest.mark.parametrize(
    "conf, setting, key",
    [
        ("lite", "lr=-1", "'lr' must be positive, got -1.0"),
        ("lite", "epochs=0", "'epochs' must be positive"),
        ("lite", "seed=-1", "'seed' must be >= 0"),
        ("lite", "channels=[8, 0]", "'channels' must list 2 positive widths"),
        ("gain-lite", "lr=0", "'lr' must be positive"),
        ("gain-lite", "dilations=[]", "'dilations' must list positive dilations"),
    ],
)
def test_a_distillation_setting_out_of_range_is_named(conf, setting, key, tmp_path, capsys):
    """``distill --conf lite --set lr=-1`` ended in torch's "Invalid learning rate: -1.0", naming no key."""
    out = tmp_path / "w.npz"
    assert key in _refused(["distill", "--conf", conf, "--set", setting, "--out", str(out), "--no-progress"], capsys)
    assert key in _refused(["distill", "--conf", conf, "--set", setting, "--print-config"], capsys)
    assert not out.exists()


@pytest.mark.parametrize(
    "command, setting",
    [(["train"], "seed=-1"), (["train"], "data.object_seed=-1"), (["train-real-light"], "seed=-1")],
)
def test_a_negative_seed_setting_is_named(command, setting, capsys):
    """``--set seed=-1`` reached numpy's seeding."""
    assert "seed" in _refused([*command, "--set", setting, "--print-config"], capsys)


@pytest.mark.parametrize(
    "option, value, message",
    [
        ("--epochs", "0", "argument --epochs: an integer at least 1, got '0'"),
        ("--batch-size", "0", "argument --batch-size: an integer at least 1, got '0'"),
        ("--lr", "-1", "argument --lr: a number greater than 0, got '-1'"),
        ("--per-image", "0", "argument --per-image: an integer at least 1, got '0'"),
        ("--negatives", "-1", "argument --negatives: an integer at least 0, got '-1'"),
    ],
)
def test_train_detector_checks_its_options_before_making_windows(option, value, message, tmp_path, capsys):
    """``train-detector --epochs 0`` or ``--lr -1`` said "need epochs >= 1, batch_size >= 1 and lr > 0", and only
    after the windows were made."""
    args = ["train-detector", str(tmp_path / "missing"), "--out", str(tmp_path / "out"), option, value]
    assert message in _refused(args, capsys)


def test_train_detector_checks_its_training_settings_first_when_called(tmp_path):
    """The Python function, as the command line: the training settings before the images are read."""
    from alcn_cv.errors import InputError
    from alcn_cv.train.stage2 import main as train_detector

    with pytest.raises(InputError, match="--lr > 0"):
        train_detector(tmp_path / "missing", tmp_path / "out", lr=-1.0)


@pytest.mark.parametrize("levels", ["50", "9", "0"])
def test_train_unet_refuses_levels_its_crops_cannot_hold(levels, tmp_path, capsys):
    """``train-unet --set net.levels=50`` was not checked: the network's widths double per level, and the process
    was killed at about 24 GB of memory."""
    out = tmp_path / "run"
    err = _refused(["train-unet", "--out", str(out), "--set", "steps=2", "--set", f"net.levels={levels}"], capsys)
    assert "config key 'net.levels' must be from 1 to 8 (level L sees the 160-pixel crop" in err
    assert err.endswith(f"got {levels}") and not out.exists()
    err = _refused(["train-unet", "--out", str(out), "--print-config", "--set", f"net.levels={levels}"], capsys)
    assert "config key 'net.levels' must be from 1 to 8" in err  # the settings printed are those a run takes


@pytest.mark.parametrize(("levels", "channels", "widest"), [("3", "100000", 256), ("8", "9", 8), ("1", "0", 1024)])
def test_train_unet_refuses_widths_past_the_widest_level(levels, channels, widest, tmp_path, capsys):
    """``train-unet --set net.channels=100000`` was not checked: a 3x3 convolution of that width holds 9e10
    weights, and the network's memory was gone before the first step."""
    out = tmp_path / "run"
    args = ["--set", f"net.levels={levels}", "--set", f"net.channels={channels}"]
    err = _refused(["train-unet", "--out", str(out), "--set", "steps=2", *args], capsys)
    assert f"config key 'net.channels' must be from 1 to {widest} (the widths double per level" in err
    assert err.endswith(f"got {channels}") and not out.exists()


def test_unet_levels_leave_a_channel_at_the_widest_level():
    """A 2048-pixel crop allowed 12 levels, whose widest may have 1024 channels: "net.channels must be from 1 to 0"."""
    from alcn_cv.errors import InputError
    from alcn_cv.train.config import UNetConfig

    with pytest.raises(InputError, match=r"'net.levels' must be from 1 to 11 .*, got 12"):
        UNetConfig(crop=2048, net={"channels": 1, "levels": 12, "eps": 0.01}).check()


def test_export_names_a_path_without_the_onnx_suffix_first(tmp_path, capsys, caplog):
    """``export --onnx EXISTING_DIR`` said "exists (--overwrite replaces it)", then with --overwrite "must end in
    .onnx"; ``--onnx x.txt`` logged an unrelated warning (backend='opencv' will not find it) before the error."""
    weights = str(MODELS["paper"])
    for extra in ([], ["--overwrite"]):
        err = _refused(["export", "--weights", weights, "--onnx", str(tmp_path), *extra], capsys)
        assert "must end in .onnx" in err
    assert "must end in .onnx" in _refused(["export", "--weights", weights, "--onnx", str(tmp_path / "x.txt")], capsys)
    assert "will not find" not in caplog.text
    folder = tmp_path / "d.onnx"
    folder.mkdir()
    err = _refused(["export", "--weights", weights, "--onnx", str(folder), "--overwrite"], capsys)
    assert f"{folder} is a folder" in err


def test_a_run_folder_that_cannot_be_written_is_refused_before_the_data(tmp_path, monkeypatch):
    """An unwritable --out was found when the run made its folder, after the scenes were read and relit (seconds;
    minutes with many photographs), with the raw "[Errno 13] Permission denied"."""
    import tempfile

    from alcn_cv.errors import InputError
    from alcn_cv.train.checkpoint import check_run_folder

    def refused(*args, **kwargs):  # as on a read-only mount (root ignores chmod)
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", refused)
    with pytest.raises(InputError, match=r"cannot write .*run/train.log: .* is not writable \(Permission denied\)"):
        check_run_folder(tmp_path / "run")
    assert not (tmp_path / "run").exists()
