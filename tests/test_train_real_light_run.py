"""The run lifecycle of `alcn train-real-light` (alcn_cv.train.real_light), modelled on `alcn train`'s: an earlier run
is replaced only with --overwrite and never by a run that fails its checks, Ctrl-C saves the step reached and prints
the command that goes on, --resume takes the checkpoint's settings, the end prints the next commands; and the
`alcn export` and weight-file paths those commands take."""

from __future__ import annotations

import json
import logging
import shlex
import sys

import cv2
import numpy as np
import pytest
import torch

import alcn_cv
from alcn_cv.cli import build_parser, main
from alcn_cv.enhance.registry import from_spec
from alcn_cv.errors import WeightFileError
from alcn_cv.train import real_light
from alcn_cv.train.checkpoint import load_checkpoint
from alcn_cv.weight_file import load_normalizer_file
from scene_sets import write_scene


@pytest.fixture(autouse=True)
def _one_thread():
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


def _scene(folder, frames=3, h=120, w=136, seed=0):
    """A registered scene: one texture under a different uneven light in each frame (no gamma, less noise)."""
    return write_scene(folder, frames, h, w, seed, gamma=None, noise=0.2)


def _tiny(scene, steps=2, save_every=2, **more) -> list[str]:
    """The --set options of a run of a few steps on ``scene``."""
    settings = {
        "scenes": f"['{scene}']",
        "relit": 0,
        "crop": 96,
        "patch": 32,
        "net.channels": 8,
        "locations": 16,
        "min_distance": 8,
        "temperature": 0.5,
        "lr": 0.02,
        "steps": steps,
        "save_every": save_every,
        **more,
    }
    return [word for key, value in settings.items() for word in ("--set", f"{key}={value}")]


def _run(out, *options) -> list[str]:
    return ["train-real-light", "--out", str(out), "--no-progress", *options]


def _interrupted_at(call: int, monkeypatch) -> list[int]:
    """Ctrl-C within step ``call`` of the next run, after its draws (the generators moved on)."""
    draw_step, calls = real_light.draw_step, []

    def draw(*args):
        drawn = draw_step(*args)
        calls.append(1)
        if len(calls) == call:
            raise KeyboardInterrupt
        return drawn

    monkeypatch.setattr(real_light, "draw_step", draw)
    return calls


def test_a_failed_or_unasked_run_never_destroys_an_earlier_one(tmp_path, capsys):
    scene = _scene(tmp_path / "scene")
    out = tmp_path / "run"
    assert main(_run(out, *_tiny(scene))) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert {"checkpoint.pt", "gain_normalizer_step2.npz", "gain_normalizer.npz", "train.log"} <= set(before)
    capsys.readouterr()

    assert main(_run(out, *_tiny(scene))) == 2  # the same run again: only with --overwrite
    err = capsys.readouterr().err
    assert "holds an earlier run" in err and "--resume continues it, --overwrite replaces it" in err
    misspelt = _tiny(tmp_path / "scnee")
    assert main(_run(out, "--overwrite", *misspelt)) == 2  # fails on its scenes, before the folder is touched
    assert "scnee" in capsys.readouterr().err
    assert main(_run(out, "--overwrite", *_tiny(scene, patch=8))) == 2  # the kernels do not fit: checked first too
    assert main(_run(out, "--resume", "--overwrite", *_tiny(scene))) == 2  # as alcn train: one or the other
    assert "not both" in capsys.readouterr().err
    from alcn_cv.io import held_folder

    with held_folder(out):  # another run writing into the folder: refused before anything is removed
        assert main(_run(out, "--overwrite", *_tiny(scene))) == 2
    assert "is in use by another run" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before

    assert main(_run(tmp_path / "new", *misspelt)) == 2
    assert not (tmp_path / "new").exists()

    assert main(_run(out, "--overwrite", *_tiny(scene, steps=1, save_every=1))) == 0  # replaced: no file of the first
    assert sorted(p.name for p in out.iterdir()) == [
        "checkpoint.pt",
        "gain_normalizer.npz",
        "gain_normalizer_step1.npz",
        "history.json",
        "train.log",
    ]
    assert "scene scene: 3 frames" in (out / "train.log").read_text()  # loaded before the log opened: logged too


