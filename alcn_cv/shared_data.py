"""Where the real photographs used by tests, benchmarks and examples live.

They stay outside the project (``../shared/data`` beside the checkout); the
``ALCN_SHARED_DATA`` environment variable overrides the location.
"""

from __future__ import annotations

import os
from pathlib import Path

ENV_VAR = "ALCN_SHARED_DATA"


def shared_data_dir() -> Path:
    """Return the folder of the shared real data (it may not exist)."""
    if ENV_VAR in os.environ:
        return Path(os.environ[ENV_VAR]).expanduser()
    return Path(__file__).resolve().parents[1].parent / "shared" / "data"
