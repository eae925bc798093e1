"""The methods a benchmark compares, built from their specs before any work."""

from __future__ import annotations

from collections.abc import Callable, Sequence

from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import from_spec
from alcn_cv.errors import InputError, WeightFileError

__all__ = ["build_methods"]


def build_methods(
    methods: Sequence[str], build: Callable[[str], Normalization] = from_spec
) -> dict[str, Normalization]:
    """Every method of a benchmark, built by ``build`` from its spec (its weight file loaded) before any work: a spec
    listed twice, a bad parameter or weight file ends the command with one line naming the method, not with a failed
    run found after the long work.

    Returns:
        The built methods by spec, in the order of ``methods``.

    Raises:
        InputError: a method listed twice or that cannot be built; the message names its spec.
    """
    twice = [spec for i, spec in enumerate(methods) if spec in methods[:i]]
    if twice:
        raise InputError(f"method {twice[0]!r} is listed twice")
    norms = {}
    for spec in methods:
        try:
            norms[spec] = build(spec)
        except (InputError, WeightFileError) as exc:
            raise InputError(f"method {spec!r}: {exc}") from None
    return norms
