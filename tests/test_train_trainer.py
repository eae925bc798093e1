"""Joint training (Eq. 2): checkpoints, exact resume, faults, outputs (alcn_cv.train.trainer and its stages)."""

from __future__ import annotations

import json
import re
import signal
from pathlib import Path

import numpy as np
import pytest
import torch

from alcn_cv.data import phos
from alcn_cv.errors import InputError, WeightFileError
from alcn_cv.filters.gaussian_mixture import gaussian_sigmas
from alcn_cv.nets.gain import dog_weights
from alcn_cv.train import trainer, windows
from alcn_cv.train.checkpoint import load_checkpoint
from alcn_cv.train.config import load_config
from alcn_cv.train.models import CentreMixture, JointModel
from alcn_cv.train.stage2 import NonFiniteLossError
from alcn_cv.weight_file import load_normalizer_file


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("phos")
    train_dir = phos.generate(root / "train", 96, 0, n_objects=3, lighting="ambient,bright", progress=False)
    val_dir = phos.generate(root / "val", 48, 1, n_objects=3, lighting="side", progress=False)
    return str(train_dir), str(val_dir)


def _config(data, **model):
    return {
        "data": {"path": data[0], "val_path": data[1], "gain_jitter": [0.7, 1.4]},
        "model": {"channels": [4, 8], "hidden": 16, "detector_channels": [4, 8], "detector_hidden": 16, **model},
        "optim": {"epochs": 2, "batch_size": 16, "warmup_steps": 2},
        "fewshot": {"enabled": False},
        "run": {"threads": 1, "log_every": 2},
    }


def _weights(path):
    return load_checkpoint(path)["model"]


def test_train_outputs_and_gradients_reach_the_normalizer(data, tmp_path):
    cfg = _config(data)
    cfg["fewshot"] = {"n_objects": 2, "per_image": 8, "n_test": 40, "epochs": 1, "dog": [[0.5, 1.5]]}
    result = trainer.train(cfg, tmp_path, progress=False, command="alcn train --conf paper --out X", conf="paper")
    assert set(result.fewshot) == {"alcn", "dog 0.5/1.5", "none"}
    assert 0 <= result.fewshot["alcn"]["auc"] <= 1
    assert result.status == "done" and len(result.history) == 2
    assert set(result.val_by_family) == {"side"}
    for name in (
        "checkpoint.pt",
        "train.log",
        "history.json",
        "curves.png",
        "config.toml",
        "alcn_normalizer.npz",
        "fewshot.json",
        "summary.md",
    ):
        assert (tmp_path / name).is_file(), name
    assert "held-out val" in (tmp_path / "train.log").read_text()
    assert "| dog 0.5/1.5 |" in (tmp_path / "summary.md").read_text()
    assert "new objects, 1 image(s) each under one light" in (tmp_path / "summary.md").read_text()
    # The Normalizer moved away from its DoG initialisation: gradients went through the mixture.
    init = torch.tensor(dog_weights(gaussian_sigmas(10, 0.5), 0.5, 1.5))
    with torch.no_grad():
        x = torch.rand(4, 1, 64, 64)
        assert not torch.allclose(result.model.weights(x), init.expand(4, -1))
    wf = load_normalizer_file(result.weights)
    assert wf.meta["trained"] is True and wf.meta["working_scale"] == 0.5
    assert wf.meta["output_range"][0] < 0 < wf.meta["output_range"][1]
    assert wf.meta["detector_input"] == "standardize"
    # how it was made, as the gain Normalizer's file records it (the paper family's recorded neither command nor preset)
    made = wf.meta["training"]
    assert (made["command"], made["conf"]) == ("alcn train --conf paper --out X", "paper")
    assert re.fullmatch(r"\d{4}-\d\d-\d\d \d\d:\d\d UTC", made["date"]) and made["machine"]["cpu_count"] >= 1


def test_resume_equals_uninterrupted_run(data, tmp_path, monkeypatch):
    cfg = _config(data, detector_dropout=0.3)  # dropout: the random state must be restored too
    full = trainer.train(cfg, tmp_path / "full", progress=False)

    def interrupt(step):
        if step == 8:  # mid-way through the second epoch (6 steps per epoch)
            raise KeyboardInterrupt

    monkeypatch.setattr(trainer, "_on_step", interrupt)
    part = trainer.train(cfg, tmp_path / "part", progress=False)
    assert part.status == "interrupted" and len(part.history) == 1
    monkeypatch.undo()
    resumed = trainer.train(cfg, tmp_path / "part", resume=True, progress=False)
    assert resumed.status == "done"
    a, b = _weights(tmp_path / "full" / "checkpoint.pt"), _weights(tmp_path / "part" / "checkpoint.pt")
    for k in a:
        assert torch.equal(a[k], b[k]), k
    assert resumed.history[-1]["val_loss"] == full.history[-1]["val_loss"]


