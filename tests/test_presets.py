"""Each shipped weight file is its preset alone: the configuration recorded in the file's header
equals the preset's (where an older header records less than the preset, what it records)."""

from __future__ import annotations

import dataclasses
import json
import tomllib
from pathlib import Path

import pytest

from alcn_cv.errors import InputError
from alcn_cv.presets import dump_toml, preset, with_settings
from alcn_cv.train.config import (
    DISTILL_CONFS,
    REAL_LIGHT_CONFS,
    TRAIN_CONFS,
    LiteDistillConfig,
    RealLightConfig,
    TrainConfig,
    load_config,
)
from alcn_cv.weight_file import WEIGHTS_DIR, load_normalizer_file

WEIGHTS = WEIGHTS_DIR


def _recorded_equal(recorded: dict, expected: dict, where: str) -> None:
    """Every key ``recorded`` holds equals ``expected``'s (nested tables compared the same way)."""
    for key, value in recorded.items():
        assert key in expected, f"{where}.{key} is recorded but is no key of the preset"
        if isinstance(value, dict):
            _recorded_equal(value, expected[key], f"{where}.{key}")
        else:
            assert value == expected[key], f"{where}.{key}: file {value!r}, preset {expected[key]!r}"


#: Keys the paper file's header records of training variants since removed (SGD and its momentum,
#: step and constant schedules, weight decay, ReLU activations, a random initialisation): the values it records were
#: the Adam and cosine schedule, no weight decay, tanh and the DoG initialisation kept.
REMOVED = {
    "optim": {
        "optimizer": "adam",
        "momentum": 0.9,
        "schedule": "cosine",
        "step_epochs": 2,
        "step_gamma": 0.3,
        "weight_decay": 0.0,
    },
    "model": {"activation": "tanh", "init": "dog"},
}


def test_paper_preset_is_the_shipped_paper_file():
    recorded = load_normalizer_file(WEIGHTS / "alcn_normalizer.npz").meta["training"]["config"]
    for table, keys in REMOVED.items():
        for key, value in keys.items():
            assert recorded[table].pop(key) == value
    _recorded_equal(recorded, load_config("paper").to_dict(), "training.config")
    assert load_config("paper") == TrainConfig()  # the class's defaults are the shipped recipe


def test_gain_preset_is_the_shipped_gain_file():
    training = load_normalizer_file(WEIGHTS / "alcn_normalizer_gain.npz").meta["training"]
    cfg = preset(REAL_LIGHT_CONFS, "gain")
    assert cfg == RealLightConfig()
    recorded = {k: v for k, v in training["config"].items() if k not in ("scenes", "net", "command")}
    _recorded_equal(recorded, dataclasses.asdict(cfg), "training.config")
    assert [Path(s).name for s in training["config"]["scenes"]] == cfg.scenes
    assert training["config"]["net"] == cfg.net  # the network: what the preset sets, as recorded
    header = load_normalizer_file(WEIGHTS / "alcn_normalizer_gain.npz").meta["config"]
    assert {k: header[k] for k in cfg.net} == cfg.net


@pytest.mark.parametrize(
    "name, file, teacher",
    [
        ("lite", "alcn_normalizer_lite.npz", "alcn_normalizer.npz"),
        ("gain-lite", "alcn_normalizer_gain_lite.npz", "alcn_normalizer_gain.npz"),
    ],
)
def test_distill_presets_are_the_shipped_students(name, file, teacher):
    meta = load_normalizer_file(WEIGHTS / file).meta
    cfg = dataclasses.asdict(preset(DISTILL_CONFS, name))
    settings = {k: v for k, v in meta["distillation"]["settings"].items() if k not in ("frames", "teacher")}
    _recorded_equal(settings, cfg, "distillation.settings")
    assert meta["teacher"]["file"] == teacher
    from alcn_cv.train.distill import teacher_file

    assert teacher_file(cfg["teacher"]).name == teacher


@pytest.mark.parametrize(
    "file", ["alcn_normalizer", "alcn_normalizer_lite", "alcn_normalizer_gain", "alcn_normalizer_gain_lite"]
)
def test_each_onnx_file_is_its_weight_file(file):
    onnx = pytest.importorskip("onnx")
    props = {p.key: p.value for p in onnx.load(str(WEIGHTS / f"{file}.onnx")).metadata_props}
    meta = load_normalizer_file(WEIGHTS / f"{file}.npz").meta
    assert json.loads(props["alcn_cv"]) == {k: v for k, v in meta.items() if k != "training"}


def test_settings_are_typed_by_the_fields():
    cfg = with_settings(LiteDistillConfig(), ["lr=1", "channels=[4, 4]", "teacher=some/file.npz", {"epochs": 2}])
    assert (cfg.lr, cfg.channels, cfg.teacher, cfg.epochs) == (1.0, [4, 4], "some/file.npz", 2)
    assert isinstance(cfg.lr, float) and LiteDistillConfig().lr == 3e-3  # the preset itself is untouched
    net = with_settings(RealLightConfig(), ["net.divisive_sigma=3", "net.dilations=[1, 2]"]).net
    assert (net["divisive_sigma"], net["dilations"]) == (3.0, [1, 2])
    for bad, key in (
        ["epochs=1.5", "epochs"],
        ["lr=fast", "lr"],
        ["channels=4", "channels"],
        ["chanels=[4, 4]", "chanels"],
        ["teacher.x=1", "teacher"],
    ):
        with pytest.raises(InputError, match=key):
            with_settings(LiteDistillConfig(), [bad])
    with pytest.raises(InputError, match="net.tau"):
        with_settings(RealLightConfig(), ["net.tau=[1]"])
    with pytest.raises(InputError, match="unknown preset 'nope'; choose one of lite, gain-lite"):
        preset(DISTILL_CONFS, "nope")
    assert set(TRAIN_CONFS) >= {"paper"} and set(REAL_LIGHT_CONFS) == {"gain"}


def test_dump_toml_reads_back_as_the_same_values():
    @dataclasses.dataclass
    class Settings:
        name: str = 'a "quoted" \\ path'
        sizes: tuple[int, int] = (8, 8)
        ranges: list[list[float]] = dataclasses.field(default_factory=lambda: [[0.5, 1.0], [2.0, 4.0]])
        flag: bool = False
        net: dict[str, object] = dataclasses.field(default_factory=lambda: {"tau": 3.0, "dilations": (1, 2)})

    text = dump_toml(Settings())
    assert tomllib.loads(text) == {
        "name": 'a "quoted" \\ path',
        "sizes": [8, 8],
        "ranges": [[0.5, 1.0], [2.0, 4.0]],
        "flag": False,
        "net": {"tau": 3.0, "dilations": [1, 2]},
    }
    assert text.index("[net]") > text.index("flag")  # a table after the keys, as TOML requires
