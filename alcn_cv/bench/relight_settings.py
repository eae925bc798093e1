"""Settings of ``alcn bench relight`` (:mod:`alcn_cv.bench.relight`): the protocols' parameters and the presets of
their sampling sizes (:data:`CONFS`), apart from the benchmark so that what describes its reports
(``experiments/report.py``) reads them without importing it."""

from __future__ import annotations

from dataclasses import asdict, dataclass

from alcn_cv.errors import InputError

__all__ = ["CONFS", "CONF_SUMMARIES", "Sampling", "Settings"]


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
    #: The largest move along each axis, in pixels, by which identification registers a pair of frames.
    shift_px: int = 2
    keypoint_protocols: bool = True

    def check(self) -> Settings:
        if self.patch < 4 or self.patches < 2 or self.gallery < 1 or self.keypoints < 4:
            raise InputError("need patch >= 4, patches >= 2, gallery >= 1 and keypoints >= 4")
        if self.shift_px < 0:
            raise InputError(f"shift_px must be 0 or more, got {self.shift_px}")
        if self.max_pairs is not None and self.max_pairs < 1:
            raise InputError(f"max_pairs must be positive, got {self.max_pairs}")
        if not 0 < self.ratio <= 1:
            raise InputError(f"ratio must be in (0, 1], got {self.ratio}")
        return self


@dataclass(frozen=True)
class Sampling:
    """The sampling sizes of a run, what a preset of :data:`CONFS` sets (its reports record them beside
    :class:`Settings`' fields).

    Attributes:
        max_frames: frames per scene, evenly spaced (``None``: all).
        patches: :attr:`Settings.patches`.
        max_pairs: :attr:`Settings.max_pairs` (``None``: all).
    """

    max_frames: int | None = 20
    patches: int = Settings.patches
    max_pairs: int | None = Settings.max_pairs

    def options(self) -> list[str]:
        """The options of ``alcn bench relight`` that set these sizes, ``["--max-frames", "12", ...]`` (0: all)."""
        return [arg for key, value in asdict(self).items() for arg in (f"--{key.replace('_', '-')}", str(value or 0))]


#: The named presets of ``alcn bench relight`` (hloc's ``confs``; ``--conf NAME``), its sampling sizes: ``default``,
#: the benchmark's, and ``quick``, the quick protocol of docs/results.md's "(quick protocol)" tables. Frozen: a run
#: derives its own with :func:`dataclasses.replace`.
CONFS: dict[str, Sampling] = {"default": Sampling(), "quick": Sampling(max_frames=12, patches=150, max_pairs=12)}

#: One line per preset of :data:`CONFS`, for ``alcn bench relight --help``.
CONF_SUMMARIES: dict[str, str] = {
    "default": "the benchmark's sampling sizes",
    "quick": "the quick protocol of docs/results.md (fewer frames, patches and pairs; about 3 times faster)",
}
