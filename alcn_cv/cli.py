"""The ``alcn`` command: one subcommand per pipeline stage.

Each stage module exposes ``add_parser(subparsers)``, which adds its subcommand and
sets ``func`` (called with the parsed ``argparse.Namespace``) as the default.
Errors from bad input end the command with a one-line message and exit code 2; a
traceback is printed only with ``--debug``.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

logger = logging.getLogger("alcn_cv")

# Modules that contribute subcommands, in the order ``alcn --help`` lists them.
_STAGES = (
    "alcn_cv.commands.normalize",
    "alcn_cv.commands.demo",
    "alcn_cv.data.cli",
    "alcn_cv.train.cli",
    "alcn_cv.bench.cli",
    "pose.cli",
    "calib.cli",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="alcn",
        description="Adaptive Local Contrast Normalization (ALCN) and its tools: normalize images and "
        "videos, generate data, train, benchmark, calibrate and estimate box poses.",
    )
    parser.add_argument("--debug", action="store_true", help="print full tracebacks on errors")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in _STAGES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:  # a stage not installed in this build
            if exc.name != name:
                raise
            continue
        module.add_parser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="[%(asctime)s %(name)s %(levelname)s] %(message)s",
        datefmt="%Y/%m/%d %H:%M:%S",
    )
    try:
        result = args.func(args)
    except KeyboardInterrupt:
        print("alcn: interrupted", file=sys.stderr)
        return 130
    except (ValueError, TypeError, OSError, RuntimeError) as exc:
        if args.debug:
            raise
        print(f"alcn {args.command}: error: {exc}", file=sys.stderr)
        return 2
    return int(result or 0)


if __name__ == "__main__":
    sys.exit(main())
