"""Normalizations by name or spec: ``create("clahe", clipLimit=2.0)``, ``create("dog:sigma1=1:sigma2=2")``.

A spec ``NAME[:KEY=VALUE...]`` (:func:`parse_spec`, values as Python literals, else strings) names
a method with parameters wherever a method is named: :func:`create`, ``alcn normalize -m``, the
benchmarks' and pose commands' method lists. OpenCV's camelCase parameter names (CLAHE's
``clipLimit``, ``tileGridSize``) are also accepted in snake_case (``clip_limit``).
"""

from __future__ import annotations

import ast
import inspect
import math
import numbers
import re
import types
import typing
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from alcn_cv.enhance.base import NoNormalization, Normalization
from alcn_cv.errors import ALCNError, InputError

__all__ = [
    "available",
    "create",
    "describe",
    "format_param",
    "format_spec",
    "from_spec",
    "parameters",
    "parse_params",
    "parse_spec",
    "register",
    "same_method",
]

_REGISTRY: dict[str, type[Normalization]] = {}
N = TypeVar("N", bound=type[Normalization])


#: Names that ``alcn bench relight`` builds itself, before the registry: the free-form U-Net baseline
#: (``unet:weights=PATH``); kept from the registry so that no method of one's own takes the name.
_BUILT_BY_THE_BENCHES = frozenset({"unet"})
#: A registered name: one word of a spec, and not a bench's composite (``dog+lstd``) or a list (``none,dog``).
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_.-]*")


def register(cls: N) -> N:
    """Class decorator adding a :class:`Normalization` subclass under its ``name``: then :func:`create` builds it by
    name or spec, and every command takes it as a method once its module is imported (``alcn --import MODULE``).

    A class of the same module and name registered again (a module reloaded, a notebook's cell run again) replaces
    the earlier one.

    Raises:
        TypeError: not a :class:`Normalization` subclass; no ``name``, one that a spec cannot hold (letters, digits,
            ``_``, ``-`` and ``.``, a letter first) or one another class holds; an ``output_range`` that is not two
            finite numbers, the first the smaller.
    """
    if not (isinstance(cls, type) and issubclass(cls, Normalization)):
        raise TypeError(f"{getattr(cls, '__name__', cls)!r} is not a subclass of alcn_cv.Normalization")
    if not cls.name:
        raise TypeError(f"{cls.__name__} has no name to register under")
    if not _NAME.fullmatch(cls.name):
        raise TypeError(f"{cls.__name__}: {cls.name!r} cannot name a method (letters, digits, _ - ., a letter first)")
    if cls.name in _BUILT_BY_THE_BENCHES:
        raise TypeError(f"{cls.__name__}: {cls.name!r} names a method the benchmarks build themselves: another name")
    bounds = cls.output_range  # the class's own; an instance may set another (ALCN's, from its weight file)
    if isinstance(bounds, tuple | list):  # not a property, which each instance answers
        finite = [isinstance(b, numbers.Real) and math.isfinite(b) for b in bounds]
        if finite != [True, True] or not bounds[0] < bounds[1]:
            raise TypeError(f"{cls.__name__}: output_range must be two finite numbers (low, high), got {bounds!r}")
    held = _REGISTRY.get(cls.name)
    if held is not None and (held.__module__, held.__qualname__) != (cls.__module__, cls.__qualname__):
        raise TypeError(
            f"normalization {cls.name!r} is already registered by {held.__module__}.{held.__qualname__}: give "
            f"{cls.__module__}.{cls.__qualname__} another name"
        )
    _REGISTRY[cls.name] = cls
    return cls


def available() -> list[str]:
    """Names accepted by :func:`create`, in registration order."""
    return list(_REGISTRY)


def describe(name: str) -> tuple[str, str]:
    """``(summary, reference)`` of the normalization registered as ``name`` (one line each)."""
    if name not in _REGISTRY:
        raise InputError(f"unknown normalization {name!r}; available: {', '.join(available())}")
    return _REGISTRY[name].describe()


def parameters(name: str) -> dict[str, object]:
    """The parameters of the method registered as ``name`` and their defaults
    (:data:`inspect.Parameter.empty` for one without a default), in the constructor's order."""
    cls = _registered(name)
    if cls.__init__ is object.__init__:
        return {}
    return {
        p.name: p.default
        for p in list(inspect.signature(cls.__init__).parameters.values())[1:]
        if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
    }


