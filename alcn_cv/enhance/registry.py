"""Normalizations by name: ``create("clahe", clipLimit=2.0).apply(img)``."""

from __future__ import annotations

import ast
from collections.abc import Callable
from typing import TypeVar

from alcn_cv.enhance.base import Normalization, NoNormalization
from alcn_cv.errors import InputError

__all__ = ["available", "create", "from_spec", "parse_params", "parse_spec", "register"]

_REGISTRY: dict[str, type[Normalization]] = {}
N = TypeVar("N", bound=type[Normalization])


def register(cls: N) -> N:
    """Class decorator adding a :class:`Normalization` subclass under its ``name``."""
    if not cls.name:
        raise TypeError(f"{cls.__name__} has no name to register under")
    if cls.name in _REGISTRY and _REGISTRY[cls.name] is not cls:
        raise TypeError(f"normalization {cls.name!r} is already registered by {_REGISTRY[cls.name].__name__}")
    _REGISTRY[cls.name] = cls
    return cls


def available() -> list[str]:
    """Names accepted by :func:`create`, in registration order."""
    return list(_REGISTRY)


def create(name: str, **params: object) -> Normalization:
    """Create the normalization registered as ``name`` with its parameters.

    Raises:
        InputError: unknown name or parameters.
    """
    try:
        cls: Callable[..., Normalization] = _REGISTRY[name]
    except KeyError:
        raise InputError(f"unknown normalization {name!r}; available: {', '.join(available())}") from None
    try:
        return cls(**params)
    except TypeError as exc:
        raise InputError(f"bad parameters for {name!r}: {exc}") from None


def parse_params(items: list[str]) -> dict[str, object]:
    """``["clipLimit=2", "backend=torch"]`` -> ``{"clipLimit": 2, "backend": "torch"}`` (Python literals, else strings)."""
    params: dict[str, object] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.isidentifier():
            raise InputError(f"bad parameter {item!r}; expected NAME=VALUE")
        try:
            params[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            params[key] = value
    return params


def parse_spec(spec: str) -> tuple[str, dict[str, object]]:
    """A method with parameters, ``NAME[:KEY=VALUE...]``: ``"alcn:model=lite:mixture=pyramid"`` ->
    ``("alcn", {"model": "lite", "mixture": "pyramid"})``. The name is not checked here."""
    name, *items = spec.strip().split(":")
    if not name:
        raise InputError(f"bad method {spec!r}; expected NAME[:KEY=VALUE...]")
    return name, parse_params(items)


def from_spec(spec: str, **defaults: object) -> Normalization:
    """The normalization a spec ``NAME[:KEY=VALUE...]`` names (:func:`parse_spec`), e.g.
    ``from_spec("alcn:model=lite:mixture=pyramid")``; ``defaults`` fill parameters the spec
    does not give.

    Raises:
        InputError: bad spec, unknown name or parameters.
    """
    name, params = parse_spec(spec)
    return create(name, **{**defaults, **params})


register(NoNormalization)