def test_an_error_during_the_run_is_in_train_log(tmp_path, monkeypatch, caplog):
    def broken(*args, **kwargs):
        raise RuntimeError("the loss broke")

    from alcn_cv.train.config import RealLightConfig

    monkeypatch.setattr(real_light, "pair_loss", broken)
    cfg = RealLightConfig(
        scenes=[str(_scene(tmp_path / "scene"))], relit=0, crop=96, patch=32, net={"channels": 8}, steps=2
    )
    with caplog.at_level(logging.INFO), pytest.raises(RuntimeError, match="the loss broke"):
        real_light.train_real_light(cfg, tmp_path / "run", progress=False)
    log = (tmp_path / "run" / "train.log").read_text()
    assert "ERROR] the run failed: the loss broke" in log and "Traceback" in log
    assert "the run failed" not in caplog.text  # the console gets it once, from the command line


def test_ctrl_c_saves_the_step_reached_and_prints_how_to_go_on(tmp_path, monkeypatch, capsys):
    scene = _scene(tmp_path / "scene")
    settings = _tiny(scene, steps=4, save_every=10)
    assert main(_run(tmp_path / "whole", *settings)) == 0
    whole = load_normalizer_file(tmp_path / "whole" / "gain_normalizer.npz")
    capsys.readouterr()

    out = tmp_path / "run"
    calls = _interrupted_at(3, monkeypatch)  # within step 3; no periodic save before (save_every 10)
    assert main(_run(out, *settings, "--threads", "1")) == 130
    hint = shlex.join(["alcn", "train-real-light", "--out", str(out), "--resume", "--no-progress"])
    assert capsys.readouterr().err.strip().endswith(f"interrupted at step 2; continue with: {hint}")
    assert load_checkpoint(out / "checkpoint.pt")["step"] == 2
    assert "interrupted at step 2 of 4" in (out / "train.log").read_text()

    assert len(calls) == 3
    monkeypatch.undo()
    draws = _interrupted_at(0, monkeypatch)  # counts the steps only
    assert main(shlex.split(hint)[1:]) == 0  # as printed: no --set, the checkpoint's settings
    assert len(draws) == 2  # steps 3 and 4, from the state at the start of step 3
    resumed = load_normalizer_file(out / "gain_normalizer.npz")
    for key, value in whole.arrays.items():
        np.testing.assert_array_equal(resumed.arrays[key], value, err_msg=key)
    assert resumed.meta["training"]["command"] == whole.meta["training"]["command"]  # the run's, kept in its checkpoint
    assert [h["step"] for h in json.loads((out / "history.json").read_text())] == [1, 2, 3, 4]


def test_ctrl_c_before_the_first_step_saves_nothing(tmp_path, monkeypatch, capsys):
    _interrupted_at(1, monkeypatch)
    assert main(_run(tmp_path / "run", *_tiny(_scene(tmp_path / "scene")))) == 130
    assert "interrupted before the first step: nothing saved" in capsys.readouterr().err
    assert not (tmp_path / "run" / "checkpoint.pt").exists()


