"""Where the real photographs used by tests, benchmarks and examples live.

They stay outside the project (``../shared/data`` beside the checkout); the
``ALCN_SHARED_DATA`` environment variable overrides the location.
"""

from __future__ import annotations

import os
from pathlib import Path

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
    """``"PATH: folder not found"`` (or ``not a folder``), and where ``path`` is one of the shared data's folders (a
    default), how to give another: ``--data`` or :data:`ENV_VAR`."""
    path = Path(path)
    what = f"{path}: {'not a folder' if path.exists() else 'folder not found'}"
    if path.resolve().is_relative_to(shared_data_dir().resolve()):
        what += f" (the shared data's {path.name}: give --data DIR, or set {ENV_VAR} to the folder that holds it)"
    return what
