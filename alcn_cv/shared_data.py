"""Where the real photographs used by tests, benchmarks and examples live.

They stay outside the project (``../shared/data`` beside the checkout); the
``ALCN_SHARED_DATA`` environment variable overrides the location.
"""

from __future__ import annotations

import os
from pathlib import Path

from alcn_cv.errors import DatasetError

ENV_VAR = "ALCN_SHARED_DATA"


def shared_data_dir() -> Path:
    """The folder of the shared real data (it may not exist): ``$ALCN_SHARED_DATA``; else ``../shared/data``
    beside the checkout this package is imported from; else, for an installed package (``pip install .``, not
    ``-e``), ``../shared/data`` from the current directory (the clone it was installed from, say)."""
    if ENV_VAR in os.environ:
        return Path(os.environ[ENV_VAR]).expanduser()
    checkout = Path(__file__).resolve().parents[1]
    base = checkout if (checkout / "pyproject.toml").is_file() else Path.cwd()
    return base.parent / "shared" / "data"


def missing_folder(path: str | os.PathLike) -> str:
    """``"PATH: folder not found"`` (or ``not a folder``)."""
    path = Path(path)
    return f"{path}: {'not a folder' if path.exists() else 'folder not found'}"


def default_folder(name: str) -> Path:
    """The shared data's folder ``name`` (``webcam``, ``psm``), a command's data when none is given.

    Raises:
        DatasetError: it is not a folder; the message says how to give another (``--data``, :data:`ENV_VAR`).
    """
    path = shared_data_dir() / name
    if not path.is_dir():
        raise DatasetError(
            f"{missing_folder(path)} (the default {name} data: give --data DIR, or set {ENV_VAR} to the folder "
            f"that holds {name}/)"
        )
    return path