def test_resume_takes_the_checkpoints_settings_and_names_each_difference(tmp_path, capsys):
    scene = _scene(tmp_path / "scene")
    out = tmp_path / "run"
    assert main(_run(out, *_tiny(scene))) == 0
    capsys.readouterr()
    # with a preset, its settings are compared: each difference named, with both values
    assert main(_run(out, "--resume", "--conf", "gain", *_tiny(scene, steps=1, save_every=5, lr=0.01))) == 2
    err = capsys.readouterr().err
    for named in ("lr (0.02 in the checkpoint, 0.01 now)", "save_every (2 in the checkpoint, 5 now)", "steps (2 in"):
        assert named in err
    assert "{'alcn_cv'" not in err  # no raw dict of versions
    assert main(_run(out, "--resume", "--set", "steps=1")) == 2  # fewer steps than done
    assert "steps (2 in the checkpoint, 1 now)" in capsys.readouterr().err
    assert main(_run(out, "--resume", "--seed", "3", "--set", "steps=3")) == 2  # as --help says: steps only
    assert "seed (0 in the checkpoint, 3 now)" in capsys.readouterr().err
    assert main(_run(out, "--resume", "--seed", "0", "--set", "steps=3")) == 0  # longer; the seed repeated
    assert [h["step"] for h in json.loads((out / "history.json").read_text())] == [1, 2, 3]
    meta = load_normalizer_file(out / "gain_normalizer.npz").meta["training"]
    assert meta["config"]["steps"] == 3 and meta["config"]["lr"] == 0.02 and meta["date"].endswith(" UTC")
    assert meta["command"].startswith("alcn train-real-light --conf gain --set") and meta["command"].endswith(
        "--set steps=3 --seed 0"
    )
    assert main(_run(out, "--resume", "--conf", "gain", *_tiny(scene, steps=4))) == 0  # a preset's: same settings


def test_the_end_of_a_run_prints_the_weights_and_commands_that_work(tmp_path, monkeypatch, capsys):
    """The comparison is the README's: the preset alone, trained beside the run, then both benched (it compared with
    the shipped file, which another machine's recipe differs from); the bench's report replaced after a retrain (it
    refused the command, the earlier report in the way)."""
    from alcn_cv.bench import relight

    scene = _scene(tmp_path / "scene")
    out = tmp_path / "run"
    assert main(_run(out, *_tiny(scene, steps=1, save_every=1))) == 0
    printed = capsys.readouterr().out
    weights = out / "gain_normalizer.npz"
    assert printed.startswith(f"weights: {weights}\n")
    assert "train the recipe alone too, once (another machine gives other weights than the shipped file's):" in printed
    assert "relight.md's paired difference of the second from the first is what your settings changed" in printed
    assert "(needs the shared data, or --data DIR of your own registered scenes)" in printed  # the bench's data
    commands = [shlex.split(line)[1:] for line in printed.splitlines() if line.strip().startswith("alcn ")]
    normalize, export, recipe, bench = commands
    assert normalize[:3] == ["normalize", "IMAGE", "OUTPUT"] and export == ["export", "--weights", str(weights)]
    normalize[1:3] = [str(scene / "00.png"), str(tmp_path / "normalized.png")]
    assert main(normalize) == 0 and cv2.imread(str(tmp_path / "normalized.png")) is not None
    assert main(export) == 0 and weights.with_suffix(".onnx").is_file()  # beside: backend='opencv' finds it
    assert recipe == ["train-real-light", "--conf", "gain", "--out", str(tmp_path / "run_recipe")]
    assert build_parser().parse_args(recipe).conf == "gain"  # the preset alone (it trains for minutes)
    args = build_parser().parse_args(bench)  # its options exist (the bench itself takes minutes), its methods too
    first = f"alcn:weights={tmp_path / 'run_recipe' / 'gain_normalizer.npz'}"
    assert args.conf == "quick" and args.methods == [first, f"alcn:weights={weights}"]  # the recipe's first
    assert args.out == tmp_path / "run_bench"  # beside the run (it was inside, where --overwrite left it stale)
    assert from_spec(args.methods[1]).normalize(np.full((40, 40), 0.5, np.float32)).shape == (40, 40)

    # retrained: the same command, run over the report on the weights replaced
    (tmp_path / "run_bench").mkdir()
    for name in ("relight.json", "relight.md"):
        (tmp_path / "run_bench" / name).write_text("the report on the earlier weights")
    assert main(_run(out, "--overwrite", *_tiny(scene, steps=1, save_every=1))) == 0
    again = [shlex.split(line)[1:] for line in capsys.readouterr().out.splitlines() if line.strip().startswith("alcn ")]
    assert again[-1] == bench

    class BenchedError(Exception):
        """The bench's work begins: past its check of an earlier report."""

    def built(*args):
        raise BenchedError

    monkeypatch.setattr(relight, "build_methods", built)
    with pytest.raises(BenchedError):
        main(bench)


