"""Shared by the experiment scripts: run `alcn` commands and keep their JSON reports.

An experiment writes its whole output under ``runs/<name>/`` (ignored by git) and copies each small
JSON report to ``docs/reports/<name>.json`` (tracked), adding an ``experiment`` record (the script,
its arguments and the date, UTC). ``experiments/report.py`` builds ``docs/results.md`` from those
copies alone.
"""

from __future__ import annotations

import argparse
import datetime
import json
import shlex
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RUNS = ROOT / "runs"
REPORTS = ROOT / "docs" / "reports"

sys.path.insert(0, str(ROOT))  # the checkout's packages, also when not installed

from alcn_cv.shared_data import shared_data_dir  # noqa: E402

#: The real photographs (``../shared/data`` beside the checkout, or ``ALCN_SHARED_DATA``).
SHARED_DATA = shared_data_dir()


#: The option that lets a run with other arguments than the published one's replace its report.
KEEP = "--keep"


def command_line(doc: str, keeps: bool = True) -> argparse.ArgumentParser:
    """An experiment's command line, its whole docstring as the help: what it runs, what it writes and where;
    for a script that ``keeps`` a report, :data:`KEEP` (no abbreviations, so that :func:`keep` can find it)."""
    parser = argparse.ArgumentParser(
        description=doc, formatter_class=argparse.RawDescriptionHelpFormatter, allow_abbrev=False
    )
    if not keeps:
        return parser
    parser.add_argument(
        KEEP,
        action="store_true",
        help="replace the published report in docs/reports even when this run's arguments differ from those it "
        "records (without it, only a run with the same arguments replaces it)",
    )
    return parser


def _script() -> tuple[str, list[str], bool]:
    """The experiment script (its path in the checkout), its own arguments as typed but :data:`KEEP`, and whether
    :data:`KEEP` was given (``sys.argv`` is the last ``alcn`` command's)."""
    argv = getattr(sys, "orig_argv", [])
    script = Path(sys.modules["__main__"].__file__).resolve()
    args = next((argv[i + 1 :] for i, a in enumerate(argv) if a.endswith(".py") and Path(a).resolve() == script), [])
    return script.relative_to(ROOT).as_posix(), [a for a in args if a != KEEP], KEEP in args


def script_command() -> str:
    """The experiment's command line, for a report the script writes itself: ``python SCRIPT ARGS`` (without
    :data:`KEEP`, which says what to do with the report, not what it measures)."""
    script, args, _ = _script()
    return shlex.join(["python", script, *args])


def _what_ran(report: dict) -> object:
    """What a report measured: its commands (the runs' own ``command`` or ``commands``), else the script's
    arguments: two runs of the same commands are the same measurement whatever options led to them."""
    return report.get("commands") or report.get("command") or report.get("experiment", {}).get("argv")


def alcn(*argv: str) -> None:
    """Run ``alcn ARGV...`` in this process; exit with its status if it fails."""
    from alcn_cv.cli import main

    sys.argv = ["alcn", *argv]  # the reports record sys.argv as their command
    status = main(list(argv))
    if status:
        raise SystemExit(f"alcn {shlex.join(argv)}: exit status {status}")


def keep(report: Path, name: str, drop: tuple[str, ...] = ()) -> Path:
    """Copy the JSON ``report`` to ``docs/reports/<name>.json`` with the experiment's record (the script,
    its arguments, and the date the report was written, UTC), without the top-level keys ``drop``
    (per-frame details: the copy stays small; the whole report stays where the run wrote it). The run's
    output folder is written ``OUT`` and the shared data ``../shared/data``, so that no tracked file
    cites the ignored output folder or a machine's paths.

    A published report is replaced only by a run of the same commands (:func:`_what_ran`), or with :data:`KEEP`: a
    smoke run with other settings leaves it alone (and says so). Returns the published report's path, or
    ``report`` when it was not replaced."""
    report = Path(report)
    target = REPORTS / f"{name}.json"
    script, args, replace = _script()
    data = {k: v for k, v in json.loads(report.read_text(encoding="utf-8")).items() if k not in drop}
    written = datetime.datetime.fromtimestamp(report.stat().st_mtime, datetime.UTC)
    data["experiment"] = {
        "script": script,
        "argv": args,
        "date": written.strftime("%Y-%m-%d %H:%M UTC"),
    }
    text = json.dumps(data, indent=1) + "\n"
    for path, alias in (
        (RUNS, "OUT"),
        (SHARED_DATA.resolve(), "../shared/data"),
        (SHARED_DATA, "../shared/data"),
        (ROOT, "."),
    ):
        text = text.replace(str(path), alias)
    if target.is_file() and not replace:
        published = json.loads(target.read_text(encoding="utf-8"))
        if _what_ran(published) != _what_ran(json.loads(text)):
            argv = published.get("experiment", {}).get("argv") or []
            print(
                f"not kept: {target.relative_to(ROOT)} is the report of other settings (its run: "
                f"`{shlex.join(['python', published.get('experiment', {}).get('script', '?'), *argv])}`); "
                f"this run's stays at {report} ({KEEP} replaces the published one)"
            )
            return report
    REPORTS.mkdir(parents=True, exist_ok=True)
    target.write_text(text, encoding="utf-8")
    print(f"kept {target.relative_to(ROOT)}")
    return target


def untrained_start(trained: str | Path, path: str | Path, description: str) -> Path:
    """The untrained start of a trained gain weight file: the network its recipe builds (the same arguments and
    seed) before any step, saved to ``path``."""
    import torch

    from alcn_cv.nets.gain import GainNormalizer
    from alcn_cv.weight_file import load_normalizer_file, save_normalizer_file

    config = load_normalizer_file(trained).meta["training"]["config"]
    torch.manual_seed(config["seed"])
    net = GainNormalizer(**config["net"])
    return save_normalizer_file(path, net.state_arrays(), net.file_meta(trained=False, description=description))