def test_the_weight_file_records_no_absolute_path_of_the_machine(data, tmp_path, monkeypatch):
    """The weight file, which users share, recorded the data folders absolute (`/home/<user>/...`) once the checkpoint
    needed them so: it records them as given, the home folder written ~ (a run resumed from another working folder is
    given them absolute), while the checkpoint and config.toml hold them absolute."""
    root = Path(data[0]).parent
    monkeypatch.setenv("HOME", str(root))
    monkeypatch.chdir(root)
    cfg = _config(("train", "val"))

    def interrupt(step):
        if step == 8:  # mid-way through the second epoch
            raise KeyboardInterrupt

    monkeypatch.setattr(trainer, "_on_step", interrupt)
    assert trainer.train(cfg, tmp_path / "run", progress=False).status == "interrupted"
    absolute = {"path": str(Path(data[0]).resolve()), "val_path": str(Path(data[1]).resolve())}
    assert {k: load_checkpoint(tmp_path / "run" / "checkpoint.pt")["config"]["data"][k] for k in absolute} == absolute
    assert load_config(tmp_path / "run" / "config.toml").data.path == absolute["path"]
    monkeypatch.setattr(trainer, "_on_step", lambda step: None)
    monkeypatch.chdir(tmp_path)  # elsewhere: the folders given absolute, as the command printed on Ctrl-C gives them
    resumed = trainer.train({**cfg, "data": {**cfg["data"], **absolute}}, tmp_path / "run", resume=True, progress=False)
    assert resumed.status == "done"
    assert load_normalizer_file(resumed.weights).meta["training"]["config"]["data"]["path"] == "~/train"

    monkeypatch.chdir(root)
    whole = trainer.train(cfg, tmp_path / "whole", progress=False)
    header = load_normalizer_file(whole.weights).meta
    assert (header["training"]["config"]["data"]["path"], header["training"]["config"]["data"]["val_path"]) == (
        "train",
        "val",
    )
    assert str(root) not in json.dumps(header) and str(root.resolve()) not in json.dumps(header)


def test_a_ctrl_c_right_after_a_step_is_saved_with_that_step_counted(data, tmp_path, monkeypatch):
    """Ctrl-C between optimizer.step() and the step's counter: the interrupted run's checkpoint counts the step its
    weights hold (Adam's own count of the steps it took), so that a resumed run does not take it twice."""
    make_optimizer = trainer._make_optimizer

    def interrupted_at_eighth_step(model, cfg):
        optimizer = make_optimizer(model, cfg)
        step, taken = optimizer.step, []

        def step_then_ctrl_c():
            step()
            taken.append(1)
            if len(taken) == 8:  # mid-way through the second epoch (6 steps per epoch)
                signal.raise_signal(signal.SIGINT)

        optimizer.step = step_then_ctrl_c
        return optimizer

    monkeypatch.setattr(trainer, "_make_optimizer", interrupted_at_eighth_step)
    result = trainer.train(_config(data), tmp_path, progress=False)
    assert result.status == "interrupted"
    ckpt = load_checkpoint(tmp_path / "checkpoint.pt")
    assert (ckpt["epoch"], ckpt["step_in_epoch"]) == (1, 2)
    # where it stopped (the epoch under way from 1, as the command line prints it) and what stopped it
    assert result.stopped_at == (2, 2) and type(result.interruption) is KeyboardInterrupt
    assert {int(s["step"]) for s in ckpt["optimizer"]["state"].values()} == {8}


class _CtrlCAfterAppend(list):
    """A history that raises Ctrl-C as soon as an epoch's entry is in (module-level: the checkpoint pickles it)."""

    def append(self, entry):
        super().append(entry)
        signal.raise_signal(signal.SIGINT)


def test_a_ctrl_c_right_after_an_epochs_entry_is_saved_with_that_epoch_counted(data, tmp_path, monkeypatch):
    """Ctrl-C between the epoch's history entry and the epoch's counter: the interrupted run's checkpoint counts the
    epoch its history holds, so that a resumed run does not record it twice."""
    build_models = trainer._build_models

    def with_ctrl_c_after_the_first_entry(*args):
        model, optimizer, state = build_models(*args)
        state.history = _CtrlCAfterAppend(state.history)
        return model, optimizer, state

    monkeypatch.setattr(trainer, "_build_models", with_ctrl_c_after_the_first_entry)
    assert trainer.train(_config(data), tmp_path, progress=False).status == "interrupted"
    ckpt = torch.load(tmp_path / "checkpoint.pt", weights_only=False)  # its history is a _CtrlCAfterAppend
    assert (ckpt["epoch"], ckpt["step_in_epoch"], [h["epoch"] for h in ckpt["history"]]) == (1, 0, [1])


