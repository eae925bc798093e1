"""Manifests, atomic output folders and deterministic files of the data engine.

Every dataset folder holds a ``manifest.json``::

    {"generator": "alcn_cv.data", "generator_version": "1", "kind": "phos" | "detect" | "pose" | "relief_scenes",
     "seed": 0, "parameters": {...}, ...}

Its JSON schema is :data:`MANIFEST_SCHEMA`. It holds no time stamp or timing, so that the same seed and parameters
give byte-identical folders. Folders are written under a temporary name beside the target and renamed when
complete, so a half-written dataset is never mistaken for a complete one.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from alcn_cv.errors import DatasetError
from alcn_cv.io import UMASK, atomic_path, make_folder, read_json

__all__ = [
    "GENERATOR",
    "GENERATOR_VERSION",
    "MANIFEST_SCHEMA",
    "make_manifest",
    "read_manifest",
    "atomic_output_dir",
    "save_npz",
]

GENERATOR = "alcn_cv.data"
#: Bumped whenever the same seed and parameters would give different data.
GENERATOR_VERSION = "1"
#: The JSON schema (draft 2020-12) of ``manifest.json``.
MANIFEST_SCHEMA = Path(__file__).resolve().parent / "manifest.schema.json"


def make_manifest(kind: str, seed: int, parameters: dict[str, Any], **extra: Any) -> dict[str, Any]:
    """The manifest dictionary of a dataset of ``kind`` (extra keys are added at top level)."""
    return {
        "generator": GENERATOR,
        "generator_version": GENERATOR_VERSION,
        "kind": kind,
        "seed": int(seed),
        "parameters": parameters,
        **extra,
    }


def read_manifest(folder: str | os.PathLike, kind: str | None = None) -> dict[str, Any]:
    """Read and check ``folder/manifest.json`` (and its ``kind`` when given)."""
    path = Path(folder) / "manifest.json"
    man = read_json(path)
    if not isinstance(man, dict):
        raise DatasetError(f"{path}: expected a JSON object")
    for key in ("generator_version", "kind", "seed", "parameters"):
        if key not in man:
            raise DatasetError(f"{path}: missing field {key!r}")
    if kind is not None and man["kind"] != kind:
        raise DatasetError(f"{path}: field 'kind' is {man['kind']!r}, expected {kind!r}")
    return man


@contextlib.contextmanager
def atomic_output_dir(
    out_dir: str | os.PathLike, *, overwrite: bool = False, marker: str = "manifest.json"
) -> Iterator[Path]:
    """Yield a temporary folder that becomes ``out_dir`` when the block completes.

    On error the temporary folder is removed and ``out_dir`` is left as it was. An empty folder counts as
    absent (as for ``git clone``); with ``overwrite``, an existing ``out_dir`` is also replaced if it is an earlier
    output (it holds ``marker``); anything else (a file, a folder of other files) is never removed.

    Raises:
        FileExistsError: ``out_dir`` is a file or a folder that is not an earlier output (whether or not
            ``overwrite``), or an earlier output and not ``overwrite``; one line, as
            :func:`~alcn_cv.io.check_no_earlier_output` words it (``--overwrite``).
        InputError: a parent of ``out_dir`` is a file.
    """
    out = Path(out_dir)
    empty = out.is_dir() and not any(out.iterdir())
    # what overwriting would not replace says so first, whether or not overwriting was asked
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"{out} is a file, not an output folder: not replaced; give another path")
    if out.exists() and not (empty or (out / marker).is_file()):
        raise FileExistsError(f"{out} is not an earlier output (no {marker}): not replaced; give another path")
    if out.exists() and not overwrite and not empty:
        raise FileExistsError(f"{out} exists (--overwrite replaces it)")
    make_folder(out.parent)  # a parent that is a file: the one-line InputError, not mkdir's errno
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp"))
    tmp.chmod(0o777 & ~UMASK)  # mkdtemp's folder is private (0700); the output is as any other folder made here
    try:
        yield tmp
        if out.exists():
            old = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".old"))
            os.replace(out, old / "d")
            os.replace(tmp, out)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def save_npz(path: str | os.PathLike, **arrays: np.ndarray) -> Path:
    """Write a compressed ``.npz`` that :func:`numpy.load` reads, byte-identical for equal arrays.

    :func:`numpy.savez_compressed` stamps the current time into the zip entries; this writer
    uses a fixed date so that the same data always gives the same file.
    """
    path = Path(path)
    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=6) as zf:
        for name, arr in arrays.items():
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            with zf.open(info, "w", force_zip64=True) as f:  # streamed: no copy in memory
                np.lib.format.write_array(f, np.ascontiguousarray(arr), allow_pickle=False)
    return path
