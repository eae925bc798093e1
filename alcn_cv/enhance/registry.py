"""Normalizations by name: ``create("clahe", clipLimit=2.0).apply(img)``."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from alcn_cv.enhance.base import Normalization, NoNormalization
from alcn_cv.errors import InputError

__all__ = ["available", "create", "register"]

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


register(NoNormalization)