def test_a_run_leaves_the_callers_thread_count_as_it_was(data, tmp_path, monkeypatch):
    """The run's ``run.threads`` were set for the whole process and left so after it: a Python caller's own torch
    work ran on them."""
    before = torch.get_num_threads()
    during = []
    monkeypatch.setattr(trainer, "_on_step", lambda step: during.append(torch.get_num_threads()))
    cfg = _config(data)
    cfg["optim"]["epochs"], cfg["run"]["threads"] = 1, before + 1
    assert trainer.train(cfg, tmp_path, progress=False).status == "done"
    assert set(during) == {before + 1} and torch.get_num_threads() == before


def test_nan_loss_stops_and_keeps_last_good_checkpoint(data, tmp_path, monkeypatch):
    def poison(step):
        if step == 7:
            with torch.no_grad():
                next(iter(poisoned[0].parameters())).fill_(float("nan"))

    poisoned = []
    original = JointModel.__init__

    def init(self, *args, **kwargs):
        original(self, *args, **kwargs)
        poisoned.append(self)

    monkeypatch.setattr(JointModel, "__init__", init)
    monkeypatch.setattr(trainer, "_on_step", poison)
    with pytest.raises(NonFiniteLossError, match="last good checkpoint"):
        trainer.train(_config(data), tmp_path, progress=False)
    ckpt = load_checkpoint(tmp_path / "checkpoint.pt")
    assert ckpt["epoch"] == 1 and all(torch.isfinite(v).all() for v in ckpt["model"].values() if v.is_floating_point())
    assert "loss is nan" in (tmp_path / "train.log").read_text()


def test_bad_checkpoints(data, tmp_path):
    cfg = _config(data, method="dog")
    with pytest.raises(WeightFileError, match="not found"):
        trainer.train(cfg, tmp_path, resume=True, progress=False)
    trainer.train({**cfg, "optim": {**cfg["optim"], "epochs": 1}}, tmp_path, progress=False)
    path = tmp_path / "checkpoint.pt"
    with pytest.raises(WeightFileError, match="optim.epochs"):
        trainer.train(cfg, tmp_path, resume=True, progress=False)
    ckpt = torch.load(path, weights_only=True)
    ckpt["version"] = 99
    torch.save(ckpt, path)
    with pytest.raises(WeightFileError, match="version 99.*torch"):
        load_checkpoint(path)
    path.write_bytes(b"PK\x03\x04 truncated")
    with pytest.raises(WeightFileError, match="corrupt"):
        load_checkpoint(path)


def test_baselines_and_policy(data, tmp_path):
    cfg = _config(data, method="none", detector_input="raw")
    result = trainer.train({**cfg, "optim": {**cfg["optim"], "epochs": 1}}, tmp_path, progress=False)
    assert result.weights is None and 0 <= result.val_accuracy <= 1
    model = JointModel(load_config(_config(data)).model, 4)
    x = torch.rand(3, 1, 64, 64)
    z = model.normalized(x)
    assert z.shape == (3, 1, 32, 32)
    np.testing.assert_allclose(z.mean(dim=(2, 3)).detach(), 0, atol=1e-5)


def test_validation_must_hold_lightings_out(data, tmp_path):
    cfg = _config(data)
    cfg["data"]["val_path"] = data[0]
    cfg["data"]["path"] = data[0]
    with pytest.raises(InputError, match="hold some lightings out"):
        trainer.train(cfg, tmp_path, progress=False)


def test_centre_mixture_equals_kornia_mixture():
    from alcn_cv.filters.kornia_mixture import gaussian_mixture2d

    x, w = torch.rand(3, 1, 64, 64), torch.randn(3, 10)
    centre = CentreMixture(tuple(0.5 * i for i in range(1, 11)))
    np.testing.assert_allclose(centre(x, w), gaussian_mixture2d(x, w)[..., 16:48, 16:48], atol=1e-5)
    maps = torch.randn(3, 10, 64, 64)  # Eq. 3: per-pixel weights
    np.testing.assert_allclose(centre.dense(x, maps), gaussian_mixture2d(x, maps)[..., 16:48, 16:48], atol=1e-5)


