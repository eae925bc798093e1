"""Every ``alcn`` command's ``--help`` states the default of every option that has one."""

from __future__ import annotations

import argparse

import pytest

from alcn_cv.cli import build_parser


def _commands(parser: argparse.ArgumentParser, prefix: str = "alcn") -> dict[str, argparse.ArgumentParser]:
    found = {prefix: parser}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found |= _commands(sub, f"{prefix} {name}")
    return found


COMMANDS = _commands(build_parser())


def _has_default(action: argparse.Action) -> bool:
    return action.default not in (None, False, [], argparse.SUPPRESS) and action.help != argparse.SUPPRESS


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_help_states_every_default(command):
    parser = COMMANDS[command]
    missing = [
        a.option_strings[-1]
        for a in parser._actions
        if a.option_strings and _has_default(a) and "default" not in (a.help or "")
    ]
    assert not missing, f"{command}: no default in the help of {missing}"


def test_help_has_no_literal_percent_escapes():
    for command, parser in COMMANDS.items():
        assert "%%" not in parser.format_help(), command


def test_building_the_command_line_does_not_import_torch():
    """`alcn pose bench-corners` and the other torch-free commands start without torch (an app's
    pose tracker runs through cv2.dnn): only a command that needs torch imports it when it runs."""
    import subprocess
    import sys

    code = "import sys, alcn_cv.cli as c; c.build_parser(); print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


#: The commands that show no progress bar (no long loop of their own), so take no ``--no-progress``.
WITHOUT_PROGRESS_BARS = {
    "alcn calib board",
    "alcn data compare-psm",
    "alcn data preview",
    "alcn export",
    "alcn pose bench-corners",
    "alcn pose corner-recall",
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_command_with_progress_bars_can_hide_them(command):
    parser = COMMANDS[command]
    if any(isinstance(a, argparse._SubParsersAction) for a in parser._actions):
        return  # a group: its leaves are checked
    options = {o for a in parser._actions for o in a.option_strings}
    assert ("--no-progress" in options) == (command not in WITHOUT_PROGRESS_BARS), command


def _commands_with(option: str) -> dict[str, argparse.Action]:
    return {c: a for c, p in COMMANDS.items() for a in p._actions if option in a.option_strings}


@pytest.mark.parametrize("command", sorted(_commands_with("--conf")))
def test_every_preset_is_taken_one_way(command):
    """Every --conf is alcn_cv.cli.add_conf_option's: the name looked up by the command (no argparse choices, whose
    error was another message) and the presets listed below the options, one line each."""
    parser, conf = COMMANDS[command], _commands_with("--conf")[command]
    assert conf.choices is None and conf.metavar == "NAME" and "one of those listed below" in conf.help
    assert parser.epilog.startswith("presets (--conf NAME):\n  ")


def test_one_option_name_for_each_idea():
    """The same idea has the same option in every command (a newcomer's walk-through found three that had two)."""
    # a preset is --conf NAME in every command that has presets; a size in pixels says what it measures (--side,
    # --frame-size)
    stages = {"alcn data detect", "alcn data pose", "alcn bench detect", "alcn bench relight", "alcn bench speed"}
    training = {"alcn train", "alcn train-real-light", "alcn train-unet", "alcn distill"}
    pose = {"alcn pose build", "alcn pose train-corners", "alcn pose eval", "alcn pose planar"}
    assert stages | training | pose == set(_commands_with("--conf"))
    # the keypoints per image: --n-features
    assert {"alcn calib register", "alcn pose build", "alcn pose track", "alcn bench relight"} <= set(
        _commands_with("--n-features")
    )
    # runs repeated, each with its own seed: one --seeds declaration, a list of seeds everywhere
    seeds = _commands_with("--seeds")
    repeated = {"alcn bench detect", "alcn bench fewshot", "alcn bench relight", "alcn pose eval"}
    assert repeated <= set(seeds) and len({type(a) for a in seeds.values()}) == 1, seeds
    # an earlier run's output is replaced with --overwrite, in every command that refuses it
    benches = {f"alcn bench {name}" for name in ("detect", "fewshot", "invariance", "relight", "speed")}
    assert benches | {"alcn normalize", "alcn train-real-light"} <= set(_commands_with("--overwrite"))
    retired = {"--max-features", "--draws", "--size", "--quick", "--small"}
    assert not {c for c, p in COMMANDS.items() for a in p._actions if retired & set(a.option_strings)}


def test_the_command_says_its_version_and_opencvs(capsys):
    import cv2

    from alcn_cv import __version__
    from alcn_cv.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.startswith(f"alcn-cv {__version__} (OpenCV {cv2.__version__}, NumPy ")