def test_a_run_of_its_preset_alone_is_compared_with_the_shipped_model(tmp_path, monkeypatch, capsys):
    """The preset alone has no recipe to train beside it: it is compared with the shipped file (the same recipe on
    another machine); a run of any other setting, with the preset alone."""
    monkeypatch.setattr(real_light, "train_real_light", lambda cfg, out, **kwargs: out / "gain_normalizer.npz")
    out = tmp_path / "run"
    assert main(_run(out)) == 0
    printed = capsys.readouterr().out
    assert "train the recipe alone" not in printed
    assert "compare them with the shipped model on real light changes (the same recipe: another machine" in printed
    methods = f"alcn,alcn:weights={out / 'gain_normalizer.npz'}"
    bench = ["bench", "relight", "--conf", "quick", "--methods", methods, "--out", str(tmp_path / "run_bench")]
    assert shlex.split(printed.splitlines()[-1])[1:] == [*bench, "--overwrite"]
    assert main(_run(out, "--seed", "1")) == 0
    assert "train the recipe alone too" in capsys.readouterr().out


def test_the_bar_shows_the_mean_loss_and_logs_print_above_it(tmp_path, monkeypatch):
    from tqdm import tqdm

    from alcn_cv.train.config import RealLightConfig

    postfixes, redirected = [], []

    class Bar(tqdm):
        def set_postfix_str(self, s="", refresh=True):
            postfixes.append(s)
            super().set_postfix_str(s, refresh)

        def set_postfix(self, *args, **kwargs):
            postfixes.append(kwargs)
            super().set_postfix(*args, **kwargs)

    console = logging.StreamHandler(sys.stderr)
    logging.root.addHandler(console)
    draw_step = real_light.draw_step
    monkeypatch.setattr(real_light, "tqdm", Bar)
    monkeypatch.setattr(
        real_light, "draw_step", lambda *a: redirected.append(console not in logging.root.handlers) or draw_step(*a)
    )
    cfg = RealLightConfig(
        scenes=[str(_scene(tmp_path / "scene"))], relit=0, crop=96, patch=32, net={"channels": 8}, steps=3
    )
    try:
        real_light.train_real_light(cfg, tmp_path / "run", progress=True)
    finally:
        logging.root.removeHandler(console)
    assert redirected == [True, True, True]  # the console's handler writes through tqdm while the bar runs
    losses = [h["loss"] for h in json.loads((tmp_path / "run" / "history.json").read_text())]
    assert postfixes == [f"mean loss {np.mean(losses[: i + 1]):.3f}" for i in range(3)]


def test_export_writes_beside_the_weights_and_never_over_a_file_unasked(tmp_path, capsys, caplog):
    from alcn_cv.runtime import MODELS

    weights = tmp_path / "mine.npz"
    weights.write_bytes(MODELS["gain"].read_bytes())
    assert main(["export", "--weights", str(weights)]) == 0
    beside = weights.with_suffix(".onnx")
    assert capsys.readouterr().out.strip() == str(beside) and beside.is_file()
    assert alcn_cv.createALCN(weights=weights, backend="opencv") is not None
    assert main(["export", "--weights", str(weights)]) == 2
    assert f"{beside} exists (--overwrite replaces it)" in capsys.readouterr().err
    assert main(["export", "--weights", str(weights), "--overwrite"]) == 0
    elsewhere = tmp_path / "other" / "n.onnx"
    elsewhere.parent.mkdir()
    with caplog.at_level(logging.WARNING):
        assert main(["export", "--weights", str(weights), "--onnx", str(elsewhere)]) == 0
    assert elsewhere.is_file() and "will not find this one" in caplog.text and str(beside) in caplog.text


