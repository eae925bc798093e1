"""The ``alcn`` command: one subcommand per pipeline stage.

The subcommands are the entry points of the group ``alcn_cv.commands`` (declared in
``pyproject.toml``, discovered with :func:`importlib.metadata.entry_points`, listed by name):
each names an ``add_parser(subparsers)`` function, which adds its subcommand and sets
``func`` (called with the parsed ``argparse.Namespace``) as the default. A subcommand whose
module needs an extra that is not installed is still listed; running it prints the one line
that names the extra. Errors from bad input end the command with a one-line message and exit
code 2; ``--debug`` prints the traceback before that line. OpenCV logs errors only (its warnings would come before
that line) unless ``--debug`` or ``--verbose`` is given, FFmpeg fatal errors only unless ``--verbose`` is. SIGTERM
(``timeout``, a job scheduler) ends a command as Ctrl-C does, with exit code 143: temporary files and folders are
removed. The command's process keeps the memory a frame frees for the next one
(:func:`alcn_cv.malloc.keep_freed_memory`, on glibc).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import logging
import math
import os
import re
import signal
import sys
import textwrap
import traceback
from collections.abc import Callable, Iterator, Mapping, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

from alcn_cv.errors import ALCNError, InputError, MissingDependencyError
from alcn_cv.extras import DISTRIBUTION, is_installed, missing_extra, require
from alcn_cv.malloc import keep_freed_memory

logger = logging.getLogger("alcn_cv")

#: The entry-point group of the subcommands.
COMMANDS_GROUP = "alcn_cv.commands"
#: FFmpeg's log level for fatal errors only (AV_LOG_FATAL), OpenCV's ``OPENCV_FFMPEG_LOGLEVEL`` without --verbose.
FFMPEG_FATAL = 8
#: OpenCV's log level for errors only (``cv::utils::logging::LOG_LEVEL_ERROR``, the same in OpenCV 4 and 5).
OPENCV_LOG_ERROR = 2


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program is, so that it unwinds as on Ctrl-C (files cleaned up)."""


def _terminate(signum: int, frame: object) -> None:
    raise Terminated


def interrupt_exit_code(interrupt: BaseException | None) -> int:
    """The exit code of a command that an interrupt ended: 143 (128 + SIGTERM) for :class:`Terminated`, else 130
    (128 + SIGINT, Ctrl-C)."""
    return 128 + (signal.SIGTERM if isinstance(interrupt, Terminated) else signal.SIGINT)


