"""Shared by the experiment scripts: run `alcn` commands and keep their JSON reports, and the helpers that more than
one experiment uses (the quick protocol's options, the shipped default with another band, the rendered stand-in for
faces), so that no experiment imports another.

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
from typing import Any

import cv2
import numpy as np
from tqdm.auto import tqdm

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


def recorded_settings(args: argparse.Namespace) -> dict[str, object]:
    """An experiment's arguments as its report records them: all but :data:`KEEP` (what to do with the report, not
    what it measures), paths as text."""
    return {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items() if k != KEEP.lstrip("-")}


def _script() -> tuple[str, list[str], bool]:
    """The experiment script (its path in the checkout), its own arguments as typed but :data:`KEEP`, and whether
    :data:`KEEP` was given (``sys.argv`` is the last ``alcn`` command's)."""
    argv = getattr(sys, "orig_argv", [])
    main = getattr(sys.modules["__main__"], "__file__", None)
    if main is None:  # an interactive session or `python -c`: no script to record as the report's rerun
        raise SystemExit("a report is kept by the experiment that made it: run it as `python experiments/NAME.py`")
    script = Path(main).resolve()
    args = next((argv[i + 1 :] for i, a in enumerate(argv) if a.endswith(".py") and Path(a).resolve() == script), [])
    return script.relative_to(ROOT).as_posix(), [a for a in args if a != KEEP], KEEP in args


def script_command() -> str:
    """The experiment's command line, for a report the script writes itself: ``python SCRIPT ARGS`` (without
    :data:`KEEP`, which says what to do with the report, not what it measures)."""
    script, args, _ = _script()
    return shlex.join(["python", script, *args])


def _what_ran(report: dict[str, Any]) -> object:
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


def keep(report: str | Path, name: str, drop: tuple[str, ...] = (), script: str | None = None) -> Path:
    """Copy the JSON ``report`` to ``docs/reports/<name>.json`` with the experiment's record (the script,
    its arguments, and the date the report was written, UTC), without the top-level keys ``drop``
    (per-frame details: the copy stays small; the whole report stays where the run wrote it). The run's
    output folder is written ``OUT`` and the shared data ``../shared/data``, so that no tracked file
    cites the ignored output folder or a machine's paths. ``script``: the shell script that ran the report's
    command (``experiments/gpu_check.sh``: recorded without arguments, its settings are its environment's and the
    command records them); by default the Python experiment that calls this, with its arguments.

    A published report is replaced only by a run of the same commands (:func:`_what_ran`), or with :data:`KEEP`: a
    smoke run with other settings leaves it alone (and says so). Returns the published report's path, or
    ``report`` when it was not replaced."""
    report = Path(report)
    target = REPORTS / f"{name}.json"
    script, args, replace = (script, [], False) if script else _script()
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


def quick_protocol() -> list[str]:
    """The options of ``alcn bench relight``'s quick protocol (its preset, ``alcn_cv.bench.relight.PRESETS["quick"]``)
    spelled out: the kept reports' commands record them so (``--quick`` would be another command for the same
    settings, which :func:`keep` would not let replace them)."""
    from alcn_cv.bench.relight import PRESETS

    # None (every pair) is the bench's 0
    return [arg for key, value in PRESETS["quick"].items() for arg in (f"--{key.replace('_', '-')}", str(value or 0))]


def untrained_start(trained: str | Path, path: str | Path, description: str) -> Path:
    """The untrained start of a trained gain weight file: the network its recipe builds (the same arguments and
    seed) before any step, saved to ``path``."""
    from alcn_cv.train.real_light import initial_network
    from alcn_cv.weight_file import load_normalizer_file, save_normalizer_file

    config = load_normalizer_file(trained).meta["training"]["config"]
    net = initial_network(config["seed"], config["net"])
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


# The rendered stand-in for faces (experiments/directional_light.py, and relief_training.py's training scenes).

#: Elevations of the probes' light above the ground (degrees); the gallery is lit from 90.
ELEVATIONS = (75, 55, 35, 20, 12)
AZIMUTHS = 4
#: Sides of the compared images (pixels).
SIZES = (32, 64)


def render_identity(index: int, size: int, seed: int) -> np.ndarray:
    """``(1 + len(ELEVATIONS) * AZIMUTHS, size, size)`` uint8: scene ``index`` under the gallery's light, then
    under the probes'."""
    from alcn_cv.data.lighting import Lighting, directional
    from alcn_cv.data.objects import to_surface
    from alcn_cv.data.relief_scenes import relief_surface
    from alcn_cv.data.render import render_surfaces

    rng = np.random.default_rng([seed, index])
    albedo, height, material = relief_surface(rng, size)
    lightings = [Lighting("ambient", [directional(0.0, 90.0)], np.full(3, 0.05), gain=0.9)]
    for elevation in ELEVATIONS:
        for _ in range(AZIMUTHS):
            light = directional(rng.uniform(0.0, 360.0), elevation)
            gain = rng.uniform(0.6, 1.4)
            lightings.append(Lighting("side", [light], np.full(3, 0.02), gain=gain, shot_noise=5e-4, read_noise=3e-3))
    surface = to_surface([(albedo, height, material)] * len(lightings))
    return render_surfaces(surface, lightings, rng, gray=True, shadow_steps=24)


def render_stand_in(identities: int = 80, size: int = 128, seed: int = 7) -> np.ndarray:
    """``(identities, 1 + len(ELEVATIONS) * AZIMUTHS, size, size)`` uint8: :func:`render_identity` of each."""
    return np.stack([render_identity(i, size, seed) for i in tqdm(range(identities), desc="render", unit="scene")])


def identify(spec: str, images: np.ndarray) -> dict[int, dict[str, float]]:
    """:func:`identification` of the images of :func:`render_stand_in` normalized by the method ``spec``'s
    ``apply()`` (float output), for each side of :data:`SIZES`."""
    from alcn_cv.enhance.registry import from_spec

    norm = from_spec(spec)
    normalized = np.stack([[norm.apply(im, out_dtype=np.float32) for im in scene] for scene in images])
    return {size: identification(normalized, size) for size in SIZES}


def descriptors(images: np.ndarray, size: int) -> np.ndarray:
    """``(..., H, W)`` float -> ``(..., size * size)``: area-resized, zero-mean, unit-norm."""
    flat = images.reshape(-1, *images.shape[-2:])
    small = np.stack([cv2.resize(im, (size, size), interpolation=cv2.INTER_AREA).ravel() for im in flat])
    small -= small.mean(axis=1, keepdims=True)
    small /= np.linalg.norm(small, axis=1, keepdims=True) + 1e-9
    return small.reshape(*images.shape[:-2], size * size)


def identification(normalized: np.ndarray, size: int) -> dict[str, float]:
    """Per elevation, the percentage of probes whose most correlated gallery image is their own scene's."""
    features = descriptors(normalized, size)
    gallery, identities = features[:, 0], np.arange(len(features))
    result = {}
    for j, elevation in enumerate(ELEVATIONS):
        probes = features[:, 1 + j * AZIMUTHS : 1 + (j + 1) * AZIMUTHS]
        nearest = np.argmax(probes @ gallery.T, axis=-1)
        result[f"elevation {elevation}"] = float(100 * np.mean(nearest == identities[:, None]))
    return result
