"""Shared by the experiment scripts: run `alcn` commands and keep their JSON reports, their ``--part`` option, and
the helpers that more than one experiment uses (the quick protocol's options, the shipped default with another band),
so that no experiment imports another (the rendered stand-in for faces is ``_stand_in.py``).

An experiment writes its whole output under ``runs/<name>/`` (ignored by git), replacing its earlier run's there (the
benchmarks' ``--overwrite``, which their reports' commands leave out: it says nothing of what was measured), and
copies each small JSON report to ``docs/reports/<name>.json`` (tracked), adding an ``experiment`` record (the script,
its arguments and the date, UTC). ``experiments/report.py`` builds ``docs/results.md`` from those
copies alone. A run on another machine (``experiments/gpu_check.sh`` on a GPU machine) writes that copy into its own
output folder (:func:`write_for_keeping`), which ``experiments/keep_gpu_check.py`` publishes (:func:`publish`).
"""

from __future__ import annotations

import argparse
import datetime
import json
import shlex
import sys
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any

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


def add_part_option(parser: argparse.ArgumentParser, parts: Collection[str]) -> None:
    """``--part NAME...`` (``args.part``): run only these of an experiment's ``parts``; :func:`selected_parts` reads
    it."""
    parser.add_argument(
        "--part",
        nargs="+",
        action="extend",
        choices=parts,
        help=f"run only these parts (default: all, in this order: {' '.join(parts)})",
    )


def selected_parts(args: argparse.Namespace, parts: Collection[str]) -> list[str]:
    """The parts ``--part`` selects (:func:`add_part_option`; all without it), each once, in the order of
    ``parts``: ``--part b a a`` runs ``a`` then ``b``."""
    return [part for part in parts if not args.part or part in args.part]


def recorded_settings(args: argparse.Namespace) -> dict[str, object]:
    """An experiment's arguments as its report records them: all but :data:`KEEP` (what to do with the report, not
    what it measures), paths as text."""
    return {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items() if k != KEEP.lstrip("-")}


def _script() -> tuple[str, list[str], bool]:
    """The experiment script (its path in the checkout), its own arguments as typed but :data:`KEEP`, and whether
    :data:`KEEP` was given, from ``sys.orig_argv``, what was typed."""
    argv = getattr(sys, "orig_argv", [])
    main = getattr(sys.modules["__main__"], "__file__", None)
    if main is None:  # an interactive session or `python -c`: no script to record as the report's rerun
        raise SystemExit("a report is kept by the experiment that made it: run it as `python experiments/NAME.py`")
    script = Path(main).resolve()
    args = next((argv[i + 1 :] for i, a in enumerate(argv) if a.endswith(".py") and Path(a).resolve() == script), [])
    return script.relative_to(ROOT).as_posix(), [a for a in args if a != KEEP], KEEP in args


def rerun(script: str, argv: Sequence[str] = ()) -> str:
    """The command line that runs ``script`` (a path in the checkout) with ``argv``: ``bash`` for a shell script,
    ``python`` for the others."""
    return shlex.join(["bash" if script.endswith(".sh") else "python", script, *argv])


def script_command() -> str:
    """The experiment's command line, for a report the script writes itself: ``python SCRIPT ARGS`` (without
    :data:`KEEP`, which says what to do with the report, not what it measures)."""
    script, args, _ = _script()
    return rerun(script, args)


def _what_ran(report: dict[str, Any]) -> object:
    """What a report measured: its commands (the runs' own ``command`` or ``commands``), else the script's
    arguments: two runs of the same commands are the same measurement whatever options led to them."""
    return report.get("commands") or report.get("command") or report.get("experiment", {}).get("argv")


def alcn(*argv: str) -> None:
    """Run ``alcn ARGV...`` in this process; exit with its status if it fails."""
    from alcn_cv.cli import main

    status = main(list(argv))
    if status:
        raise SystemExit(f"alcn {shlex.join(argv)}: exit status {status}")