@contextlib.contextmanager
def sigterm_as_interrupt(command: str) -> Iterator[None]:
    """Handle SIGTERM as SIGINT while ``alcn command`` runs: :class:`Terminated` is raised.

    The commands of the packages on top of alcn_cv may import pycolmap, whose glog installs a
    failure handler for SIGTERM (a C++ stack trace, no cleanup): it is imported first, so that the
    handler set here replaces glog's.
    """
    on_top = any(e.name == command and e.module.split(".")[0] != __package__ for e in command_entry_points())
    if on_top and is_installed("pycolmap"):
        import pycolmap  # noqa: F401

    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _add_unavailable(
    subparsers: argparse._SubParsersAction, name: str, why: str, message: str, cause: Exception
) -> None:
    """List ``name``, whose module cannot be imported here (``why``, its help); running it prints ``message`` (after
    the traceback of ``cause`` with ``--debug``) and returns 2."""

    def fail(args: argparse.Namespace) -> int:
        if args.debug:
            traceback.print_exception(cause)
        print(message, file=sys.stderr)
        return 2

    parser = subparsers.add_parser(name, help=f"({why})", description=message)  # --help: the message
    parser.add_argument("arguments", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    parser.set_defaults(func=fail)


def command_entry_points() -> list[metadata.EntryPoint]:
    """The subcommands' entry points (installed metadata), by name."""
    return sorted(metadata.entry_points(group=COMMANDS_GROUP), key=lambda entry: entry.name)


def _hiding_modules() -> list[str]:
    """Each top-level package of alcn-cv's commands that Python finds outside its own folder of alcn-cv's
    installation (a module of an app, or another distribution's package of that name, earlier on the path), as
    ``"NAME at PATH"``."""
    home = Path(__file__).resolve().parents[1]  # where alcn-cv's packages are installed (or checked out)
    hiding = []
    for package in sorted({entry.module.split(".")[0] for entry in command_entry_points()}):
        spec = importlib.util.find_spec(package) if is_installed(package) else None
        if spec is not None and spec.origin and not Path(spec.origin).resolve().is_relative_to(home / package):
            hiding.append(f"{package} at {spec.origin}")
    return hiding


def _add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Each command's parser; one whose module cannot be imported is listed with the reason, and the others run."""
    for entry in command_entry_points():
        try:
            entry.load()(subparsers)  # a command's add_parser imports its settings' modules first
        except ImportError as exc:
            if entry.name in subparsers.choices:  # failed after listing itself: a bug of its parser
                raise
            package = entry.module.split(".")[0]
            if not is_installed(package):  # its own package is not in this build
                logger.debug("alcn %s: %s is not installed", entry.name, package)
                continue
            if isinstance(exc, ModuleNotFoundError) and (error := missing_extra(exc, f"alcn {entry.name}", entry.name)):
                _add_unavailable(
                    subparsers, entry.name, f"needs the [{error.extra}] extra, not installed", str(error), exc
                )
                continue
            # the packages on top of alcn_cv are top-level ones: a module of the same name earlier on the path (an
            # app's own module) hides them, and the other commands still run; any other import error is a bug
            hiding = _hiding_modules()
            if not hiding:
                raise
            message = (
                f"alcn {entry.name}: cannot import {entry.module} ({exc}): {', '.join(hiding)} hides alcn-cv's "
                "(alcn --debug shows the traceback)"
            )
            _add_unavailable(subparsers, entry.name, "cannot be imported here", message, exc)


class _CommandParser(argparse.ArgumentParser):
    """The ``alcn`` parser: its namespace also holds the words it parsed, ``args.argv`` (those after ``alcn``), the
    command a report records (:func:`alcn_cv.report.typed_command`), whoever parses them: :func:`main`, or an
    experiment or a test calling it in a process of its own ``sys.argv``."""

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        parsed, unknown = super().parse_known_args(args, namespace)
        parsed.argv = list(sys.argv[1:] if args is None else args)
        return parsed, unknown


def _versions() -> str:
    """``alcn --version``: alcn-cv's, and those of OpenCV and NumPy it runs with (and torch's, where installed)."""
    import cv2
    import numpy

    try:  # the installed distribution's (the package imports this module: no import of it here)
        ours = metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        ours = "(not installed)"
    versions = f"alcn-cv {ours} (OpenCV {cv2.__version__}, NumPy {numpy.__version__}"
    if is_installed("torch"):
        versions += f", torch {metadata.version('torch')}"
    return versions + ")"


class _VersionAction(argparse.Action):
    """``--version``: :func:`_versions`, read only when asked (their lookups would cost every command's start)."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: Any) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, *args: object) -> None:
        print(_versions())
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    parser = _CommandParser(
        prog="alcn",
        description="Adaptive Local Contrast Normalization (ALCN) and its tools: normalize images and "
        "videos, generate data, train, benchmark, calibrate and estimate box poses.",
    )
    parser.add_argument(
        "--version", action=_VersionAction, help="show the versions of alcn-cv, OpenCV, NumPy (and torch) and exit"
    )
    parser.add_argument("--debug", action="store_true", help="print full tracebacks on errors, and OpenCV's warnings")
    parser.add_argument(
        "--import",
        dest="imports",
        action="append",
        default=[],
        metavar="MODULE",
        help="import MODULE (a module name, or a .py file) before the command, repeatable: a module that registers "
        "normalizations of its own (alcn_cv.register) makes them methods of every command, e.g. `alcn --import "
        "my_methods.py bench relight --methods none,mine,alcn`; a report's command records it",
    )
    parser.add_argument(
        "-v", "--verbose", action="store_true", help="log debug messages, and OpenCV's and FFmpeg's warnings"
    )
    subparsers = parser.add_subparsers(
        dest="command", metavar="COMMAND", required=True, parser_class=argparse.ArgumentParser
    )
    _add_commands(subparsers)
    return parser


class _PresetListFormatter(argparse.HelpFormatter):
    """argparse's help formatter, but each line of a description or an epilog is filled alone: the epilog of
    :func:`add_conf_option` keeps one line per preset, a longer one wrapped under its summary (an indented line's
    second column)."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        lines = []
        for line in text.splitlines():
            columns = re.match(r"\s+\S+\s+", line)
            hang = indent + " " * len(columns.group()) if columns else indent
            lines.append(
                textwrap.fill(line, width, initial_indent=indent, subsequent_indent=hang, break_on_hyphens=False)
            )
        return "\n".join(lines)


def add_conf_option(
    parser: argparse.ArgumentParser,
    summaries: Mapping[str, str],
    default: str | None = "default",
    *,
    required: bool = False,
    example: str | None = None,
    or_file: str | None = None,
) -> None:
    """``--conf NAME`` (``args.conf``), the one way every command takes a named preset.

    Args:
        parser: the command's parser; its epilog becomes the list of the presets, one line each, a longer one
            wrapped under its summary.
        summaries: the presets' names, each with what the preset is (the stage's ``CONF_SUMMARIES``), in order.
        default: the preset without ``--conf``; None: no preset unless given (or ``--conf`` is ``required``).
        required: ``--conf`` must be given (a command without a default preset).
        example: a ``KEY=VALUE`` of the presets' keys: the command also takes ``--set KEY=VALUE``
            (``args.settings``, a list, in order), the overrides of the preset's keys
            (:func:`alcn_cv.presets.with_settings`), and ``--print-config`` (``args.print_config``: the command
            prints the preset with them, :func:`alcn_cv.presets.print_config`, and exits); None: only the command's
            other options override its values.
        or_file: what else ``--conf`` takes, a file (``alcn train``: a TOML file of its keys), said in its help.

    The name is not checked here: the command looks it up (:func:`alcn_cv.presets.preset` or
    :func:`~alcn_cv.presets.preset_named`), whose error for an unknown name, ``unknown preset 'huge'; choose one of
    a, b, c``, :func:`main` prints on one line with exit code 2, the same from every command and from Python.
    """
    also = f", or {or_file}" if or_file else ""
    given = "required" if required else f"default: {default or 'none'}"
    parser.add_argument(
        "--conf",
        default=default,
        required=required,
        metavar="NAME",
        help=f"the preset, one of those listed below{also} ({given}); the options given override its values",
    )
    if example:
        parser.add_argument(
            "--set",
            action="append",
            default=[],
            metavar="KEY=VALUE",
            dest="settings",
            help=f"override one key of the preset, dotted, the value as TOML, e.g. --set {example} (repeatable)",
        )
        parser.add_argument(
            "--print-config",
            action="store_true",
            help="print the configuration of --conf (a preset, or a file where the command takes one) with --set and "
            "the other options given applied, every key, and exit",
        )
    width = max(map(len, summaries))
    rows = [f"  {name:<{width}}  {what}" for name, what in summaries.items()]
    parser.epilog = "\n".join(["presets (--conf NAME):", *rows])
    parser.formatter_class = _PresetListFormatter


def preset_values(confs: Mapping[str, object], field: str) -> str:
    """The value of ``field`` in each preset of ``confs``, for an option's help: ``"default 120, small 4"``."""
    return ", ".join(f"{name} {getattr(conf, field)}" for name, conf in confs.items())


class _Seeds(argparse.Action):
    """``--seeds 0 1 2``, each item also split on commas (``--seeds 0,1,2``, the form of older recorded commands)."""

    def __call__(
        self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any, option: str | None = None
    ) -> None:
        seeds = []
        for text in (v for item in values for v in item.split(",") if v.strip()):
            try:
                seeds.append(int(text))
            except ValueError:
                # argparse's own error line: an InputError raised while parsing would end in a traceback
                raise argparse.ArgumentError(
                    self, f"a seed is an integer (e.g. --seeds 0 1 2 or 0,1,2), got {text!r}"
                ) from None
        setattr(namespace, self.dest, seeds)


def add_seeds_option(
    parser: argparse.ArgumentParser, default: Sequence[int], what: str, from_preset: bool = False
) -> None:
    """``--seeds 0 1 2`` (``args.seeds``, a list of integers), the one way every command that repeats its runs takes
    their seeds; ``what`` says what a seed draws (``from_preset``: the parsed default is None, the preset's
    ``default`` applies)."""
    parser.add_argument(
        "--seeds",
        nargs="+",
        action=_Seeds,
        metavar="SEED",
        default=None if from_preset else list(default),
        help=f"{what}; cells give the mean ± standard deviation over the seeds, e.g. --seeds 0 1 2 (0,1,2 also "
        f"accepted; default {' '.join(map(str, default))})",
    )


def _shown(bound: float) -> str:
    """A bound as a message shows it: an integer in full, a float in its shortest form."""
    return str(bound) if isinstance(bound, int) else f"{bound:g}"


def number_in(
    kind: type[int] | type[float], low: float, high: float | None = None, *, above: bool = False, below: bool = False
) -> Callable[[str], int | float]:
    """An argparse ``type`` for a number of ``kind`` from ``low`` to ``high`` (greater than ``low`` with ``above``,
    less than ``high`` with ``below``; no upper bound when ``high`` is None, but an integer must fit an index,
    ``sys.maxsize``): a value out of range is an error that names its option and its bounds, as a Python caller's
    names the keyword.

    Example:
        >>> number_in(float, 0, 1, above=True)("0.5")
        0.5
    """
    lower = f"{'greater than' if above else 'at least'} {_shown(low)}"
    top = sys.maxsize if high is None and kind is int else high
    upper = "" if top is None else f" and {'less than' if below else 'at most'} {_shown(top)}"
    what = f"{'an integer' if kind is int else 'a number'} {lower}"

    def parse(text: str) -> int | float:
        try:
            value = kind(text)
        except ValueError:
            value = None
        # `not >=`: NaN compares false with everything and is no number in range; inf is no size, rate or time either
        if value is None or not (value > low if above else value >= low) or not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{what}{'' if high is None else upper}, got {text!r}")
        if top is not None and not (value < top if below else value <= top):
            raise argparse.ArgumentTypeError(f"{what}{upper}, got {text!r}")
        return value

    return parse


def number_at_least(kind: type[int] | type[float], low: float, above: bool = False) -> Callable[[str], int | float]:
    """:func:`number_in` without an upper bound: a number of ``kind`` at least ``low`` (greater than ``low`` with
    ``above``)."""
    return number_in(kind, low, above=above)


#: The argparse ``type`` of every ``--seed`` and ``--object-seed``: numpy's generators take no negative seed, and
#: their error names no option.
SEED = number_at_least(int, 0)
#: The argparse ``type`` of a count: an integer at least 1 (runs, windows, frames, epochs, threads).
COUNT = number_at_least(int, 1)


def all_or_at_least(low: int) -> Callable[[str], int | float]:
    """An argparse ``type``: 0 (all) or an integer at least ``low`` (:func:`number_in`'s bounds otherwise)."""
    at_least = number_in(int, low)

    def parse(text: str) -> int | float:
        try:
            return 0 if text.strip() == "0" else at_least(text)
        except argparse.ArgumentTypeError:
            raise argparse.ArgumentTypeError(f"0 (all) or an integer at least {low}, got {text!r}") from None

    return parse


def add_progress_option(parser: argparse.ArgumentParser) -> None:
    """``--no-progress`` (``args.no_progress``): the one switch of a subcommand's progress bars."""
    parser.add_argument("--no-progress", action="store_true", help="no progress bars (for logs and scripts)")


@contextlib.contextmanager
def ffmpeg_fatal_only(quiet: bool = True) -> Iterator[None]:
    """With ``quiet``, OpenCV's FFmpeg logs fatal errors only while the block runs (``OPENCV_FFMPEG_LOGLEVEL``, read
    as each video opens), unless the caller set a level: its decoder reports recoverable stream errors (a slice type
    it tolerates) between the progress bars, and a truncated or unreadable video is checked by the frames it gives
    (:mod:`alcn_cv.io`)."""
    if not quiet or "OPENCV_FFMPEG_LOGLEVEL" in os.environ:
        yield
        return
    os.environ["OPENCV_FFMPEG_LOGLEVEL"] = str(FFMPEG_FATAL)
    try:
        yield
    finally:
        os.environ.pop("OPENCV_FFMPEG_LOGLEVEL", None)


def _opencv_log_setter() -> Callable[[int], int] | None:
    """OpenCV's ``setLogLevel`` (it returns the previous level): ``cv2.utils.logging``'s in OpenCV 5, ``cv2``'s in
    OpenCV 4; None in a build that has neither."""
    import cv2

    logging_module = getattr(getattr(cv2, "utils", None), "logging", None)
    return getattr(logging_module, "setLogLevel", None) or getattr(cv2, "setLogLevel", None)


@contextlib.contextmanager
def opencv_errors_only(quiet: bool = True) -> Iterator[None]:
    """With ``quiet``, OpenCV logs errors only while the block runs, unless the caller set ``OPENCV_LOG_LEVEL``: its
    warnings (``[ WARN:0@0.99] global grfmt_png.cpp:793 ... PNG input buffer is incomplete``) would come before the
    command's own line about the same file. The command line's alone: importing the library leaves OpenCV's level
    as it is."""
    set_level = _opencv_log_setter() if quiet and "OPENCV_LOG_LEVEL" not in os.environ else None
    if set_level is None:
        yield
        return
    previous = set_level(OPENCV_LOG_ERROR)
    try:
        yield
    finally:
        set_level(previous)


def _command_parser(parser: argparse.ArgumentParser, args: argparse.Namespace) -> argparse.ArgumentParser:
    """The parser of the (sub)command ``args`` were parsed for: ``alcn bench detect``'s, not ``alcn``'s."""
    while True:
        # argparse keeps its subcommands as an action of the parser (no public accessor)
        action = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
        name = None if action is None else getattr(args, action.dest, None)
        if action is None or name not in action.choices:
            return parser
        parser = action.choices[name]


def main(argv: list[str] | None = None) -> int:
    if isinstance(sys.stdout, io.TextIOWrapper):  # a console or file in a legacy code page (Windows' cp1252): a
        sys.stdout.reconfigure(errors="backslashreplace")  # report's character it lacks is escaped, not fatal
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    command = _command_parser(parser, args)
    if unknown:  # argparse reports them from the top-level parser, naming neither the command nor its usage
        top_level = {o for a in parser._actions for o in a.option_strings if a.dest != "help"}
        misplaced = sorted(top_level & set(unknown))
        where = f" ({', '.join(misplaced)}: before the command, `alcn {misplaced[0]} COMMAND ...`)" if misplaced else ""
        command.error(f"unrecognized arguments: {' '.join(unknown)}{where}")
    prog = command.prog  # "alcn bench detect": the errors below name the command, as argparse's own do
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="[%(asctime)s %(name)s %(levelname)s] %(message)s",
        datefmt="%Y/%m/%d %H:%M:%S",
    )
    keep_freed_memory()
    try:
        quiet = not (args.verbose or args.debug)
        with sigterm_as_interrupt(args.command), ffmpeg_fatal_only(not args.verbose), opencv_errors_only(quiet):
            for module in args.imports:
                import_module(module)
            # the packages a command declares (``set_defaults(needs=...)``), every missing one's extra named at once
            require(*getattr(args, "needs", ()), what=prog, preferred=args.command)
            result = args.func(args)
    except KeyboardInterrupt as exc:
        print(f"alcn: {'terminated' if isinstance(exc, Terminated) else 'interrupted'}", file=sys.stderr)
        return interrupt_exit_code(exc)
    except ModuleNotFoundError as exc:  # a package of an extra, imported when the command runs
        error = missing_extra(exc, prog, preferred=args.command)
        if error is None:
            raise
        return _failed(str(error), args.debug)
    except MissingDependencyError as exc:  # a package checked before the work; the message names the command
        named = str(exc).startswith(f"alcn {args.command}")  # else a function's name (ALCN(backend='torch'): ...)
        return _failed(str(exc) if named else f"{prog}: {exc}", args.debug)
    except (ValueError, TypeError, OSError, RuntimeError) as exc:
        return _failed(f"{prog}: error: {exc}", args.debug)
    except MemoryError as exc:  # NumPy's says how much, for what shape: the input (or a size asked) too large
        return _failed(f"{prog}: error: out of memory ({exc or 'no details'})", args.debug)
    return int(result or 0)