def test_a_run_folder_given_for_weights_names_the_file_meant(tmp_path):
    from alcn_cv.runtime import MODELS

    (tmp_path / "train.log").write_text("")
    with pytest.raises(WeightFileError, match=r"a folder, not a weight file \(\.npz\)$"):
        alcn_cv.createALCN(weights=tmp_path)
    (tmp_path / "gain_normalizer_step1.npz").write_bytes(MODELS["gain"].read_bytes())
    with pytest.raises(WeightFileError, match=r"did you mean .*gain_normalizer_step1\.npz\?"):
        alcn_cv.createALCN(weights=tmp_path)
    (tmp_path / "gain_normalizer.npz").write_bytes(MODELS["gain"].read_bytes())
    with pytest.raises(
        WeightFileError, match=f"{tmp_path} is a folder.*did you mean {tmp_path / 'gain_normalizer.npz'}"
    ):
        alcn_cv.createALCN(weights=tmp_path)


def test_train_unet_asks_for_overwrite_too(tmp_path, capsys):
    from alcn_cv.errors import InputError
    from alcn_cv.train.config import UNetConfig
    from alcn_cv.train.unet import train_unet

    (tmp_path / "train.log").write_text("")
    (tmp_path / "history.json").write_text("[]")
    assert main(["train-unet", "--out", str(tmp_path), "--no-progress"]) == 2  # before its scenes are loaded
    assert "holds an earlier run (history.json)" in capsys.readouterr().err
    cfg = UNetConfig(scenes=[str(_scene(tmp_path / "data"))], relit=0, crop=96, patch=32, steps=1)
    with pytest.raises(InputError, match=r"holds an earlier run \(history.json\)"):  # the library's own check
        train_unet(cfg, tmp_path, progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data", "history.json", "train.log"]


def test_an_interrupted_train_unet_says_it_has_no_checkpoint(tmp_path, monkeypatch, capsys):
    _interrupted_at(3, monkeypatch)
    out = tmp_path / "run"
    options = _tiny(_scene(tmp_path / "scene"), steps=4, **{"net.channels": 4, "net.levels": 2})
    assert main(["train-unet", "--out", str(out), "--no-progress", *options]) == 130
    err = capsys.readouterr().err.strip()
    assert err.endswith(
        "interrupted at step 2: no checkpoint to go on from (this command writes none; history.json "
        "holds the steps done)"
    )
    assert "--resume" not in err and not (out / "checkpoint.pt").exists()
    assert [h["step"] for h in json.loads((out / "history.json").read_text())] == [1, 2]


@pytest.mark.parametrize("key", ["data", "record"])
def test_a_checkpoint_of_an_earlier_version_is_refused_with_one_line(tmp_path, capsys, key):
    """A checkpoint that records neither its data nor its command does not resume, with or without --conf."""
    scene = _scene(tmp_path / "scene")
    out = tmp_path / "run"
    assert main(_run(out, *_tiny(scene))) == 0
    path = out / "checkpoint.pt"
    ckpt = torch.load(path, weights_only=True)
    del ckpt[key]
    torch.save(ckpt, path)
    capsys.readouterr()
    for extra in ([], ["--conf", "gain", *_tiny(scene, steps=3)]):
        assert main(_run(out, "--resume", "--set", "steps=3", *extra)) == 2
        err = capsys.readouterr().err.strip()
        assert err.endswith(
            f"checkpoint {path} was written by an earlier alcn-cv (it records no {key}): start a new run folder"
        )


def test_a_run_resumes_from_any_working_folder(tmp_path, monkeypatch, capsys):
    """The checkpoint records the settings' folders absolute, and the command printed on Ctrl-C names the run folder
    absolute: it goes on from another working folder, on the same data (it failed with `photos: photos: folder not
    found`). The weight file, which users share, holds no absolute path of the machine: the folders as given, the
    checkpoint's absolute ones of a resumed run from the home folder, written ~."""
    for seed, where in enumerate("ab"):  # a scene of the same name in each working folder
        _scene(tmp_path / where / "scene", seed=seed)
    photos = tmp_path / "a" / "mine"
    photos.mkdir()
    for name in ("01.png", "02.png"):  # two frames of the scene, as photographs
        (photos / name).write_bytes((tmp_path / "a" / "scene" / name).read_bytes())
    monkeypatch.chdir(tmp_path / "a")
    mine = ["--set", "photos=['mine']", "--set", "shipped_photos=false", "--set", "relit=2"]
    _interrupted_at(2, monkeypatch)
    assert main(_run("run", *_tiny("scene", steps=3, save_every=5), *mine)) == 130
    hint = capsys.readouterr().err.strip().split("continue with: ")[1]
    assert shlex.split(hint)[1:5] == ["train-real-light", "--out", str(tmp_path / "a" / "run"), "--resume"]
    config = load_checkpoint(tmp_path / "a" / "run" / "checkpoint.pt")["config"]
    folders = {key: [str(tmp_path / "a" / name)] for key, name in (("scenes", "scene"), ("photos", "mine"))}
    assert {key: config[key] for key in folders} == folders

    snapshot = load_normalizer_file(tmp_path / "a" / "run" / "gain_normalizer_step1.npz").meta  # the step done
    assert {key: snapshot["training"]["config"][key] for key in folders} == {"scenes": ["scene"], "photos": ["mine"]}
    assert str(tmp_path) not in json.dumps(snapshot)

    monkeypatch.undo()
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.chdir(tmp_path / "b")
    assert main(shlex.split(hint)[1:]) == 0, capsys.readouterr().err
    meta = load_normalizer_file(tmp_path / "a" / "run" / "gain_normalizer.npz").meta
    mine = {"scenes": ["~/a/scene"], "photos": ["~/a/mine"]}  # a's folders, not b's scene
    assert {key: meta["training"]["config"][key] for key in folders} == mine
    assert str(tmp_path) not in json.dumps(meta)
    assert [h["step"] for h in json.loads((tmp_path / "a" / "run" / "history.json").read_text())] == [1, 2, 3]


def test_resume_refuses_other_data_and_names_what_changed(tmp_path, monkeypatch, capsys):
    """The settings given again with --conf, relative, from another working folder, name another folder: refused,
    both named (the checkpoint records the folders resolved); a photograph added to a folder shifts the draws of those
    after it (the checkpoint records the files of photos)."""
    for seed, where in enumerate("ab"):
        _scene(tmp_path / where / "scene", seed=seed)
    monkeypatch.chdir(tmp_path / "a")
    out = tmp_path / "run"
    assert main(_run(out, *_tiny("scene"))) == 0
    monkeypatch.chdir(tmp_path / "b")
    assert main(_run(out, "--resume", "--conf", "gain", *_tiny("scene", steps=3))) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "was written with another configuration: differs in scenes" in err
    assert f"['{tmp_path / 'a' / 'scene'}'] in the checkpoint, ['{tmp_path / 'b' / 'scene'}'] now" in err
    assert main(_run(out, "--resume", "--set", "steps=3")) == 0  # the checkpoint's settings: a's scene

    monkeypatch.chdir(tmp_path / "a")
    photos = tmp_path / "a" / "mine"
    photos.mkdir()
    for name in ("01.png", "02.png"):  # two frames of the scene, as photographs
        (photos / name).write_bytes((tmp_path / "a" / "scene" / name).read_bytes())
    mine = ["--set", "photos=['mine']", "--set", "shipped_photos=false", "--set", "relit=2"]
    out = tmp_path / "mine_run"
    assert main(_run(out, *_tiny("scene", steps=1, save_every=1), *mine)) == 0
    (photos / "00.png").write_bytes((tmp_path / "a" / "scene" / "00.png").read_bytes())
    (photos / "02.png").write_bytes(b"")  # not read: the check is on the files' names and sizes
    assert main(_run(out, "--resume", "--set", "steps=2")) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"photos {photos}: added 00.png; photos {photos}: resized 02.png;" in err


def test_ctrl_c_during_a_periodic_save_saves_the_step_once(tmp_path, monkeypatch):
    """A Ctrl-C held by the save of step 2 is raised after it: the step was saved again (its snapshot, checkpoint and
    history written twice)."""
    import signal

    from alcn_cv.train.config import RealLightConfig

    saves, save_weights = [], real_light._save_weights

    def save_with_ctrl_c(net, path, *args):
        saves.append(path.name)
        if saves == ["gain_normalizer_step2.npz"]:  # Ctrl-C once, held by the save
            signal.raise_signal(signal.SIGINT)
        return save_weights(net, path, *args)

    monkeypatch.setattr(real_light, "_save_weights", save_with_ctrl_c)
    cfg = RealLightConfig(
        scenes=[str(_scene(tmp_path / "scene"))], relit=0, crop=96, patch=32, net={"channels": 8}, steps=4, save_every=2
    )
    with pytest.raises(real_light.TrainingInterrupted) as stopped:
        real_light.train_real_light(cfg, tmp_path / "run", progress=False)
    assert saves == ["gain_normalizer_step2.npz"] and load_checkpoint(tmp_path / "run" / "checkpoint.pt")["step"] == 2
    assert (stopped.value.step, stopped.value.checkpoint) == (2, True)


def test_a_finished_run_resumed_to_train_longer_loses_its_final_file(tmp_path, monkeypatch, capsys):
    """Its final weights (and their export) would lie beside a later checkpoint once the longer run stops."""
    out = tmp_path / "run"
    assert main(_run(out, *_tiny(_scene(tmp_path / "scene")))) == 0
    (out / "gain_normalizer.onnx").write_bytes(b"an export")
    _interrupted_at(2, monkeypatch)  # within step 4
    assert main(_run(out, "--resume", "--set", "steps=5")) == 130
    assert load_checkpoint(out / "checkpoint.pt")["step"] == 3
    assert not (out / "gain_normalizer.npz").exists() and not (out / "gain_normalizer.onnx").exists()
    assert "removed" in (out / "train.log").read_text()


def test_a_cli_resume_reads_its_checkpoint_and_checks_its_settings_once(tmp_path, monkeypatch):
    from alcn_cv.train.config import RealLightConfig

    out = tmp_path / "run"
    assert main(_run(out, *_tiny(_scene(tmp_path / "scene")))) == 0
    loads, checks, load, check = [], [], torch.load, RealLightConfig.check
    monkeypatch.setattr(torch, "load", lambda *a, **k: loads.append(a[0]) or load(*a, **k))
    monkeypatch.setattr(RealLightConfig, "check", lambda self: checks.append(1) or check(self))
    assert main(_run(out, "--resume", "--set", "steps=3")) == 0
    assert len(loads) == 1 and len(checks) == 1


def test_export_never_offers_to_replace_what_alcn_cv_installed(tmp_path, capsys):
    from alcn_cv.runtime import MODELS

    assert main(["export"]) == 2  # the default model's export beside its weights: the package's own
    err = capsys.readouterr().err
    assert "export is installed already" in err and "--weights FILE" in err and "--overwrite" not in err
    assert main(["export", "--weights", str(MODELS["gain"])]) == 2
    err = capsys.readouterr().err
    assert "is an export installed with alcn-cv; give --onnx PATH" in err and "--overwrite" not in err
    run = tmp_path / "run"  # a run folder given for the weights: the file meant, before any path beside the folder
    run.mkdir()
    (run / "train.log").write_text("")
    (run / "gain_normalizer.npz").write_bytes(MODELS["gain"].read_bytes())
    (tmp_path / "run.onnx").write_bytes(b"")
    assert main(["export", "--weights", str(run)]) == 2
    assert f"did you mean {run / 'gain_normalizer.npz'}?" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["train-real-light", "train-unet", "train"])
