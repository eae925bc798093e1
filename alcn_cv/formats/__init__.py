"""Readers and writers of the file formats the field already uses.

- :mod:`alcn_cv.formats.coco`: COCO detection annotations.
- :mod:`alcn_cv.formats.bop`: BOP pose scenes (``scene_camera.json``, ``scene_gt.json``, ``rgb/``)
  and PLY models in millimetres.
- :mod:`alcn_cv.formats.colmap`: COLMAP sparse models.
- :mod:`alcn_cv.formats.middlebury`: Middlebury multi-view stereo camera files.

:func:`validate_json` checks a parsed JSON document against one of the JSON schemas shipped in
``alcn_cv/formats/schemas`` (with the ``jsonschema`` package, of the ``[data]`` extra) and raises
:class:`~alcn_cv.errors.DatasetError` naming the file and the offending field.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Any

from alcn_cv.errors import DatasetError, InputError
from alcn_cv.extras import require
from alcn_cv.io import read_json

__all__ = ["SCHEMA_DIR", "schema", "validate_json"]

#: Folder of the JSON schemas (``<name>.schema.json``).
SCHEMA_DIR = Path(__file__).resolve().parent / "schemas"


@functools.cache
def schema(name: str) -> dict[str, Any]:
    """The JSON schema ``name`` (``coco``, ``bop_scene_camera``, ``bop_scene_gt``).

    Raises:
        InputError: no schema of that name (the message lists the known ones).
    """
    path = SCHEMA_DIR / f"{name}.schema.json"
    if not path.is_file():
        known = sorted(p.name.removesuffix(".schema.json") for p in SCHEMA_DIR.glob("*.schema.json"))
        raise InputError(f"unknown schema {name!r}; known: {', '.join(known)}")
    return read_json(path)


def validate_json(obj: Any, name: str, file: str | os.PathLike) -> None:
    """Validate ``obj`` (parsed from ``file``) against schema ``name``.

    Raises:
        DatasetError: ``"<file>: field <path>: <reason>"`` for the first violation (the most
            deeply nested one, which is the most specific).
        InputError: no schema ``name``.
        MissingDependencyError: jsonschema is not installed (the message names the extra that installs it).
    """
    spec = schema(name)
    require("jsonschema", what=f"validating {file}")
    import jsonschema

    validator = jsonschema.Draft202012Validator(spec)
    errors = list(validator.iter_errors(obj))
    if errors:
        err = max(errors, key=lambda e: len(e.absolute_path))
        field = (
            "".join(
                f"[{p}]" if isinstance(p, int) else (f".{p}" if i else str(p)) for i, p in enumerate(err.absolute_path)
            )
            or "(top level)"
        )
        raise DatasetError(f"{file}: field {field}: {err.message}")