def _recorded(report: Path, drop: tuple[str, ...], script: str, args: list[str], out: Path | None = None) -> str:
    """The text of the published copy of the JSON ``report``: without its top-level keys ``drop``, with the
    experiment's record (``script``, its ``args``, the date the report was written, UTC); the run's output folder
    ``out`` (default: the runs folder) is written ``OUT`` and the shared data ``../shared/data``, so that no tracked
    file cites the ignored output folder or a machine's paths."""
    out = RUNS if out is None else out
    data = {k: v for k, v in json.loads(report.read_text(encoding="utf-8")).items() if k not in drop}
    written = datetime.datetime.fromtimestamp(report.stat().st_mtime, datetime.UTC)
    data["experiment"] = {"script": script, "argv": args, "date": written.strftime("%Y-%m-%d %H:%M UTC")}
    text = json.dumps(data, indent=1) + "\n"
    for path, alias in (
        (out.resolve(), "OUT"),
        (out, "OUT"),
        (SHARED_DATA.resolve(), "../shared/data"),
        (SHARED_DATA, "../shared/data"),
        (ROOT, "."),
    ):
        text = text.replace(str(path), alias)
    return text


def _publish(text: str, name: str, source: Path, replace: bool) -> Path:
    """Write ``text`` (:func:`_recorded`) to ``docs/reports/<name>.json``, unless a published report of other
    commands is there and not ``replace`` (then say so and return ``source``, the report the text was made from)."""
    target = REPORTS / f"{name}.json"
    if target.is_file() and not replace:
        published = json.loads(target.read_text(encoding="utf-8"))
        current = json.loads(text)
        if _what_ran(published) != _what_ran(current):
            its_run, this_run = (
                rerun(r.get("experiment", {}).get("script", "?"), r.get("experiment", {}).get("argv") or [])
                for r in (published, current)
            )
            # the same script line: the script itself runs other commands now
            why = "the script ran other commands then" if its_run == this_run else "its run"
            print(
                f"not kept: {target.relative_to(ROOT)} is the report of other settings ({why}: `{its_run}`); this "
                f"run's stays at {source} (run this again with {KEEP} to replace the published one)"
            )
            return source
    REPORTS.mkdir(parents=True, exist_ok=True)
    target.write_text(text, encoding="utf-8")
    print(f"kept {target.relative_to(ROOT)}")
    return target


def keep(report: str | Path, name: str, drop: tuple[str, ...] = ()) -> Path:
    """Copy the JSON ``report`` to ``docs/reports/<name>.json`` with the experiment's record (the Python experiment
    that calls this, its arguments, and the date the report was written, UTC), without the top-level keys ``drop``
    (per-frame details: the copy stays small; the whole report stays where the run wrote it); the runs folder is
    written ``OUT`` (:func:`_recorded`).

    A published report is replaced only by a run of the same commands (:func:`_what_ran`), or with :data:`KEEP`: a
    smoke run with other settings leaves it alone (and says so). Returns the published report's path, or
    ``report`` when it was not replaced."""
    report = Path(report)
    script, args, replace = _script()
    return _publish(_recorded(report, drop, script, args), name, report, replace)


def write_for_keeping(report: str | Path, name: str, out: str | Path, script: str) -> Path:
    """For a run on another machine whose output folder ``out`` is all that comes back (``experiments/gpu_check.sh``
    on a GPU machine): ``report`` as :func:`keep` would publish it, recorded as the run of the shell ``script``
    (without arguments: its settings are its environment's, and the command records them), ``out`` written ``OUT``,
    written to ``out/<name>.json``, for :func:`publish` on the machine it came back to."""
    report, out = Path(report), Path(out)
    path = out / f"{name}.json"
    path.write_text(_recorded(report, (), script, [], out), encoding="utf-8")
    print(f"wrote {path}, to publish where it comes back: python experiments/keep_gpu_check.py FOLDER")
    return path