def test_a_weight_file_given_for_the_run_folder_is_refused_before_any_work(command, tmp_path, monkeypatch, capsys):
    """It failed only once the scenes were loaded (seconds), as the run folder was made."""
    from alcn_cv.train import windows

    def never(*args):
        raise AssertionError("data loaded before the run folder was checked")

    monkeypatch.setattr(real_light, "training_scenes", never)
    monkeypatch.setattr(windows, "load_windows", never)
    (tmp_path / "mine").mkdir()
    weights = tmp_path / "mine" / "gain_normalizer.npz"
    weights.write_bytes(b"weights")
    assert main([command, "--out", str(weights), "--no-progress"]) == 2
    assert (
        capsys.readouterr()
        .err.strip()
        .endswith(
            f"{weights} is a file, not a folder: --out names the run folder, into which the run writes its weight file "
            f"and checkpoints; give a folder (e.g. {tmp_path / 'mine'})"
        )
    )
    assert main([command, "--out", str(weights / "run"), "--no-progress"]) == 2
    assert f"{weights / 'run'} lies under the file {weights}: --out names the run folder" in capsys.readouterr().err


def test_each_line_of_log_gives_the_untrained_starts_loss_on_the_same_draws(tmp_path, caplog):
    """The loss rose from block to block with the draws, read as a diverging run: each line now gives the mean loss of
    its last steps and the untrained start's on their draws, recomputed here from the seed."""
    import re

    from alcn_cv.presets import with_settings
    from alcn_cv.train.config import RealLightConfig

    scene = _scene(tmp_path / "scene")
    settings = [item for item in _tiny(scene, steps=3, save_every=2) if item != "--set"]
    cfg = with_settings(RealLightConfig(), settings)
    with caplog.at_level(logging.INFO):
        real_light.train_real_light(cfg, tmp_path / "run", progress=False)
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("step ")]
    pattern = r"step (\d): mean loss \S+ over the last \d steps, \d+ s \((steps? [\d-]+): (\S+); the untrained start "
    pattern += r"on the same draws: (\S+)\)"
    found = [re.fullmatch(pattern, line).groups() for line in lines]
    assert [(step, steps) for step, steps, *_ in found] == [("2", "steps 1-2"), ("3", "step 3")]
    losses = [h["loss"] for h in json.loads((tmp_path / "run" / "history.json").read_text())]
    scenes, rendered = real_light.training_scenes(cfg)
    rng, start = np.random.default_rng(cfg.seed), real_light.initial_network(cfg.seed, cfg.net)
    draws = [real_light.draw_step(scenes, rendered, cfg, rng) for _ in range(3)]
    with torch.no_grad():
        untrained = [float(real_light.pair_loss(start, d[0], d[1], d[2], cfg, d[3])) for d in draws]
    assert [float(trained) for *_, trained, _ in found] == pytest.approx([np.mean(losses[:2]), losses[2]], abs=1e-4)
    assert [float(u) for *_, u in found] == pytest.approx([np.mean(untrained[:2]), untrained[2]], abs=1e-4)
    assert losses[0] == pytest.approx(untrained[0], abs=1e-6)  # the first step's loss is the untrained start's
    assert "the loss of each step is on a pair drawn afresh: a block's mean moves with its draws" in caplog.text


