"""`alcn train`, `alcn train-detector`, `alcn distill` and `alcn export` on the command line."""

from __future__ import annotations

import json
import shlex
import shutil
import tomllib

import cv2
import numpy as np
import pytest
import torch

import alcn_cv
from alcn_cv.cli import main
from alcn_cv.errors import InputError
from alcn_cv.nets.opencv_runtime import OpenCVNormalizer
from alcn_cv.runtime import resolve_weights
from alcn_cv.weight_file import load_normalizer_file


def test_print_config_applies_the_preset_set_and_seed(capsys):
    args = ["--set", "optim.epochs=2", "--set", "model.method=dog", "--set", "optim.lr=3e-4", "--seed", "5"]
    assert main(["train", "--conf", "paper-full", "--print-config", *args]) == 0
    cfg = tomllib.loads(capsys.readouterr().out)
    assert (cfg["optim"]["epochs"], cfg["model"]["method"], cfg["optim"]["lr"], cfg["seed"]) == (2, "dog", 3e-4, 5)
    assert cfg["data"]["n_train"] == 500_000


@pytest.mark.parametrize(
    "command", [["train"], ["train-real-light"], ["distill", "--conf", "lite"], ["distill", "--conf", "gain-lite"]]
)
def test_every_training_command_takes_a_preset_and_settings(command, capsys):
    assert main([*command, "--print-config", "--set", "seed=7"]) == 0
    assert tomllib.loads(capsys.readouterr().out)["seed"] == 7