def install_metadata(site: str | Path) -> Path | None:
    """Where alcn-cv is not installed (a bare GPU machine, running the checkout from ``PYTHONPATH``), write its
    metadata into ``site``, a folder on the path: the ``alcn`` command finds its subcommands as entry points of the
    installed distribution (``pyproject.toml``'s), and without them has none. Returns the ``.dist-info`` folder
    written, or None where alcn-cv's commands are found already."""
    import tomllib
    from importlib import metadata

    from alcn_cv import __version__ as version

    if metadata.entry_points(group="alcn_cv.commands"):
        return None
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    groups = {"console_scripts": project["scripts"], **project["entry-points"]}
    dist = Path(site) / f"{project['name'].replace('-', '_')}-{version}.dist-info"
    dist.mkdir(parents=True, exist_ok=True)
    (dist / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: {project['name']}\nVersion: {version}\n", encoding="utf-8"
    )
    entries = [
        f"[{group}]\n" + "".join(f"{name} = {target}\n" for name, target in items.items())
        for group, items in groups.items()
    ]
    (dist / "entry_points.txt").write_text("\n".join(entries), encoding="utf-8")
    return dist


def publish(path: str | Path, replace: bool = False) -> Path:
    """Copy a report :func:`write_for_keeping` wrote (``<name>.json``, its record made where it ran) to
    ``docs/reports/<name>.json``: only over a published report of the same commands, or with ``replace``
    (:func:`keep`'s rule). Returns the published report's path, or ``path`` when it was not replaced."""
    path = Path(path)
    return _publish(path.read_text(encoding="utf-8"), path.stem, path, replace)


def quick_protocol() -> list[str]:
    """The options of ``alcn bench relight``'s quick protocol (its preset,
    ``alcn_cv.bench.relight_settings.CONFS["quick"]``) spelled out: the kept reports' commands record them so
    (``--conf quick`` would be another command for the same settings, which :func:`keep` would not let replace
    them)."""
    from alcn_cv.bench.relight_settings import CONFS

    return CONFS["quick"].options()


def short_relight(out: Path, methods: list[str], seeds: Sequence[int] = (0,), options: Sequence[str] = ()) -> None:
    """An experiment's short ``alcn bench relight`` run of ``methods`` into ``out`` (replacing an earlier one): the
    quick protocol (:func:`quick_protocol`), ``seeds`` (seed 0 alone by default), no tuning, and the bench's
    ``options`` (``--leave-one-out``, say)."""
    alcn(
        "bench",
        "relight",
        "--out",
        str(out),
        "--overwrite",
        "--methods",
        ",".join(methods),
        "--seeds",
        *(str(seed) for seed in seeds),
        *quick_protocol(),
        "--no-tune",
        *options,
    )


def untrained_start(trained: str | Path, path: str | Path, description: str, **net_args: Any) -> Path:
    """The untrained start of a trained gain weight file: the network its recipe builds (the same arguments and
    seed, but ``net_args``, which replace the recipe's) before any step, saved to ``path``."""
    from alcn_cv.train.real_light import initial_network
    from alcn_cv.weight_file import load_normalizer_file, save_normalizer_file

    config = load_normalizer_file(trained).meta["training"]["config"]
    net = initial_network(config["seed"], {**config["net"], **net_args})
    return save_normalizer_file(path, net.state_arrays(), net.file_meta(trained=False, description=description))


def band_variant(weight: float, path: Path) -> str:
    """The spec of the shipped default with the wide band's ``weight`` (0: none) instead of its own, saved to
    ``path`` with the shipped file's description and training record."""
    from alcn_cv.nets.gain import GainNormalizer
    from alcn_cv.runtime import MODELS
    from alcn_cv.weight_file import NormalizerFile, load_normalizer_file, save_normalizer_file

    shipped = load_normalizer_file(MODELS["gain"])
    # the band is a setting of the network (it has no parameters): the shipped arrays fit a network with another
    config = {**shipped.meta["config"], "band": weight}
    net = GainNormalizer.from_file(NormalizerFile(shipped.arrays, {**shipped.meta, "config": config}))
    provenance = {key: shipped.meta[key] for key in ("description", "training") if key in shipped.meta}
    meta = net.file_meta(trained=shipped.meta["trained"], **provenance)
    save_normalizer_file(path, net.state_arrays(), meta)
    return f"alcn:weights={path}"
