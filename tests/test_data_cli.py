from __future__ import annotations

import argparse

import pytest

from alcn_cv.data.cli import add_parser


def _data_subparsers() -> dict[str, argparse.ArgumentParser]:
    root = argparse.ArgumentParser(prog="alcn")
    add_parser(root.add_subparsers())
    data = next(a for a in root._actions if isinstance(a, argparse._SubParsersAction)).choices["data"]
    return next(a for a in data._actions if isinstance(a, argparse._SubParsersAction)).choices


def _no_default(value: object) -> bool:
    return value is None or value is False or value == argparse.SUPPRESS


@pytest.mark.parametrize("command", sorted(_data_subparsers()))
def test_help_states_every_default(command):
    """Every option with a default value says it in its help (``alcn data COMMAND --help``)."""
    parser = _data_subparsers()[command]
    missing = [a.option_strings[-1] for a in parser._actions
               if a.option_strings and not _no_default(a.default) and "default" not in a.help]
    assert not missing, f"alcn data {command}: no default in the help of {missing}"