def _registered(name: str) -> type[Normalization]:
    try:
        return _REGISTRY[name]
    except KeyError:
        raise InputError(f"unknown normalization {name!r}; available: {', '.join(available())}") from None


def _camel_case(name: str) -> str:
    head, *rest = name.split("_")
    return head + "".join(word.capitalize() for word in rest)


def _accepted_names(params: dict[str, object], accepted: dict[str, object]) -> dict[str, object]:
    """``params`` with each snake_case name the method does not have as the camelCase one it spells."""
    return {
        _camel_case(key) if key not in accepted and _camel_case(key) in accepted else key: value
        for key, value in params.items()
    }


def same_method(spec: str, other: str) -> bool:
    """Whether two specs name the same method with the same parameters, the defaults included:
    ``same_method("clahe", "clahe:clip_limit=2.0")`` and ``same_method("alcn", "alcn:model=gain")`` (defaults that
    the other parameters decide, as :meth:`Normalization.resolved <alcn_cv.enhance.base.Normalization.resolved>`
    resolves them) are True.

    Raises:
        InputError: a bad spec or an unknown name.
    """

    def full(text: str) -> tuple[str, dict[str, object]]:
        name, params = parse_spec(text)
        accepted = parameters(name)
        defaults = {k: v for k, v in accepted.items() if v is not inspect.Parameter.empty}
        return name, _REGISTRY[name].resolved({**defaults, **_accepted_names(params, accepted)})

    return full(spec) == full(other)


def create(spec: str, **params: object) -> Normalization:
    """Create the normalization a name or spec ``NAME[:KEY=VALUE...]`` names, with ``params``.

    ``create("dog", sigma1=1.0)`` and ``create("dog:sigma1=1")`` are the same method; a
    parameter given both in the spec and as a keyword is an error. A snake_case name stands for
    the camelCase parameter it spells (``clip_limit`` for CLAHE's ``clipLimit``).

    Raises:
        InputError: bad spec, unknown name, a parameter the method does not have or given twice,
            or a value of the wrong type or out of range (the message names the method and the
            parameter).

    Example:
        >>> import numpy as np
        >>> clahe = create("clahe:clipLimit=4", tileGridSize=(16, 16))
        >>> clahe.apply(np.zeros((48, 64), np.uint8)).dtype
        dtype('uint8')
    """
    name, spec_params = parse_spec(spec)
    twice = sorted(spec_params.keys() & params.keys())
    if twice:
        raise InputError(
            f"bad parameters for {name!r}: {', '.join(twice)} given in the spec {spec!r} and again on its own "
            "(-p on the command line, a keyword in Python); give each once"
        )
    cls: Callable[..., Normalization] = _registered(name)
    params = _accepted_names({**spec_params, **params}, parameters(name))
    _check_params(name, _REGISTRY[name], params)
    try:
        return cls(**params)
    except ALCNError:
        raise
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"bad parameters for {name!r} ({', '.join(f'{k}={v!r}' for k, v in params.items())}): {exc}"
        ) from None


# What a value must be for the types of an ``__init__`` annotation: numpy scalars count as
# numbers, and a float where an integer is expected is left to the constructor (``size=9.0``).
_ACCEPTED: dict[type, tuple[type, ...]] = {
    float: (numbers.Real,),
    int: (numbers.Real,),
    bool: (bool, numbers.Integral),
    tuple: (tuple, list),
    list: (list, tuple),
}
_TYPE_NAMES = {
    float: "a number",
    int: "an integer",
    bool: "True or False",
    str: "a string",
    type(None): "None",
    Path: "a path",
    tuple: "a tuple",
    list: "a list",
}


