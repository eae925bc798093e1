"""Settings of ``alcn data pose`` (:mod:`alcn_cv.data.pose`): the dataset's sizes and its named presets, apart
from the renderer so that the command line's help reads them without importing it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CONFS", "CONF_SUMMARIES", "PoseConfig"]


@dataclass(frozen=True)
class PoseConfig:
    """Size of the pose dataset, one preset of :data:`CONFS`: image size, focal length (px), frames per sequence,
    texture sizes."""

    width: int = 640
    height: int = 480
    focal: float = 580.0
    n_frames: int = 60
    n_test: int = 8
    texel: int = 256
    table_px: int = 1024
    shadow_res: int = 1024

    @property
    def K(self) -> np.ndarray:
        """OpenCV intrinsics (principal point at the image centre, OpenCV convention)."""
        return np.array([[self.focal, 0, (self.width - 1) / 2], [0, self.focal, (self.height - 1) / 2], [0, 0, 1.0]])


#: The named presets of :func:`~alcn_cv.data.pose.generate` (hloc's ``confs``; ``alcn data pose --conf NAME``):
#: ``default``, the rendered Table 1's scenes (its published run renders 30 frames a sequence: ``--frames 30``);
#: ``small``, 320x240 and 3 frames a sequence (seconds, for tests).
#: Frozen: :func:`~alcn_cv.data.pose.generate` derives a run's configuration with :func:`dataclasses.replace`, never
#: changing a preset.
CONFS: dict[str, PoseConfig] = {
    "default": PoseConfig(),
    "small": PoseConfig(width=320, height=240, focal=290.0, n_frames=3, texel=96, table_px=384, shadow_res=512),
}

#: One line per preset of :data:`CONFS`, for ``alcn data pose --help``.
CONF_SUMMARIES: dict[str, str] = {
    "default": "60 frames a sequence (minutes on 2 cores); the published rendered Table 1 used --frames 30 "
    "(experiments/pose_table1.py)",
    "small": "small frames, few of them (seconds; for tests, and with --frames 12 for `alcn pose eval`)",
}
