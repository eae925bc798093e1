"""Presets are named, chosen and stored one way in every command that has them (hloc's ``confs``): a module-level
``CONFS`` with one line of ``CONF_SUMMARIES`` per preset, ``--conf NAME`` on the command line
(:func:`alcn_cv.cli.add_conf_option`: the ``--help`` lists the presets one line each; an unknown name is the one error
of :func:`alcn_cv.presets.preset_named`, one line, exit code 2), copies handed out, and ``alcn demo`` running the
``demo`` presets as they are."""

from __future__ import annotations

import copy
import dataclasses
import re
from pathlib import Path
from typing import Any

import pytest

from alcn_cv.bench import detect_settings, relight_settings, speed
from alcn_cv.cli import build_parser, main
from alcn_cv.data import detect as data_detect
from alcn_cv.data import detect_settings as data_detect_settings
from alcn_cv.data import pose as data_pose
from alcn_cv.data import pose_settings as data_pose_settings
from alcn_cv.errors import InputError
from alcn_cv.presets import preset
from alcn_cv.train import config as train_config
from pose import build as pose_build
from pose import corner_train

#: The stages of the data engine and the benchmarks: the module that holds their ``CONFS`` (settings dataclasses,
#: ``default`` first) and ``CONF_SUMMARIES``, and their command line without ``--conf``.
STAGES: dict[str, tuple[Any, list[str]]] = {
    "alcn data detect": (data_detect_settings, ["data", "detect", "--out", "o"]),
    "alcn data pose": (data_pose_settings, ["data", "pose", "--out", "o"]),
    "alcn bench detect": (detect_settings, ["bench", "detect", "--data", "d", "--out", "o"]),
    "alcn bench relight": (relight_settings, ["bench", "relight", "--out", "o"]),
    "alcn bench speed": (speed, ["bench", "speed", "--out", "o"]),
}

#: Every command that takes a preset: its presets, their summaries and its command line without ``--conf``.
COMMANDS: dict[str, tuple[Any, Any, list[str]]] = {
    **{command: (module.CONFS, module.CONF_SUMMARIES, argv) for command, (module, argv) in STAGES.items()},
    "alcn train": (train_config.TRAIN_CONFS, train_config.TRAIN_CONF_SUMMARIES, ["train"]),
    "alcn train-real-light": (
        train_config.REAL_LIGHT_CONFS,
        train_config.REAL_LIGHT_CONF_SUMMARIES,
        ["train-real-light"],
    ),
    "alcn train-unet": (train_config.UNET_CONFS, train_config.UNET_CONF_SUMMARIES, ["train-unet"]),
    "alcn distill": (train_config.DISTILL_CONFS, train_config.DISTILL_CONF_SUMMARIES, ["distill"]),
    "alcn pose build": (pose_build.CONFS, pose_build.CONF_SUMMARIES, ["pose", "build", "in.mp4", "m.npz"]),
    "alcn pose train-corners": (
        corner_train.CONFS,
        corner_train.CONF_SUMMARIES,
        ["pose", "train-corners", "in", "c.onnx", "--box-ply", "box.ply"],
    ),
    "alcn pose eval": (corner_train.CONFS, corner_train.CONF_SUMMARIES, ["pose", "eval", "--data", "d", "--out", "o"]),
    "alcn pose planar": (corner_train.CONFS, corner_train.CONF_SUMMARIES, ["pose", "planar", "--out", "o"]),
}

#: The commands that also take ``--set KEY=VALUE`` overrides of their preset's keys.
WITH_SETTINGS = {
    "alcn train",
    "alcn train-real-light",
    "alcn train-unet",
    "alcn distill",
    "alcn pose train-corners",
    "alcn pose eval",
    "alcn pose planar",
}


class _StopError(Exception):
    """Raised by a stand-in where the test has seen what it needs."""


@pytest.mark.parametrize("command", sorted(STAGES))
def test_each_stage_stores_its_presets_one_way(command):
    module, _ = STAGES[command]
    assert isinstance(module.CONFS, dict) and next(iter(module.CONFS)) == "default"
    assert len({type(conf) for conf in module.CONFS.values()}) == 1
    assert all(dataclasses.is_dataclass(conf) for conf in module.CONFS.values())


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_each_preset_has_its_summary(command):
    confs, summaries, _ = COMMANDS[command]
    assert list(summaries) == list(confs)
    assert all(summary and "\n" not in summary for summary in summaries.values())


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_an_unknown_preset_is_the_one_line_error_naming_the_presets(command, tmp_path, monkeypatch, capsys):
    """The same message from every command (argparse's choices gave one, the training and pose commands two others),
    before any work: nothing written."""
    confs, _, argv = COMMANDS[command]
    monkeypatch.chdir(tmp_path)
    assert main([*argv, "--conf", "huge"]) == 2
    err = capsys.readouterr().err
    assert err == f"{command}: error: unknown preset 'huge'; choose one of {', '.join(confs)}\n"
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_help_lists_every_preset_on_a_line_of_its_own(command, capsys):
    confs, summaries, argv = COMMANDS[command]
    with pytest.raises(SystemExit):
        build_parser().parse_args([*argv, "--help"])
    text = capsys.readouterr().out
    listed = text[text.index("presets (--conf NAME):") :]
    for name, summary in summaries.items():
        assert re.search(rf"^  {re.escape(name)}  ", listed, re.MULTILINE), (name, listed)
        assert f"{name} {' '.join(summary.split())}" in " ".join(listed.split()), (name, listed)
    assert len(re.findall(r"^  \S", listed, re.MULTILINE)) == len(confs)  # one line each, the rest wrapped under it
    assert ("--set KEY=VALUE" in text) == (command in WITH_SETTINGS)