def test_meta_objective_trains_the_normalizer_only_on_other_lightings(data):
    cfg = load_config(_config(data))
    model = JointModel(cfg.model, 4)
    x, y = torch.rand(6, 1, 64, 64), torch.tensor([0, 1, 2, 3, 1, 2])
    anchor = torch.tensor([True, True, True, False, False, False])
    logits = model(x, anchor)
    torch.testing.assert_close(logits, model(x))  # same values, different gradients
    F = torch.nn.functional
    F.cross_entropy(logits[~anchor], y[~anchor]).backward()
    assert all(p.grad is None or not p.grad.any() for p in model.detector.parameters())
    assert model.normalizer.head.weight.grad.abs().sum() > 0


def test_meta_objective_renders_anchor_windows(tmp_path):
    cfg = {
        "data": {"n_train": 24, "n_val": 8, "n_objects": 2, "train_lighting": ["ambient", "bright"]},
        "model": {"channels": [4, 8], "hidden": 16, "detector_channels": [4, 8], "detector_hidden": 16},
        "optim": {"objective": "meta", "epochs": 1, "batch_size": 8},
        "fewshot": {"enabled": False},
        "run": {"threads": 1},
    }
    result = trainer.train(cfg, tmp_path, progress=False)
    assert result.status == "done"
    with np.load(next(tmp_path.glob("windows-*.npz"))) as z:
        assert np.bincount(z["train_light_ids"], minlength=3)[[0, 2]].tolist() == [12, 12]


def test_meta_objective_names_an_anchor_lighting_the_windows_lack(data, tmp_path):
    """Windows read from data.path: a misspelt anchor is an InputError naming it (it was list.index's ValueError)."""
    cfg = _config(data)
    cfg["data"]["anchor_lighting"] = "ambiant"
    with pytest.raises(InputError, match="anchor lighting 'ambiant'"):
        trainer.train(cfg, tmp_path, progress=False)


def test_cached_windows_are_those_of_the_settings_and_folders(data, tmp_path):
    """A run folder's cache holds the windows read from data.path too: a later run there that renders its windows
    must not take those for its own; the key of rendered windows is the one earlier caches were written under."""
    read = load_config({**_config(data), "data": {"path": data[0], "n_train": 96, "n_val": 48, "n_objects": 3}})
    rendered = load_config({**_config(data), "data": {"n_train": 96, "n_val": 48, "n_objects": 3}})
    train_read, _ = windows.load_windows(read, tmp_path, False)
    train_rendered, _ = windows.load_windows(rendered, tmp_path, False)
    assert np.array_equal(train_read.windows, phos.load(data[0]).windows)
    assert not np.array_equal(train_rendered.windows, train_read.windows)
    assert len(list(tmp_path.glob("windows-*.npz"))) == 2
    key = load_config({"data": {"n_train": 200, "n_val": 60, "n_objects": 3}})
    assert windows._data_key(key) == "eb466d6df4480fa0"  # as before the folders joined the key
    assert windows._data_key(load_config("paper")) == "56d1d03489f7d337"


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_a_cuda_run_writes_its_weights_and_resumes_exactly(data, tmp_path, monkeypatch):
    """run.device = "cuda": the few-shot validation and the weight file at the end (they ran CPU windows through the
    CUDA model), and a resumed run equal to an uninterrupted one with dropout (drawn on the device)."""
    cfg = _config(data, detector_dropout=0.3)
    cfg["run"] = {**cfg["run"], "device": "cuda"}
    cfg["fewshot"] = {"n_objects": 2, "per_image": 8, "n_test": 40, "epochs": 1, "dog": [[0.5, 1.5]]}
    full = trainer.train(cfg, tmp_path / "full", progress=False)
    assert full.weights is not None and set(full.fewshot) == {"alcn", "dog 0.5/1.5", "none"}
    assert next(full.model.parameters()).device.type == "cpu"
    assert load_checkpoint(tmp_path / "full" / "checkpoint.pt")["cuda_rng"] is not None
    cfg["fewshot"] = {"enabled": False}

    def interrupt(step):
        if step == 8:
            raise KeyboardInterrupt

    monkeypatch.setattr(trainer, "_on_step", interrupt)
    trainer.train(cfg, tmp_path / "part", progress=False)
    monkeypatch.undo()
    trainer.train(cfg, tmp_path / "part", resume=True, progress=False)
    a, b = _weights(tmp_path / "full" / "checkpoint.pt"), _weights(tmp_path / "part" / "checkpoint.pt")
    for k in a:
        assert torch.equal(a[k], b[k]), k