def import_module(module: str) -> None:
    """Import ``module``, a module's name or a ``.py`` file's path (``alcn --import``), as a program importing it
    would: a file is imported under its own name, its folder first on the path (for the modules beside it).

    Raises:
        InputError: the module or the file is not found (a failure inside the module propagates as it is).
    """
    path = Path(module).expanduser()
    if module.endswith(".py") or os.sep in module:
        if not path.is_file():
            raise InputError(f"--import {module}: no such file")
        # a module of that name imported already (the standard library's, alcn-cv's own, another --import) would be
        # taken for the file, which would never run
        held = getattr(sys.modules.get(path.stem), "__file__", None)
        if held is not None and Path(held).resolve() != path.resolve():
            raise InputError(
                f"--import {module}: a module named {path.stem!r} is imported already ({held}): rename the file"
            )
        sys.path.insert(0, str(path.resolve().parent))
        module = path.stem
    try:
        importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name != module:  # a module that the imported one needs: its own error, as it is
            raise
        raise InputError(
            f"--import {module}: no module named {module!r} (give a .py file's path, or set PYTHONPATH)"
        ) from None


def run_script(main: Callable[[], object]) -> None:
    """Run a script's ``main`` (``examples/``) as ``alcn`` runs a subcommand: FFmpeg and OpenCV print errors only
    (:func:`ffmpeg_fatal_only`, :func:`opencv_errors_only`; a caller's levels are kept), and bad input
    (:class:`~alcn_cv.errors.ALCNError`, or an ``OSError``: a file that cannot be read or written) ends the process
    with its one line, ``SCRIPT: error: ...``, and exit code 2."""
    try:
        with ffmpeg_fatal_only(), opencv_errors_only():
            main()
    except (ALCNError, OSError) as exc:
        sys.exit(_failed(f"{os.path.basename(sys.argv[0])}: error: {exc}", debug=False))


