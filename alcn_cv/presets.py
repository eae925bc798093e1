"""Named presets (hloc's ``confs``), taken one way by every stage that has them.

A stage keeps its presets in a module-level dict, ``CONFS`` (name -> settings: a dataclass, or a mapping of
keywords), with ``CONF_SUMMARIES`` (name -> one line saying what the preset is) beside it; its command takes the
name with ``--conf NAME`` (:func:`alcn_cv.cli.add_conf_option`). Here is what every stage shares: the one lookup of
a name, which names the presets when there is none of that name (:func:`preset_named`), the copy of a preset a
caller may change (:func:`preset`), ``KEY=VALUE`` overrides of its keys (:func:`with_settings`, ``--set``) and the
settings written back as TOML (:func:`dump_toml`, ``--print-config``).

The module imports nothing of alcn_cv but its errors, so that the data, bench and training stages and the packages
on top of alcn_cv all use it without importing one another.
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import sys
import tomllib
from collections.abc import Mapping, Sequence
from typing import Any, TypeVar

from alcn_cv.errors import InputError

__all__ = ["dump_toml", "preset", "preset_named", "print_config", "with_given", "with_settings"]

ConfigT = TypeVar("ConfigT")


def preset_named(confs: Mapping[str, ConfigT], name: str) -> ConfigT:
    """The preset ``confs[name]`` itself, shared by every caller: read it, or change a copy (:func:`preset`).

    Raises:
        InputError: no preset of that name: ``unknown preset 'huge'; choose one of a, b, c`` (the presets of
            ``confs`` in their order), the one message of every stage.
    """
    if name not in confs:
        raise InputError(f"unknown preset {name!r}; choose one of {', '.join(confs)}")
    return confs[name]


def preset(confs: Mapping[str, ConfigT], name: str, settings: Sequence[str | dict[str, Any]] = ()) -> ConfigT:
    """A copy of the preset ``confs[name]`` with :func:`with_settings` applied: the caller's to change.

    Raises:
        InputError: an unknown name (:func:`preset_named`), or a bad setting (:func:`with_settings`).
    """
    return with_settings(preset_named(confs, name), settings)


def with_given(cfg: ConfigT, **given: Any) -> ConfigT:
    """A copy of the dataclass ``cfg`` with the fields ``given`` that are not None replaced: None, not 0, leaves the
    preset's value (an option not given), so that an option's 0 is checked as a value, never read as "the default"."""
    return dataclasses.replace(cfg, **{key: value for key, value in given.items() if value is not None})


def _type_name(value: Any) -> str:
    return {
        bool: "a boolean",
        int: "an integer",
        float: "a number",
        str: "a string",
        list: "a list",
        tuple: "a list",
        dict: "a table",
    }.get(type(value), type(value).__name__)


def _coerce(key: str, value: Any, default: Any) -> Any:
    """``value`` checked against the type of ``default`` (ints are accepted for floats, lists for
    tuples; list items against the default's first item)."""
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        value = float(value) if ok else value
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif isinstance(default, (list, tuple)):
        ok = isinstance(value, (list, tuple))
        if ok and default:
            value = [_coerce(key, v, default[0]) for v in value]
        if ok:
            value = type(default)(value)
    else:
        ok = isinstance(value, type(default))
    if not ok:
        # a value that is no TOML stays a string: the usual causes are a list of unquoted words and Python's booleans
        hint = ""
        if isinstance(value, str) and value.startswith(("[", "{")):
            hint = " (a TOML value: quote the strings, e.g. ['a', 'b'])"
        elif isinstance(value, str) and isinstance(default, bool):
            hint = " (values are TOML: true or false, in lower case)"
        raise InputError(f"config key {key!r} must be {_type_name(default)}, got {value!r}{hint}")
    return value


def _merge(obj: Any, values: dict[str, Any], prefix: str = "") -> None:
    """Set the keys of ``values`` on the dataclass or dict ``obj`` (nested tables recursively)."""
    if not isinstance(values, dict):
        raise InputError(f"config key {prefix.rstrip('.')!r} must be a table, got {values!r}")
    names = set(obj) if isinstance(obj, dict) else {f.name for f in dataclasses.fields(obj)}
    for key, value in values.items():
        full = prefix + key
        if key not in names:
            close = difflib.get_close_matches(key, sorted(names), n=1)
            guess = f" did you mean {prefix + close[0]!r}?" if close else ""
            raise InputError(f"unknown config key {full!r};{guess} known keys here: {', '.join(sorted(names))}")
        current = obj[key] if isinstance(obj, dict) else getattr(obj, key)
        if dataclasses.is_dataclass(current) or isinstance(current, dict):
            _merge(current, value, full + ".")
        elif isinstance(obj, dict):
            obj[key] = _coerce(full, value, current)
        else:
            setattr(obj, key, _coerce(full, value, current))


def _parse_setting(item: str) -> dict[str, Any]:
    """``"optim.lr=3e-4"`` -> ``{"optim": {"lr": 0.0003}}`` (the value is read as TOML, or a bare string)."""
    if "=" not in item:
        raise InputError(f"setting {item!r} must be KEY=VALUE (--print-config shows the keys)")
    key, text = (s.strip() for s in item.split("=", 1))
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        value = text
    out: dict[str, Any] = {}
    node = out
    parts = key.split(".")
    for p in parts[:-1]:
        node = node.setdefault(p, {})
    node[parts[-1]] = value
    return out


def with_settings(cfg: ConfigT, settings: Sequence[str | dict[str, Any]] = ()) -> ConfigT:
    """A copy of the dataclass ``cfg`` with ``settings`` applied in order.

    Args:
        cfg: a configuration dataclass (nested dataclasses and dicts are tables).
        settings: ``"KEY=VALUE"`` strings (``--set``; dotted keys, the value read as TOML, else as
            a string) or nested dicts.

    Raises:
        InputError: an unknown key or a value of the wrong type, the key named in one line.
    """
    cfg = copy.deepcopy(cfg)
    for item in settings:
        _merge(cfg, item if isinstance(item, dict) else _parse_setting(item))
    return cfg


def print_config(config: Any) -> int:
    """Write the configuration dataclass ``config`` to stdout as TOML (``--print-config``); the exit code, 0."""
    sys.stdout.write(dump_toml(config))
    return 0


def dump_toml(cfg: Any) -> str:
    """A configuration dataclass as TOML text, its tables after its keys (``--print-config``, a run's
    ``config.toml``; :func:`alcn_cv.train.config.load_config` reads a :class:`~alcn_cv.train.config.TrainConfig`'s
    back to the same values)."""
    d = dataclasses.asdict(cfg)
    lines = [f"{k} = {_toml_value(v)}" for k, v in d.items() if not isinstance(v, dict)]
    for table, values in d.items():
        if isinstance(values, dict):
            lines += ["", f"[{table}]"] + [f"{k} = {_toml_value(v)}" for k, v in values.items()]
    return "\n".join(lines) + "\n"


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(v)