@pytest.mark.parametrize("arriving", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_while_the_handlers_are_put_back_leaves_none_held_for_good(arriving, monkeypatch):
    """interrupts_deferred put SIGINT's handler back first: a Ctrl-C right then raised out of it before SIGTERM's was
    back, and SIGTERM went to the temporary collector for good (swallowed). Now no signal comes between the swaps."""
    if not hasattr(signal, "pthread_sigmask") and arriving == signal.SIGTERM:
        pytest.skip("without pthread_sigmask only SIGINT, put back last, is safe")
    from alcn_cv.io import interrupts_deferred

    real_signal = signal.signal
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}

    def terminated(signum, frame):
        raise KeyboardInterrupt("terminated")

    swaps = []

    def swap_then_signal(signum, handler):
        previous = real_signal(signum, handler)
        swaps.append(signum)
        if len(swaps) == 3:  # the first handler put back: the signal arrives right then
            signal.raise_signal(arriving)
        return previous

    real_signal(signal.SIGINT, signal.default_int_handler)
    real_signal(signal.SIGTERM, terminated)
    try:
        monkeypatch.setattr(signal, "signal", swap_then_signal)
        with pytest.raises(KeyboardInterrupt), interrupts_deferred():
            pass
        monkeypatch.undo()
        after = (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM))
    finally:
        monkeypatch.undo()
        for s, handler in before.items():
            real_signal(s, handler)
    assert after == (signal.default_int_handler, terminated)


def test_the_warm_up_starts_above_zero_and_ends_on_the_cosine():
    """The linear warm-up is ``(step + 1) / warmup_steps``: its first step learns (a factor of 0 wasted it, and its
    Adam moments were taken at a zero rate), and its last reaches the cosine schedule."""
    import math

    from alcn_cv.train.config import TrainConfig

    cfg = TrainConfig()
    cfg.optim.warmup_steps, cfg.optim.epochs = 4, 1

    def cosine(step: int) -> float:
        return 0.5 * (1 + math.cos(math.pi * step / 100))

    assert trainer._lr_factor(cfg, 0, 100) == pytest.approx(0.25 * cosine(0))
    assert trainer._lr_factor(cfg, 3, 100) == pytest.approx(cosine(3))
    assert trainer._lr_factor(cfg, 100, 100) == pytest.approx(0.0, abs=1e-12)


def test_an_epochs_intensity_gains_are_log_uniform_within_the_jitter():
    """``gain_jitter`` is the range of a log-uniform gain: the gains are ``exp`` of a uniform draw between the logs of
    its ends (the logs themselves, negative half of the time, would turn the windows' intensities negative)."""
    from alcn_cv.train.config import TrainConfig

    cfg = TrainConfig()
    cfg.data.gain_jitter = [0.5, 2.0]
    perm, gains = trainer._epoch_plan(cfg, 3, 4000)
    assert sorted(perm.tolist()) == list(range(4000))
    assert float(gains.min()) >= 0.5 and float(gains.max()) <= 2.0
    logs = gains.log()
    assert abs(float(logs.mean())) < 0.03 and abs(float((logs < 0).float().mean()) - 0.5) < 0.03  # centred on log 1
    again, same = trainer._epoch_plan(cfg, 3, 4000)
    assert torch.equal(again, perm) and torch.equal(same, gains)  # a function of (seed, epoch): resuming is exact


def test_a_resumed_runs_clock_goes_on_from_the_checkpoints_time():
    """The restored state's clock starts ``elapsed`` seconds before ``start``: restarted at zero, a resumed run's
    recorded training time counted only its last part."""
    from alcn_cv.train.checkpoint import restore_checkpoint

    model = torch.nn.Linear(2, 1)
    optimizer = torch.optim.SGD(model.parameters(), lr=0.1)
    ckpt = {
        "model": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "rng": torch.get_rng_state(),
        "history": [{"epoch": 0}],
        "epoch": 1,
        "step_in_epoch": 2,
        "sums": [1.5, 3, 4],
        "elapsed": 100.0,
    }
    state = restore_checkpoint(ckpt, model, optimizer, start=1000.0)
    assert state.start == 900.0
    assert (state.history, state.epoch, state.step_in_epoch, state.sums) == ([{"epoch": 0}], 1, 2, [1.5, 3, 4])


def test_a_resume_with_another_seed_is_a_difference():
    """The seed draws the data and the epochs' order: a run resumed with another one is another run, named as such
    (the other differences compared are the model's, the data's and the optimisation's)."""
    from alcn_cv.train.checkpoint import _config_dict, _differences
    from alcn_cv.train.config import TrainConfig

    saved = _config_dict(TrainConfig().resolved())
    assert _differences(saved, TrainConfig()) == []
    assert _differences(saved, TrainConfig(seed=5)) == ["seed (0 in the checkpoint, 5 now)"]