#: The file names of the ``alcn`` command's script: pip's console script, and on Windows its launcher and script.
SCRIPT_NAMES = frozenset({"alcn", "alcn.exe", "alcn-script.py"})


def exit_in_the_command(error: MissingDependencyError) -> None:
    """In the ``alcn`` command, end the process as a missing extra ends it: ``error``'s one line (after its traceback
    with ``--debug``) and exit code 2; elsewhere return. ``import alcn_cv`` calls it, while it handles ``error``,
    when OpenCV is missing or too old: the command's script imports the package before :func:`main` runs, and a
    program that imports the package gets the error raised. The command is told by its script's name (``sys.argv[0]``)
    or, for ``python -m alcn_cv.cli`` (whose ``sys.argv[0]`` is ``-m`` while the package is imported), by the
    interpreter's own arguments (``sys.orig_argv``)."""
    argv = getattr(sys, "argv", None) or [""]
    orig = getattr(sys, "orig_argv", [])
    as_module = any(a == "-m" and b == __name__ for a, b in zip(orig, orig[1:]))
    if os.path.basename(argv[0]) in SCRIPT_NAMES or as_module:
        sys.exit(_failed(str(error), "--debug" in argv[1:]))


def _failed(message: str, debug: bool) -> int:
    """Print the error's one line (after its traceback with ``--debug``) and return exit code 2; called while
    the exception is handled."""
    if debug:
        traceback.print_exc()
    print(message, file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
