"""The training configuration schema (alcn_cv.train.config)."""

from __future__ import annotations

import re

import pytest

from alcn_cv.errors import InputError
from alcn_cv.presets import dump_toml
from alcn_cv.train.config import TRAIN_CONFS, TrainConfig, load_config


def test_defaults_and_presets():
    cfg = load_config()
    assert cfg == TrainConfig()
    assert not set(cfg.data.train_lighting) & set(cfg.data.val_lighting)
    assert load_config("paper") == cfg  # the defaults are the shipped file's preset
    full = load_config("paper-full")
    assert full.data.n_train == 500_000 and full.run.device == "cuda"
    assert set(TRAIN_CONFS) == {"paper", "paper-full"}


def test_toml_file_overrides_and_round_trip(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('seed = 3\n[optim]\nlr = 1\nepochs = 2\n[model]\nmethod = "dog"\n')
    overrides = [
        "optim.batch_size=16",
        {"run": {"threads": 2}},
        "data.train_lighting=['ambient', 'side']",
        "data.val_lighting=['dark']",
    ]
    cfg = load_config(path, overrides)
    assert (cfg.seed, cfg.optim.lr, cfg.optim.epochs, cfg.model.method) == (3, 1.0, 2, "dog")
    assert isinstance(cfg.optim.lr, float)
    assert (cfg.optim.batch_size, cfg.run.threads, cfg.data.train_lighting) == (16, 2, ["ambient", "side"])
    again = tmp_path / "again.toml"
    again.write_text(dump_toml(cfg))
    assert load_config(again) == cfg


@pytest.mark.parametrize(
    "values, key",
    [
        ({"optim": {"lrr": 1e-3}}, "optim.lrr"),
        ({"bogus": 1}, "bogus"),
        ({"optim": {"epochs": "ten"}}, "optim.epochs"),
        ({"optim": {"epochs": 2.5}}, "optim.epochs"),
        ({"model": {"channels": [20]}}, "model.channels"),
        ({"model": {"method": "clahe"}}, "model.method"),
        ({"optim": {"lr": -1.0}}, "optim.lr"),
        ({"data": {"path": "/nonexistent/phos"}}, "data.path"),
        ({"data": {"val_lighting": ["ambient"]}}, "data.val_lighting"),
        ({"data": {"train_lighting": ["moonlight"]}}, "data.train_lighting"),
        ({"model": {"dog": [0.5, 0.7]}}, "model.dog"),
        ({"optim": 3}, "optim"),
        # "meta" with so few windows that none (or all) would be rendered under the anchor lighting
        ({"data": {"n_train": 1}}, "data.n_train"),
        ({"data": {"n_train": 3, "anchor_fraction": 0.9}}, "data.anchor_fraction"),
    ],
)
def test_errors_name_the_key(values, key):
    with pytest.raises(InputError, match=key.replace(".", r"\.")):
        load_config(values)


def test_bad_toml_and_unknown_preset(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("seed = = 3")
    with pytest.raises(InputError, match="invalid TOML"):
        load_config(bad)
    # a name is a preset's, the one error of every command for an unknown one; a path is a TOML file's
    with pytest.raises(InputError, match="^unknown preset 'nonexistent-preset'; choose one of paper, paper-full$"):
        load_config("nonexistent-preset")
    for path in (tmp_path / "missing.toml", tmp_path / "missing", "./missing"):
        with pytest.raises(InputError, match=f"^config file {re.escape(str(path))}: not found$"):
            load_config(str(path))
    with pytest.raises(InputError, match="KEY=VALUE"):
        load_config(None, ["optim.lr"])


def test_the_folders_are_given_resolved_for_a_checkpoint_and_from_home_for_a_weight_file(tmp_path, monkeypatch):
    """A configuration holds its folders as given (load_config made them absolute, and the weight file, which users
    share, recorded `/home/<user>/...`); resolved() makes them absolute (a checkpoint's), shareable() writes the home
    folder ~ (a weight file's)."""
    from alcn_cv.train.config import TRAIN_FOLDER_SETTINGS, home_path

    home = tmp_path / "home"
    (home / "work" / "phos").mkdir(parents=True)
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(home / "work")
    cfg = load_config(None, ["data.path='phos'", f"data.val_path='{home / 'work' / 'phos'}'"])
    assert tuple(cfg.folders()) == TRAIN_FOLDER_SETTINGS
    assert cfg.folders() == {"data.path": "phos", "data.val_path": str(home / "work" / "phos")}
    assert set(cfg.resolved().folders().values()) == {str(home / "work" / "phos")}
    assert cfg.shareable().folders() == {"data.path": "phos", "data.val_path": "~/work/phos"}
    assert cfg.folders() == {"data.path": "phos", "data.val_path": str(home / "work" / "phos")}  # copies
    elsewhere = str(tmp_path / "elsewhere")  # not under the home folder: as given
    given = ["phos", "~/phos", str(home), elsewhere, "courbevoie", ""]
    assert [home_path(entry) for entry in given] == ["phos", "~/phos", "~", elsewhere, "courbevoie", ""]
