"""Settings of ``alcn bench relight`` (:mod:`alcn_cv.bench.relight`): the protocols' parameters and the presets of
their sampling sizes, apart from the benchmark so that what describes its reports (``experiments/report.py``) reads
them without importing it."""

from __future__ import annotations

from dataclasses import dataclass

from alcn_cv.errors import InputError

__all__ = ["PRESETS", "Settings"]


@dataclass(frozen=True)
class Settings:
    """The protocols' parameters (see :mod:`alcn_cv.bench.relight`)."""

    patch: int = 32
    patches: int = 300
    gallery: int = 3
    max_pairs: int | None = 30
    keypoints: int = 1000
    ratio: float = 0.8
    match_px: float = 3.0
    ransac_px: float = 3.0
    pose_px: float = 5.0
    keypoint_protocols: bool = True

    def check(self) -> Settings:
        if self.patch < 4 or self.patches < 2 or self.gallery < 1 or self.keypoints < 4:
            raise InputError("need patch >= 4, patches >= 2, gallery >= 1 and keypoints >= 4")
        if self.max_pairs is not None and self.max_pairs < 1:
            raise InputError(f"max_pairs must be positive, got {self.max_pairs}")
        if not 0 < self.ratio <= 1:
            raise InputError(f"ratio must be in (0, 1], got {self.ratio}")
        return self


#: The sampling sizes of ``alcn bench relight``'s presets: the benchmark's, and ``quick``, the quick protocol of
#: docs/results.md's "(quick protocol)" tables (``--quick``; about 3 times faster).
PRESETS: dict[str, dict[str, int | None]] = {
    "default": {"max_frames": 20, "patches": Settings.patches, "max_pairs": Settings.max_pairs},
    "quick": {"max_frames": 12, "patches": 150, "max_pairs": 12},
}
