"""The Normalizer weight file: a ``.npz`` of the network's arrays plus a JSON header.

NumPy-only on purpose: the header (architecture, sigmas, working scale, output range, whether
the weights are trained) is readable without torch, and loading never unpickles code.
"""

from __future__ import annotations

import io
import json
import logging
import math
import re
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from alcn_cv.errors import WeightFileError
from alcn_cv.io import atomic_write, with_suffix

logger = logging.getLogger(__name__)

__all__ = [
    "WEIGHTS_DIR",
    "FORMAT",
    "ONNX_METADATA_KEY",
    "VERSION",
    "NormalizerFile",
    "check_header",
    "gain_scale",
    "load_normalizer_file",
    "npz_array",
    "save_normalizer_file",
]

FORMAT = "alcn-cv/normalizer"
VERSION = 1
#: The folder of the shipped weight files and their ONNX exports (each model by name: :data:`alcn_cv.runtime.MODELS`).
WEIGHTS_DIR = Path(__file__).parent / "weights"
#: The key of the header in an ONNX export's ``metadata_props`` (a Normalizer's and a corner detector's), so that
#: the ``.onnx`` describes itself.
ONNX_METADATA_KEY = "alcn_cv"
_META_KEY = "__meta__"
_REQUIRED: dict[str, type | tuple[type, ...]] = {
    "config": dict,
    "sigmas": list,
    "working_scale": (int, float),
    "output_range": list,
    "trained": bool,
}


def _positive_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value > 0


def _positive_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0


#: The fields of a gain Normalizer's header (``architecture: "gain"``) that :class:`alcn_cv.runtime.ModelSpec` reads,
#: by dotted path: what each must be, and its test.
_GAIN_FIELDS: dict[str, tuple[str, Callable[[object], bool]]] = {
    "config.stride": ("a positive integer", _positive_int),
    "config.mean_sigma": ("a positive number", _positive_number),
    "config.context_sigma": ("a positive number", _positive_number),
    "config.dilations": (
        "a list of positive integers",
        lambda value: isinstance(value, list) and all(_positive_int(d) for d in value),
    ),
    "equalization.tau": ("a positive number", _positive_number),
    "divisive.sigma": ("a positive number", _positive_number),
    "divisive.scale": ("a positive number", _positive_number),
}
#: A gain Normalizer's arrays of ``log(tau)`` and ``log(c)`` (the parameters) and the header fields that restate them.
_GAIN_SCALES = {"log_tau": "equalization.tau", "log_floor_scale": "divisive.scale"}


@dataclass
class NormalizerFile:
    """Contents of a weight file.

    Attributes:
        arrays: the Normalizer's ``state_dict`` as float32 arrays.
        meta: the header: ``config`` (``Normalizer`` arguments), ``sigmas`` (pixels at the
            working scale), ``working_scale`` (factor from input to working resolution),
            ``output_range`` (``[lo, hi]`` raw responses mapped to the output range),
            ``trained`` (False for an untrained initialisation), and free-form provenance; a gain Normalizer's
            (``architecture: "gain"``) also ``equalization`` (``tau``) and ``divisive`` (``sigma``, and ``scale``,
            the floor scale ``c``), ``tau`` and ``c`` restating its arrays ``log_tau`` and ``log_floor_scale``.
        path: the file it was read from (its errors name it; None: made in memory).
    """

    arrays: dict[str, np.ndarray]
    meta: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None


