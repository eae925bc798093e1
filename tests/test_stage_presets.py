"""Presets are named, chosen and stored one way in every stage that has them (hloc's ``confs``): a module-level
``CONFS`` of settings dataclasses, ``--conf NAME`` on the command line (an unknown name is argparse's one-line error,
the ``--help`` lists the names one line each), copies handed out, and ``alcn demo`` running the ``demo`` presets as
they are."""

from __future__ import annotations

import copy
import dataclasses
import re
from pathlib import Path
from typing import Any

import pytest

from alcn_cv.bench import detect_settings, relight_settings, speed
from alcn_cv.cli import build_parser
from alcn_cv.data import detect as data_detect
from alcn_cv.data import pose as data_pose
from alcn_cv.errors import InputError
from alcn_cv.train.config import preset

#: Each stage with presets: the module that holds its ``CONFS`` and ``CONF_SUMMARIES``, and its command line
#: without ``--conf``.
STAGES: dict[str, tuple[Any, list[str]]] = {
    "alcn data detect": (data_detect, ["data", "detect", "--out", "o"]),
    "alcn data pose": (data_pose, ["data", "pose", "--out", "o"]),
    "alcn bench detect": (detect_settings, ["bench", "detect", "--data", "d", "--out", "o"]),
    "alcn bench relight": (relight_settings, ["bench", "relight", "--out", "o"]),
    "alcn bench speed": (speed, ["bench", "speed", "--out", "o"]),
}


class _StopError(Exception):
    """Raised by a stand-in where the test has seen what it needs."""


@pytest.mark.parametrize("command", sorted(STAGES))
def test_each_stage_stores_its_presets_one_way(command):
    module, _ = STAGES[command]
    assert isinstance(module.CONFS, dict) and next(iter(module.CONFS)) == "default"
    assert len({type(conf) for conf in module.CONFS.values()}) == 1
    assert all(dataclasses.is_dataclass(conf) for conf in module.CONFS.values())
    assert list(module.CONF_SUMMARIES) == list(module.CONFS)


@pytest.mark.parametrize("command", sorted(STAGES))
def test_an_unknown_preset_is_one_line_naming_the_presets(command, capsys):
    module, argv = STAGES[command]
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args([*argv, "--conf", "huge"])
    assert exit_.value.code == 2
    line = capsys.readouterr().err.splitlines()[-1]
    assert line.startswith(f"{command}: error: argument --conf: invalid choice: 'huge' (choose from ")
    assert re.findall(r"'?([\w-]+)'?(?:, |\)$)", line.partition("choose from ")[2]) == list(module.CONFS)


@pytest.mark.parametrize("command", sorted(STAGES))
def test_help_lists_every_preset_on_a_line_of_its_own(command, capsys):
    module, argv = STAGES[command]
    with pytest.raises(SystemExit):
        build_parser().parse_args([*argv, "--help"])
    text = capsys.readouterr().out
    listed = text[text.index("presets (--conf NAME):") :]
    for name, summary in module.CONF_SUMMARIES.items():
        assert re.search(rf"^  {re.escape(name)}  ", listed, re.MULTILINE), (name, listed)
        assert f"{name} {' '.join(summary.split())}" in " ".join(listed.split()), (name, listed)


@pytest.mark.parametrize("module", [data_detect, data_pose])
def test_the_generators_name_the_presets_for_an_unknown_one(module, tmp_path):
    with pytest.raises(InputError, match=f"unknown preset 'huge'; choose one of {', '.join(module.CONFS)}"):
        module.generate(tmp_path / "x", conf="huge", progress=False)


@pytest.mark.parametrize("module", [data_detect, data_pose, relight_settings])
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