@pytest.mark.parametrize(
    "args, message",
    [
        (["train", "--set", "optim.lrr=1"], "optim.lrr"),
        (["train", "--set", "optim.epochs=two"], "optim.epochs"),
        (["train", "--set", "optim.epochs"], "KEY=VALUE"),
        (["train", "--conf", "nonesuch"], "unknown preset 'nonesuch'; choose one of paper, paper-full"),
        (["train", "--conf", "nonesuch.toml"], "config file nonesuch.toml: not found"),
        (["train-real-light", "--set", "net.chanels=8"], "net.chanels"),
        (["train-real-light", "--set", "steps=[1]"], "steps"),
        (["distill", "--conf", "lite", "--set", "channels=[8, 'a']"], "channels"),
        (["distill", "--conf", "gain"], "unknown preset 'gain'"),
        (["train-real-light", "--set", "steps=-5"], "steps >= 1"),  # checked before printing, not at the run
        (["train-unet", "--set", "lr=0"], "lr must be > 0"),
        (["train-real-light", "--set", "scenes=[courbevoie]"], "quote the strings"),
        (["train", "--set", "data.train_lighting=['foo']"], "data.train_lighting' must list lighting families"),
        (
            ["train-real-light", "--set", "shipped_photos=False"],
            "'shipped_photos' must be a boolean, got 'False' (values are TOML: true or false, in lower case)",
        ),
        (["train-real-light", "--set", "photo=['photos']"], "unknown config key 'photo'; did you mean 'photos'? known"),
        (["train-unet", "--set", "net.chanels=8"], "unknown config key 'net.chanels'; did you mean 'net.channels'?"),
        (["train", "--set", "optim.lrr=1"], "unknown config key 'optim.lrr'; did you mean 'optim.lr'?"),
    ],
)
def test_bad_settings_are_one_line_errors(args, message, capsys):
    assert main([*args, "--print-config"]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


@pytest.mark.parametrize("conf", ["paper", "my.toml"])
def test_alcn_train_records_its_command_and_preset(conf, tmp_path, monkeypatch):
    """The weight file of `alcn train` records the command that makes it again and its preset's name, as those of
    `alcn train-real-light` and `alcn distill` do (it recorded neither); a TOML file of the user's is no preset."""
    from alcn_cv.train import trainer

    (tmp_path / "my.toml").write_text("[optim]\nepochs = 2\n")
    monkeypatch.chdir(tmp_path)
    given = {}
    result = trainer.TrainResult(tmp_path, "done")
    monkeypatch.setattr(trainer, "train", lambda *args, **kwargs: given.update(kwargs) or result)
    assert main(["train", "--conf", conf, "--out", "run", "--set", "optim.epochs=3", "--no-progress"]) == 0
    assert given["command"] == f"alcn train --conf {conf} --out run --set optim.epochs=3"
    assert given["conf"] == (None if conf.endswith(".toml") else conf)


@pytest.mark.parametrize("terminated, code", [(False, 130), (True, 143)])
def test_an_interrupted_alcn_train_ends_as_train_real_light(terminated, code, tmp_path, monkeypatch, capsys):
    """Where it stopped and the command that goes on, the preset and settings its checkpoint is checked against
    included; 143 on SIGTERM (it was 130 and `continue with: alcn train --resume --out OUT ...`)."""
    from alcn_cv.cli import Terminated, build_parser
    from alcn_cv.train import trainer

    interrupt = Terminated() if terminated else KeyboardInterrupt()
    result = trainer.TrainResult(tmp_path, "interrupted", stopped_at=(2, 3), interruption=interrupt)
    monkeypatch.setattr(trainer, "train", lambda *args, **kwargs: result)
    out = tmp_path / "run"
    assert main(["train", "--out", str(out), "--set", "optim.epochs=3", "--seed", "4", "--no-progress"]) == code
    words = ["alcn", "train", "--out", str(out), "--resume", "--conf", "paper", "--set", "optim.epochs=3"]
    hint = shlex.join([*words, "--seed", "4", "--no-progress"])
    assert capsys.readouterr().err.strip() == f"interrupted at epoch 2, step 3; continue with: {hint}"
    args = build_parser().parse_args(shlex.split(hint)[1:])
    assert args.resume and args.settings == ["optim.epochs=3"] and args.seed == 4


def test_an_interrupted_alcn_train_prints_a_command_that_works_from_any_folder(tmp_path, monkeypatch, capsys):
    """The run folder, a TOML file given for --conf and the data folders, absolute in the command printed on Ctrl-C
    (they were printed as given), so that the settings checked against the checkpoint's (its folders absolute,
    TrainConfig.resolved) are the run's."""
    from alcn_cv.cli import Terminated
    from alcn_cv.train import trainer

    (tmp_path / "work" / "phos").mkdir(parents=True)
    (tmp_path / "work" / "my.toml").write_text('[data]\nval_path = "phos"\n')
    (tmp_path / "elsewhere").mkdir()
    runs = []

    def train(cfg, out, **kwargs):
        runs.append(cfg)
        return trainer.TrainResult(out, "interrupted", stopped_at=(1, 2), interruption=Terminated())

    monkeypatch.setattr(trainer, "train", train)
    monkeypatch.chdir(tmp_path / "work")
    assert main(["train", "--conf", "my.toml", "--out", "run", "--set", "data.path='phos'", "--no-progress"]) == 143
    hint = capsys.readouterr().err.strip().split("continue with: ")[1]
    words = ["alcn", "train", "--out", str(tmp_path / "work" / "run"), "--resume", "--conf"]
    words += [str(tmp_path / "work" / "my.toml"), "--set", f'data.path="{tmp_path / "work" / "phos"}"']
    words += ["--set", f'data.val_path="{tmp_path / "work" / "phos"}"', "--no-progress"]
    assert shlex.split(hint) == words
    assert runs[0].folders() == {"data.path": "phos", "data.val_path": "phos"}  # as given (the weight file's)
    recorded = runs[0].resolved()  # the checkpoint's
    assert recorded.folders() == dict.fromkeys(("data.path", "data.val_path"), str(tmp_path / "work" / "phos"))
    monkeypatch.chdir(tmp_path / "elsewhere")
    assert main(shlex.split(hint)[1:]) == 143
    assert runs[1].resolved() == recorded


@pytest.mark.parametrize(
    "command, takes",
    [
        (
            "train-real-light",
            "with its settings; the one change it takes is a larger steps (--set steps=N trains on to step N): any "
            "other --set, and --seed, must repeat the checkpoint's value; with --conf, the preset's settings with "
            "--set and --seed, which must equal the checkpoint's alike; --threads and --no-progress are free",
        ),
        (
            "train",
            "give the run's --conf, --set and --seed again (the command printed on Ctrl-C does); its seed and "
            "model.*, data.* and optim.* settings must equal the checkpoint's (optim.epochs too), run.* (--device) "
            "and fewshot.* may change",
        ),
    ],
)
def test_resume_help_says_what_a_resumed_run_takes(command, takes, capsys):
    """It said `--set and --seed change them: a larger steps trains longer`, though only a larger steps is taken."""
    with pytest.raises(SystemExit):
        main([command, "--help"])
    assert takes in " ".join(capsys.readouterr().out.split())


def test_a_missing_data_folder_names_the_key(capsys, tmp_path):
    assert main(["train", "--set", f"data.path='{tmp_path / 'missing'}'", "--out", str(tmp_path / "run")]) == 2
    assert "data.path" in capsys.readouterr().err


def test_export(tmp_path, capsys):
    import shutil

    from alcn_cv.runtime import MODELS

    out = tmp_path / "n.onnx"
    assert main(["export", "--onnx", str(out), "--weights", str(MODELS["paper"])]) == 0
    assert OpenCVNormalizer(out).dense_grid(np.zeros((9, 9), np.float32)).shape == (10, 3, 3)
    assert main(["export", "--onnx", str(out)]) == 2  # exists
    assert main(["export", "--onnx", str(out), "--overwrite"]) == 0  # the default model's: the gain Normalizer, 2 maps
    shutil.copy(MODELS["gain"], out.with_suffix(".npz"))  # its features' settings, read beside the export
    assert OpenCVNormalizer(out).dense_grid(np.zeros((17, 17), np.float32)).shape == (2, 3, 3)
    assert main(["export", "--onnx", str(tmp_path / "n.txt")]) == 2


def test_train_detector_from_a_few_images(tmp_path):
    rng = np.random.default_rng(0)
    for name in ("square", "disc"):
        (tmp_path / "images" / name).mkdir(parents=True)
        img = (rng.random((60, 60)) * 60 + 40).astype(np.uint8)
        if name == "square":
            img[15:45, 15:45] = 220
        else:
            cv2.circle(img, (30, 30), 15, 230, -1)
        cv2.imwrite(str(tmp_path / "images" / name / "a.png"), img)
    mask = np.zeros((60, 60), np.uint8)
    mask[10:50, 10:50] = 255
    cv2.imwrite(str(tmp_path / "images" / "disc" / "a.mask.png"), mask)
    args = [
        "train-detector",
        str(tmp_path / "images"),
        "--out",
        str(tmp_path / "det"),
        "--method",
        "dog",
        "--per-image",
        "12",
        "--epochs",
        "1",
        "--no-progress",
    ]
    assert main(args) == 0
    state = torch.load(tmp_path / "det" / "detector.pt", weights_only=True)
    assert state["classes"] == ["background", "disc", "square"] and state["method"] == "dog"
    assert json.loads((tmp_path / "det" / "classes.json").read_text()) == state["classes"]
    assert main(args) == 2  # an earlier detector, replaced only on request
    args.append("--overwrite")
    from alcn_cv.train import stage2

    for extent in (0, -40, 100):  # 0 hung in the negatives' sampling; the others trained on other windows
        with pytest.raises(InputError, match="--extent is the object's size in the 64-px window"):
            stage2.main(tmp_path / "nothing", tmp_path / "x", extent=extent)  # refused before the images are read
    with pytest.raises(SystemExit, match="2"):  # argparse's range, before the images are read
        main([*args, "--per-image", "0"])
    assert main(["train-detector", str(tmp_path / "nothing"), "--out", str(tmp_path / "x")]) == 2
    weights = ["--weights", str(tmp_path / "w.npz")]
    assert main([*args, *weights]) == 2  # a Normalizer for a DoG
    alcn = [*args[:4], "--method", "alcn:model=lite", *args[6:]]
    assert main(alcn) == 0  # the spec it records makes the same normalization again: scale 1, the windows' own
    assert torch.load(tmp_path / "det" / "detector.pt", weights_only=True)["method"] == "alcn:scale=1.0:model=lite"
    assert main([*alcn[:5], "alcn:weights=a.npz", *alcn[6:], *weights]) == 2  # the weights given twice
    assert main([*args[:4], *args[6:]]) == 0  # the default ALCN, its model named: a later default changes nothing
    assert torch.load(tmp_path / "det" / "detector.pt", weights_only=True)["method"] == "alcn:scale=1.0:model=gain"
    colon = tmp_path / "a:b"  # a --weights path with a ":", which a spec's parsing would split
    colon.mkdir()
    lite = colon / "lite.npz"
    shutil.copy(resolve_weights("lite", None), lite)
    assert main([*args[:4], "--method", "alcn", *args[6:], "--weights", str(lite)]) == 0
    assert torch.load(tmp_path / "det" / "detector.pt", weights_only=True)["method"] == f"alcn:scale=1.0:weights={lite}"


def test_distill_help_and_a_tiny_run(tmp_path, capsys):
    with pytest.raises(SystemExit) as done:
        main(["distill", "--help"])
    assert done.value.code == 0 and "gain-lite" in capsys.readouterr().out
    out = tmp_path / "lite.npz"
    threads = torch.get_num_threads()
    args = [
        "--set",
        "n_windows=16",
        "--set",
        "n_val=8",
        "--set",
        "epochs=1",
        "--set",
        "batch_size=8",
        "--set",
        "n_objects=2",
    ]
    assert main(["distill", "--conf", "lite", "--out", str(out), *args, "--no-progress"]) == 0
    assert capsys.readouterr().out.strip() == str(out) and torch.get_num_threads() == threads
    header = load_normalizer_file(out).meta
    assert header["architecture"] == "lite" and header["distillation"]["conf"] == "lite"
    settings = header["distillation"]["settings"]
    assert settings["n_windows"] == 16 and settings["teacher"] == "paper"
    card = out.with_suffix(".md").read_text()
    assert f"Command: `alcn distill --conf lite --out {out} {' '.join(args)}`" in card
    # the header records how it was made as the card does, and the ONNX export is written as a gain student's is
    made = header["distillation"]
    assert made["command"] == f"alcn distill --conf lite --out {out} {' '.join(args)}" and made["date"].endswith(" UTC")
    assert made["machine"]["cpu_count"] >= 1 and "`lite.onnx` is the same network" in card
    fast, opencv = (alcn_cv.createALCN(weights=out, backend=b, mixture="exact") for b in ("fast", "opencv"))
    image = np.random.default_rng(0).random((64, 80), dtype=np.float32)
    assert np.abs(fast.apply(image) - opencv.apply(image)).max() < 1e-5
    assert main(["distill", "--conf", "lite", "--out", str(out), *args, "--no-progress"]) == 2  # not replaced
    assert "exists (--overwrite replaces it" in capsys.readouterr().err


def test_train_unet_prints_its_own_network(capsys):
    assert main(["train-unet", "--print-config", "--set", "net.channels=4", "--set", "net.levels=2"]) == 0
    net = tomllib.loads(capsys.readouterr().out)["net"]
    assert net == {"channels": 4, "levels": 2, "eps": 0.01}


def test_train_unet_net_keys_are_the_unets_arguments(capsys):
    import inspect

    from alcn_cv.train.config import UNET_CONFS
    from alcn_cv.train.unet_normalizer import UNetNormalizer

    assert set(UNET_CONFS["gain"].net) == set(inspect.signature(UNetNormalizer).parameters)
    assert main(["train-unet", "--print-config", "--set", "net.dilations=[1]"]) == 2
    err = capsys.readouterr().err.strip()
    assert "unknown config key 'net.dilations'; known keys here: channels, eps, levels" in err
    assert len(err.splitlines()) == 1


@pytest.mark.parametrize("command", [["train", "--conf", "paper-full"], ["train-real-light"], ["train-unet"]])
def test_a_training_run_never_writes_into_a_folder_of_other_files(command, tmp_path, capsys):
    (tmp_path / "scene_gt.json").write_text("{}")  # a data set's folder, say
    assert main([*command, "--out", str(tmp_path), "--no-progress"]) == 2
    assert "holds other files than a training run's" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene_gt.json"]


def test_a_run_folder_may_hold_hidden_files_and_configurations(tmp_path):
    from alcn_cv.train.checkpoint import run_folder

    (tmp_path / ".gitkeep").write_text("")
    (tmp_path / "my.toml").write_text("seed = 1")
    assert run_folder(tmp_path) == tmp_path


def test_train_refuses_to_replace_an_earlier_run(tmp_path, capsys):
    (tmp_path / "train.log").write_text("")
    (tmp_path / "checkpoint.pt").write_bytes(b"")
    assert main(["train", "--out", str(tmp_path), "--no-progress"]) == 2  # before any window is rendered
    assert "holds an earlier run (checkpoint.pt): --resume continues it, --overwrite replaces it" in (
        capsys.readouterr().err
    )
    assert main(["train", "--out", str(tmp_path), "--resume", "--overwrite"]) == 2
    assert "not both" in capsys.readouterr().err
    from alcn_cv.io import held_folder

    with held_folder(tmp_path):  # another run writing into the folder: refused before anything is replaced
        assert main(["train", "--out", str(tmp_path), "--overwrite", "--no-progress"]) == 2
    assert "is in use by another run" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["checkpoint.pt", "train.log"]
