"""``alcn bench``: the benchmarks, one sub-subcommand each.

Every module listed in :data:`BENCHMARKS` exposes ``add_cli(subparsers)``, which adds its
sub-subcommand and sets ``func`` to a handler returning an exit code. Adding a benchmark is
adding its module to the tuple.
"""

from __future__ import annotations

import argparse
import importlib

__all__ = ["BENCHMARKS", "add_parser"]

BENCHMARKS = (
    "alcn_cv.bench.detect",
    "alcn_cv.bench.invariance",
    "alcn_cv.bench.speed",
)


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``bench`` subcommand and its sub-subcommands to the ``alcn`` command."""
    parser = subparsers.add_parser(
        "bench",
        help="benchmarks: detection from few images, invariance on real photographs",
        description="Benchmarks comparing ALCN with the classical normalizations (Rad et al. 2017, Sec. 4.3).",
    )
    benches = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK", required=True)
    for name in BENCHMARKS:
        importlib.import_module(name).add_cli(benches)