@pytest.mark.parametrize("module, settings", [(data_detect, data_detect_settings), (data_pose, data_pose_settings)])
def test_the_generators_name_the_presets_for_an_unknown_one(module, settings, tmp_path):
    with pytest.raises(InputError, match=f"^unknown preset 'huge'; choose one of {', '.join(settings.CONFS)}$"):
        module.generate(tmp_path / "x", conf="huge", progress=False)
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("module", [data_detect_settings, data_pose_settings, relight_settings])
def test_the_presets_that_are_values_are_frozen(module):
    """A run derives its own with dataclasses.replace: none can change a preset."""
    for conf in module.CONFS.values():
        field = dataclasses.fields(conf)[0].name
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(conf, field, None)


def _change_every_list(settings: Any) -> None:
    """What a careless consumer does: append to every list of ``settings`` in place."""
    for field in dataclasses.fields(settings):
        value = getattr(settings, field.name)
        if isinstance(value, list):
            value.append(value[0] if value else "changed")


@pytest.mark.parametrize("module", [detect_settings, speed])
def test_a_preset_handed_out_is_a_copy(module):
    before = copy.deepcopy(module.CONFS)
    for name in module.CONFS:
        _change_every_list(preset(module.CONFS, name))
    assert before == module.CONFS


@pytest.mark.parametrize(
    ("command", "benchmark", "conf"),
    [("alcn bench detect", "alcn_cv.bench.detect", "small"), ("alcn bench speed", "alcn_cv.bench.speed", "quick")],
)
def test_the_command_line_changes_a_copy_of_the_preset(command, benchmark, conf, monkeypatch):
    """The benchmark gets the preset with the options given, and what it does to them stays in its run."""
    module, argv = STAGES[command]
    before = copy.deepcopy(module.CONFS)
    given: list[Any] = []

    def run(*args: Any, **kwargs: Any) -> None:
        settings = next(a for a in args if dataclasses.is_dataclass(a))
        given.append(copy.deepcopy(settings))
        _change_every_list(settings)
        raise _StopError

    monkeypatch.setattr(f"{benchmark}.main", run)
    args = build_parser().parse_args([*argv, "--conf", conf, "--threads", "3"])
    with pytest.raises(_StopError):
        args.func(args)
    assert given == [dataclasses.replace(before[conf], threads=3)]
    assert before == module.CONFS


def test_the_demo_runs_the_demo_presets_as_they_are(tmp_path, monkeypatch):
    """``alcn demo`` is ``alcn data detect --conf demo`` then ``alcn bench detect --conf demo``: no setting of its
    own (a change of the preset is a change of the demo)."""
    pytest.importorskip("skimage")
    pytest.importorskip("torch")
    from alcn_cv.bench import detect as bench
    from alcn_cv.commands import demo

    changed = dataclasses.replace(detect_settings.CONFS["demo"], epochs=7, methods=["none", "dog"])
    monkeypatch.setitem(detect_settings.CONFS, "demo", changed)

    generated: list[dict[str, Any]] = []
    render = data_detect.generate

    def generate(out: Path, **kwargs: Any) -> Path:
        generated.append(kwargs)
        return render(out, **{**kwargs, "n_test": 1, "n_train": 1})  # seconds: the demo reads one test image

    benchmarked: list[Any] = []

    def run(data: Path, out: Path, settings: Any, **kwargs: Any) -> None:
        benchmarked.append(settings)
        raise _StopError

    monkeypatch.setattr(data_detect, "generate", generate)
    monkeypatch.setattr(demo, "normalization_grid", lambda *args, **kwargs: tmp_path / "normalized.png")
    monkeypatch.setattr(bench, "main", run)
    with pytest.raises(_StopError):
        demo.main(tmp_path / "demo", progress=False)
    assert generated == [{"seed": 0, "conf": "demo", "overwrite": True, "progress": False}]
    assert benchmarked == [changed] and benchmarked[0] is not changed


@pytest.mark.parametrize("conf", ["default", "small"])
def test_a_normalization_registered_after_import_is_in_the_presets_and_the_default(conf, tmp_path, monkeypatch):
    """``--conf default`` held the normalizations registered when alcn_cv.bench was imported, ``detect.main``'s default
    settings those registered when it ran: a plugin's, registered in between, was in the one and not the other."""
    pytest.importorskip("torch")
    from alcn_cv.bench import detect as bench
    from alcn_cv.enhance import registry
    from alcn_cv.enhance.base import NoNormalization

    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))  # the registration is the test's alone

    @registry.register
    class Plugin(NoNormalization):
        name = "plugin"
        summary = "a normalization registered after alcn_cv.bench was imported"

    built: list[list[str]] = []

    def build_methods(methods: list[str], create: Any) -> None:
        built.append(list(methods))
        raise _StopError

    monkeypatch.setattr(bench, "build_methods", build_methods)
    monkeypatch.chdir(tmp_path)
    args = build_parser().parse_args(["bench", "detect", "--data", "d", "--out", "o", "--conf", conf])
    with pytest.raises(_StopError):
        args.func(args)
    with pytest.raises(_StopError):
        bench.main("d", "o")
    assert built[0] == built[1] == detect_settings.default_methods()
    assert "plugin" in built[0] and detect_settings.CONFS[conf].methods is None
