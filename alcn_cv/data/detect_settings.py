"""Settings of ``alcn data detect`` (:mod:`alcn_cv.data.detect`): the rendered benchmark's sizes and its named
presets, apart from the renderer so that the command line's help reads them without importing it."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

__all__ = ["CONFS", "CONF_SUMMARIES", "MAX_SIDE", "DetectConfig"]

#: The largest width or height of the images (pixels): an image is rendered whole, about 6 GB at 4096x4096 (its
#: memory grows with the pixels), where 100000x100000 asked for 149 GiB.
MAX_SIDE = 4096


@dataclass(frozen=True)
class DetectConfig:
    """Parameters of the rendered benchmark, one preset of :data:`CONFS`.

    Attributes:
        width, height: image size in pixels.
        n_train: training images per object.
        n_test: test images.
        n_val: validation images (test-like, for tuning).
        object_px: object extent in full-resolution pixels.
        box_px: object extent (and box side) at the working scale.
        canonical: resolution of the objects' canonical textures.
        p_object: probability that each object appears in a test image.
    """

    width: int = 1280
    height: int = 800
    n_train: int = 10
    n_test: int = 120
    n_val: int = 30
    object_px: float = 144.0
    box_px: float = 36.0
    canonical: int = 192
    p_object: float = 0.5

    @property
    def working_scale(self) -> float:
        return self.box_px / self.object_px


_SMALL = DetectConfig(width=320, height=200, n_train=3, n_test=4, n_val=2, object_px=72.0, canonical=96)

#: The named presets of :func:`~alcn_cv.data.detect.generate` (hloc's ``confs``; ``alcn data detect --conf NAME``):
#: ``default``, the benchmark (minutes on 2 cores); ``small``, seconds, for tests; ``demo``, ``alcn demo``'s set:
#: ``small``'s objects in 480x300 images, 6 test images with every object in each, no validation image (the demo does
#: not tune). Frozen: :func:`~alcn_cv.data.detect.generate` derives a run's configuration with
#: :func:`dataclasses.replace`, never changing a preset.
CONFS: dict[str, DetectConfig] = {
    "default": DetectConfig(),
    "small": _SMALL,
    "demo": dataclasses.replace(_SMALL, width=480, height=300, n_test=6, n_val=0, p_object=1.0),
}

#: One line per preset of :data:`CONFS`, for ``alcn data detect --help``.
CONF_SUMMARIES: dict[str, str] = {
    "default": "the benchmark (minutes on 2 cores)",
    "small": "small images, few of them (seconds; for tests)",
    "demo": "the set `alcn demo` renders: small's objects, larger images, every object in every test image",
}