def save_normalizer_file(path: str | Path, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> Path:
    """Write a weight file atomically (temporary name, then rename). An ONNX export beside it (the same name,
    ``.onnx``), which ``backend="opencv"`` would run, was made from the weights it held before: it is removed
    (``alcn export`` makes it again)."""
    path = with_suffix(path, ".npz", "a weight file")
    meta = {"format": FORMAT, "version": VERSION, **meta}
    _check_meta(meta, path)
    _check_arrays(arrays, path)
    _check_gain(meta, arrays, path)
    buffer = io.BytesIO()
    stored: dict[str, Any] = {
        **{k: np.asarray(v, np.float32) for k, v in arrays.items()},
        _META_KEY: np.array(json.dumps(meta)),
    }
    np.savez(buffer, **stored)
    atomic_write(path, buffer.getvalue())
    stale = path.with_suffix(".onnx")
    if stale.is_file():
        stale.unlink()
        logger.warning(
            "removed %s, the ONNX export of the weights %s held before (alcn export makes it again)", stale, path
        )
    return path


def load_normalizer_file(path: str | Path) -> NormalizerFile:
    """Read and check a weight file (a shipped model's: :func:`alcn_cv.runtime.resolve_weights`).

    Raises:
        WeightFileError: missing, a folder (the weight file in it named), empty, a training run's checkpoint (the
            run's weight file named), not a ``.npz`` archive, corrupt, holding pickled objects,
            of another format or of an incompatible version, a header field missing or out of range (a sigma or the
            working scale not positive, an empty output range; a gain Normalizer's grid, blurs, ``tau`` and divisive
            normalization), holding NaN or infinite weights, or a gain Normalizer's header restating its ``tau`` or
            ``c`` otherwise than its arrays ``log_tau`` and ``log_floor_scale``. The message names the file, and the
            field or array.
    """
    path = Path(path)
    if path.is_dir():
        raise WeightFileError(_folder_message(path))
    if not path.is_file():
        raise WeightFileError(f"weight file not found: {path}")
    if path.stat().st_size == 0:
        raise WeightFileError(f"weight file {path} is empty")
    checkpoint = _checkpoint_message(path)
    if checkpoint is not None:
        raise WeightFileError(checkpoint)
    if not zipfile.is_zipfile(path):
        if path.suffix.lower() == ".onnx":  # an export: the weight file is the .npz it was made from
            raise WeightFileError(
                f"{path} is an ONNX export; give the weight file (.npz) it was exported from, and keep the .onnx "
                "beside it under the same name: backend='opencv' reads it there"
            )
        raise WeightFileError(f"weight file {path} is not a .npz archive")
    try:
        with np.load(path, allow_pickle=False) as data:
            if _META_KEY not in data.files:
                raise WeightFileError(
                    f"{path} is not an alcn-cv weight file (no header; a torch state_dict or module? ALCN2d.save(path) "
                    "writes a weight file)"
                )
            meta = json.loads(str(npz_array(data, _META_KEY, path)))
            arrays = {k: npz_array(data, k, path) for k in data.files if k != _META_KEY}
    except WeightFileError:
        raise
    except (OSError, EOFError, ValueError, zipfile.BadZipFile, json.JSONDecodeError) as exc:
        raise WeightFileError(f"weight file {path} is corrupt or truncated: {exc}") from None
    _check_meta(meta, path)
    _check_arrays(arrays, path)
    _check_gain(meta, arrays, path)
    return NormalizerFile(arrays=arrays, meta=meta, path=path)


def check_header(
    header: Any, path: str | Path, format_name: str, versions: tuple[int, ...], *, what: str, again: str
) -> dict[str, Any]:
    """``header`` (a file's parsed JSON header) when it is a JSON object of format ``format_name`` and one of
    ``versions``: the check of the files alcn-cv writes for its runtime (weight files, part models, corner
    detectors).

    Raises:
        WeightFileError: not an object, another format or another version; ``what`` names the file's kind
            (``"part model"``), ``again`` how to make a readable one (``"rebuild it with `alcn pose build`"``).
    """
    if not isinstance(header, dict):
        raise WeightFileError(f"{path}: the header is not a JSON object; not a {what}")
    if header.get("format") != format_name:
        raise WeightFileError(f"{path}: field 'format' is {header.get('format')!r}, expected {format_name!r}")
    version = header.get("version")
    if type(version) is not int or version not in versions:  # not True, which equals 1
        readable = f"versions {', '.join(map(str, versions))}" if len(versions) > 1 else f"version {versions[0]}"
        raise WeightFileError(f"{path}: {what} format version {version!r} but this alcn-cv reads {readable}; {again}")
    return header


def npz_array(archive: Any, key: str, path: str | Path, what: str = "a weight file of alcn-cv") -> np.ndarray:
    """The array ``key`` of the archive ``archive`` (an ``NpzFile`` opened without pickles) read from ``path``.

    Raises:
        WeightFileError: an array of pickled Python objects, which are not read (NumPy's advice, to load them
            unsafely, is no help): the file is not ``what``.
        ValueError: NumPy's other errors of a corrupt array.
    """
    try:
        return archive[key]
    except ValueError as exc:
        # NumPy tells an object array refused by its advice only, to allow pickles
        if "allow_pickle" not in str(exc):
            raise
        raise WeightFileError(
            f"{path}: array {key!r} holds pickled Python objects, which are not read: not {what}"
        ) from None


def gain_scale(arrays: dict[str, np.ndarray], key: str) -> float:
    """A gain Normalizer's ``tau`` (``key="log_tau"``) or divisive floor scale ``c`` (``"log_floor_scale"``): the
    exponential of its 0-d array in float32, as the network computes it."""
    return float(np.exp(np.asarray(arrays[key], np.float32)))


#: The weight files a training run writes into its folder, by command.
_RUN_WEIGHTS = ("gain_normalizer.npz", "alcn_normalizer.npz", "unet_normalizer.npz")


def _folder_message(folder: Path) -> str:
    """Why a folder is no weight file, and the file in it meant: a training run's final weights, or its one ``.npz``."""
    files = sorted(folder.glob("*.npz"))
    meant = next((folder / n for n in _RUN_WEIGHTS if (folder / n).is_file()), files[0] if len(files) == 1 else None)
    if meant is not None:
        return f"{folder} is a folder, not a weight file; did you mean {meant}?"
    return f"{folder} is a folder, not a weight file (.npz)" + (
        f"; it holds {len(files)}: {', '.join(p.name for p in files[:5])}{', ...' if len(files) > 5 else ''}"
        if files
        else ""
    )


def _checkpoint_message(path: Path) -> str | None:
    """Why a training run's checkpoint (``checkpoint.pt``, or a ``.pt`` beside a run's weight files) is no weight file,
    and the run's weight file meant: its final one, else its latest step snapshot; None for any other file."""
    if path.suffix.lower() != ".pt":
        return None
    folder = path.parent
    finals = [folder / n for n in _RUN_WEIGHTS if (folder / n).is_file()]
    snapshots = sorted(
        (p for p in folder.glob("*_step*.npz") if re.fullmatch(r".+_step\d+", p.stem)),
        key=lambda p: int(p.stem.rsplit("_step", 1)[1]),
    )
    if not (path.name == "checkpoint.pt" or finals or snapshots):
        return None
    what = f"{path} is a training run's checkpoint (what --resume goes on from), not a weight file"
    if finals:
        return f"{what}; did you mean {finals[0]}?"
    if snapshots:
        return f"{what}; did you mean {snapshots[-1]} (the run's latest step snapshot)?"
    return f"{what}; its run has written no weight file yet (one at every save and one at its end)"


def _check_arrays(arrays: dict[str, np.ndarray], path: Path) -> None:
    """Every weight array is numeric and finite: NaN weights would make every output NaN."""
    for key, value in arrays.items():
        value = np.asarray(value)
        if not (np.issubdtype(value.dtype, np.floating) or np.issubdtype(value.dtype, np.integer)):
            raise WeightFileError(f"{path}: array {key!r} has the non-numeric type {value.dtype}")
        if not np.isfinite(value).all():
            raise WeightFileError(f"{path}: array {key!r} holds NaN or infinite values (a diverged training?)")


def _check_meta(meta: dict[str, Any], path: Path) -> None:
    check_header(
        meta,
        path,
        FORMAT,
        (VERSION,),
        what="weight file",
        again="read it with the alcn-cv that wrote it, or train it again with this one",
    )
    for key, kind in _REQUIRED.items():
        if not isinstance(meta.get(key), kind):
            raise WeightFileError(f"{path}: header field {key!r} missing or of the wrong type")
    numbers = [*meta["sigmas"], meta["working_scale"], *meta["output_range"]]
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in numbers):
        raise WeightFileError(f"{path}: sigmas, working_scale and output_range must be finite numbers")
    if not all(v > 0 for v in [*meta["sigmas"], meta["working_scale"]]):  # Gaussian widths and a resize factor
        raise WeightFileError(
            f"{path}: sigmas {meta['sigmas']} and working_scale {meta['working_scale']} must be positive"
        )
    if len(meta["output_range"]) != 2:
        raise WeightFileError(f"{path}: output_range must be [lo, hi], got {meta['output_range']}")
    lo, hi = meta["output_range"]
    if not hi > lo:
        raise WeightFileError(f"{path}: output_range {meta['output_range']} is empty")


def _check_gain(meta: dict[str, Any], arrays: dict[str, np.ndarray], path: Path) -> None:
    """A gain Normalizer's header fields (:data:`_GAIN_FIELDS`), and its ``tau`` and ``c`` restated by the header as
    its arrays hold them (to float32 rounding); nothing for the other architectures."""
    if meta.get("architecture") != "gain":
        return
    for name, (kind, valid) in _GAIN_FIELDS.items():
        table, key = name.split(".")
        if not isinstance(meta.get(table), dict) or key not in meta[table]:
            raise WeightFileError(f"{path}: header field {name!r} missing")
        if not valid(meta[table][key]):
            raise WeightFileError(f"{path}: header field {name!r} must be {kind}, got {meta[table][key]!r}")
    for key, name in _GAIN_SCALES.items():
        if key not in arrays or np.shape(arrays[key]) != ():
            raise WeightFileError(f"{path}: array {key!r} missing or not a single value")
        table, field_key = name.split(".")
        stated, value = meta[table][field_key], gain_scale(arrays, key)
        if not math.isclose(stated, value, rel_tol=1e-6):
            raise WeightFileError(f"{path}: header field {name!r} is {stated}, its array {key!r} holds {value}")