def test_a_network_whose_relus_died_is_said_to_have_died(tmp_path, monkeypatch, caplog):
    """At a high learning rate every hidden ReLU of the gain network can switch off for good (two of the rendered
    directional-light variants at lr 5e-3, 2026-11-30): training went on and wrote a file that normalizes with one
    fixed filter, its loss the untrained start's. A block without a gradient on any weight now logs a warning; a
    living network's run does not."""
    from alcn_cv.presets import with_settings
    from alcn_cv.train.config import RealLightConfig

    scene = _scene(tmp_path / "scene")
    cfg = with_settings(RealLightConfig(), [item for item in _tiny(scene, steps=2, save_every=2) if item != "--set"])
    with caplog.at_level(logging.INFO):
        real_light.train_real_light(cfg, tmp_path / "alive", progress=False)
    assert "got a gradient" not in caplog.text
    caplog.clear()
    built = real_light.initial_network

    def dead(seed, net):
        network = built(seed, net)
        with torch.no_grad():
            network.convs[-1].bias.fill_(-1e3)  # the last hidden layer off for every input
        return network

    monkeypatch.setattr(real_light, "initial_network", dead)
    with caplog.at_level(logging.INFO):
        real_light.train_real_light(cfg, tmp_path / "dead", progress=False)
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert warnings == [
        "no weight of the network got a gradient in the last 2 steps: every hidden unit is off (its ReLUs died), so "
        "its output no longer depends on the image and the weight file normalizes every image with one fixed "
        "filter; train again with a lower learning rate than 0.02 (--set lr=...)"
    ]