def _check_params(name: str, cls: type[Normalization], params: dict[str, object]) -> None:
    """Check parameter names and types against ``cls.__init__``, so that ``-p scale=abc`` says
    which parameter of which method is wrong rather than what ``float()`` thinks of ``'abc'``."""
    no_init = cls.__init__ is object.__init__  # whose signature is (*args, **kwargs)
    signature = inspect.signature(cls.__init__)
    accepted = (
        []
        if no_init
        else [
            p.name
            for p in list(signature.parameters.values())[1:]
            if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
        ]
    )
    if no_init or not any(p.kind == p.VAR_KEYWORD for p in signature.parameters.values()):
        for key in params:
            if key not in accepted:
                raise InputError(
                    f"bad parameters for {name!r}: no parameter {key!r}; "
                    f"its parameters: {', '.join(accepted) or 'none'}"
                )
    try:
        hints = typing.get_type_hints(cls.__init__)
    except (NameError, TypeError):  # an annotation only a type checker can resolve: leave it to the constructor
        return
    for key, value in params.items():
        kinds = _annotation_types(hints.get(key))
        allowed = tuple(t for kind in kinds for t in _ACCEPTED.get(kind, (kind,)))
        if kinds and not isinstance(value, allowed):
            expected = " or ".join(_TYPE_NAMES.get(kind, kind.__name__) for kind in kinds)
            default = signature.parameters[key].default
            example = (
                f", e.g. {format_param(key, default)}" if default is not None and isinstance(default, allowed) else ""
            )
            raise InputError(f"bad parameters for {name!r}: {key}={value!r} must be {expected}{example}")


def _annotation_types(hint: object) -> tuple[type, ...]:
    """The classes an annotation allows (``float | None`` -> ``(float, NoneType)``); empty when it
    cannot be checked with ``isinstance`` (no annotation, ``Any``, a type variable)."""
    if hint is None:
        return ()
    union = typing.get_origin(hint) in (typing.Union, types.UnionType)
    kinds = []
    for arg in typing.get_args(hint) if union else (hint,):
        kind = typing.get_origin(arg) or arg
        if not isinstance(kind, type):
            return ()
        kinds.append(kind)
    return tuple(kinds)


def parse_params(items: list[str]) -> dict[str, object]:
    """``["clipLimit=2", "backend=torch"]`` -> ``{"clipLimit": 2, "backend": "torch"}``.

    Values are Python literals, else strings.
    """
    params: dict[str, object] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.isidentifier():
            raise InputError(f"bad parameter {item!r}; expected NAME=VALUE")
        if key in params:  # as a keyword given twice
            raise InputError(f"parameter {key!r} given twice ({item!r} after {key}={params[key]!r})")
        try:
            params[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            params[key] = value
    return params


#: The ``:`` before each ``KEY=VALUE`` of a spec (not one inside a value: a Windows drive, a path).
_PARAMETER_START = re.compile(r":(?=[A-Za-z_]\w*=)")


def parse_spec(spec: str) -> tuple[str, dict[str, object]]:
    """A method with parameters, ``NAME[:KEY=VALUE...]``: ``"alcn:model=lite:mixture=pyramid"`` ->
    ``("alcn", {"model": "lite", "mixture": "pyramid"})``. The name is not checked here. A ``:`` starts a parameter
    only before ``KEY=``, so a value may hold one: ``"alcn:weights=C:\\models\\a.npz"``."""
    if not isinstance(spec, str):
        raise InputError(f"a method is a string NAME[:KEY=VALUE...] (e.g. 'clahe'), got {type(spec).__name__}")
    name, *items = _PARAMETER_START.split(spec.strip())
    if not name or ":" in name:  # "alcn:lite": a value without its key
        raise InputError(f"bad method {spec!r}; expected NAME[:KEY=VALUE...]")
    return name, parse_params(items)


def format_spec(name: str, params: dict[str, object]) -> str:
    """The spec of a method and its parameters, the inverse of :func:`parse_spec`: ``("dog", {"sigma1": 1.0})`` ->
    ``"dog:sigma1=1.0"``.

    Example:
        >>> format_spec("alcn", {"model": "lite", "scale": 1.0})
        'alcn:model=lite:scale=1.0'
    """
    return name + "".join(f":{k}={v}" for k, v in params.items())


def format_param(key: str, value: object) -> str:
    """One parameter as a spec or ``-p`` takes it, without spaces: ``format_param("tileGridSize", (8, 8))`` ->
    ``"tileGridSize=(8,8)"``."""
    return f"{key}={value!r}".replace(" ", "")


def from_spec(spec: str, **defaults: object) -> Normalization:
    """:func:`create` with ``defaults`` for the parameters the spec does not give, e.g.
    ``from_spec("alcn:model=lite", scale=1.0)``.

    Raises:
        InputError: bad spec, unknown name or parameters.
    """
    name, params = parse_spec(spec)
    return create(name, **{**defaults, **params})


register(NoNormalization)
