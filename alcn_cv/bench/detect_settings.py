"""Settings of the detection benchmark (:mod:`alcn_cv.bench.detect`): methods, input policies,
training and scoring, and the named presets (:data:`CONFS`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from alcn_cv.checks import check_seeds
from alcn_cv.enhance.registry import available, parse_spec
from alcn_cv.errors import InputError

__all__ = [
    "CONFS",
    "CONF_SUMMARIES",
    "CROP",
    "DEEP_BASELINES",
    "POLICIES",
    "POLICY_DESCRIPTIONS",
    "RESNETS",
    "RESNET_CONTEXT",
    "STRIDE",
    "WINDOW",
    "DetectSettings",
    "default_methods",
    "run_key",
]

#: Deep baselines (own networks, no normalization) of Sec. 4.3.1.
DEEP_BASELINES = ("cnn", "resnet20", "resnet56")
RESNETS = ("resnet20", "resnet56")
POLICIES = ("raw", "standardize", "local")
#: What each input policy feeds the detector (the reports quote it).
POLICY_DESCRIPTIONS = {
    "raw": "the normalized windows through one fixed affine map (the training windows' mean and standard "
    "deviation, one scalar each): every method reaches the detector with unit variance and its own response",
    "standardize": "each 32x32 window standardized alone to zero mean and unit variance (at test time every "
    "window is standardized and scored alone)",
    "local": "every pixel of the normalized image standardized by the mean and standard deviation of the "
    "31x31 box around it, an image operation, so the detector still runs densely (close to `standardize` at "
    "a window's centre)",
}
#: Side of the training windows (synthetic images and background).
WINDOW = 64
#: Side of the detector's input window.
CROP = 32
#: Step between scored windows of a test image.
STRIDE = 4
#: Pixels of surroundings around the 32x32 window in the ResNets' training inputs (dense policies):
#: the whole 64x64 training window.
RESNET_CONTEXT = (WINDOW - CROP) // 2


def default_methods() -> list[str]:
    """Every registered normalization, then the deep baselines but ResNet-56, the costliest by far
    (``--methods`` adds it)."""
    return list(available()) + [m for m in DEEP_BASELINES if m != "resnet56"]


def run_key(method: str, n_real: int, policy: str, seed: int) -> str:
    """Key of one run in ``detect.json``'s ``runs``."""
    return f"{method}|{n_real}|{policy}|{seed}"


@dataclass
class DetectSettings:
    """Settings of a benchmark run (all recorded in ``detect.json``).

    Attributes:
        methods: registered normalization names, each optionally with parameters
            (``NAME[:KEY=VALUE...]``, e.g. ``alcn:model=lite:mixture=pyramid``), and/or
            :data:`DEEP_BASELINES`; None: :func:`default_methods`, read when the settings are used
            (:meth:`resolved`), so that a normalization registered after this module was imported is one of them.
        real_images: numbers of real training images per object.
        policies: detector input policies (:data:`POLICIES`).
        positives_per_object: synthetic object windows per object.
        negatives_ratio: background windows per object window.
        epochs, batch_size, lr: detector training (the same for every method).
        seeds: one repetition of every run per seed (training windows, detector
            initialisation and batch order); the tables give the mean and spread over seeds.
        tune: tune DoG, SLCN and DLCN by detection on the data's validation images (``val.json``;
            :data:`alcn_cv.bench.detect.TUNING_GRIDS`).
        cnn_sweep: ``(depth, width)`` of the plain CNNs tried for ``cnn``.
        nms_iou: IoU above which non-maximum suppression removes a box.
        match_iou: PASCAL criterion (the paper: 0.8).
        max_detections: boxes kept per object and image after suppression.
        max_test_images: use only the first test images (``None``: all).
        threads: torch threads (``None``: torch's default).
        device: torch device.
    """

    methods: list[str] | None = None
    real_images: list[int] = field(default_factory=lambda: [1, 10])
    policies: list[str] = field(default_factory=lambda: ["local"])
    positives_per_object: int = 300
    negatives_ratio: float = 2.0
    epochs: int = 6
    batch_size: int = 64
    lr: float = 1e-3
    seeds: list[int] = field(default_factory=lambda: [0])
    tune: bool = False
    cnn_sweep: list[tuple[int, int]] = field(default_factory=lambda: [(1, 32), (2, 32), (3, 32)])
    nms_iou: float = 0.3
    match_iou: float = 0.8
    max_detections: int = 20
    max_test_images: int | None = None
    threads: int | None = None
    device: str = "cpu"

    def resolved(self) -> DetectSettings:
        """A copy whose ``methods`` is a list: :func:`default_methods`, the normalizations registered now, for None."""
        return dataclasses.replace(self, methods=default_methods() if self.methods is None else list(self.methods))

    def check(self) -> None:
        """Raise :class:`~alcn_cv.errors.InputError` on an unknown method or policy, or a value out of range (the
        device is checked where torch is imported, :func:`alcn_cv.bench.detect.main`)."""
        known = set(available()) | set(DEEP_BASELINES)
        methods = self.resolved().methods
        specs = [parse_spec(m) for m in methods]
        unknown = [m for m, (name, _) in zip(methods, specs) if name not in known]
        if unknown or not methods:
            raise InputError(f"unknown or no method(s) {unknown}; available: {', '.join(sorted(known))}")
        if any(name in DEEP_BASELINES and params for name, params in specs):
            raise InputError(f"the deep baselines {', '.join(DEEP_BASELINES)} take no parameters")
        check_seeds(self.seeds)
        if not self.real_images or min(self.real_images) < 1:
            raise InputError(f"real_images must be positive integers, got {self.real_images}")
        bad = [p for p in self.policies if p not in POLICIES]
        if bad or not self.policies:
            raise InputError(f"unknown or no policy {bad}; choose from {', '.join(POLICIES)}")
        if self.positives_per_object < 1 or not self.negatives_ratio >= 0 or self.epochs < 1 or self.batch_size < 1:
            raise InputError("positives_per_object, epochs and batch_size must be >= 1 and negatives_ratio >= 0")
        if not self.lr > 0:
            raise InputError(f"lr must be > 0, got {self.lr}")
        if not 0 <= self.nms_iou < 1 or not 0 < self.match_iou <= 1:
            raise InputError(f"need 0 <= nms_iou < 1 and 0 < match_iou <= 1, got {self.nms_iou}, {self.match_iou}")
        if not self.cnn_sweep or any(len(dw) != 2 or min(dw) < 1 for dw in self.cnn_sweep):
            raise InputError(f"cnn_sweep needs one or more (depth, width), each at least 1, got {self.cnn_sweep}")
        if self.max_test_images is not None and self.max_test_images < 1:
            raise InputError(f"max_test_images must be >= 1 or None (all), got {self.max_test_images}")
        if self.threads is not None and self.threads < 1:
            raise InputError(f"threads must be >= 1 or None (torch's default), got {self.threads}")


#: 1 and 3 real images: the small and demo data sets (`alcn data detect --conf small|demo`) hold 3 per object.
_SMALL = DetectSettings(positives_per_object=30, epochs=2, cnn_sweep=[(1, 16)], real_images=[1, 3])

#: The named presets of the benchmark (hloc's ``confs``; ``alcn bench detect --conf NAME``), shared: a user takes a
#: copy (:func:`alcn_cv.presets.preset`) and changes that. ``default``: the benchmark; ``small``: a quick
#: end-to-end check (fewer windows and epochs, one plain CNN, no ResNet-56, from 1 and 3 real images per object);
#: ``demo``: ``alcn demo``'s run, ``small`` for no normalization, ALCN and the strongest classical methods.
#: The methods of ``default`` and ``small`` are :func:`default_methods`, the normalizations registered when a run
#: starts, as those of :class:`DetectSettings`.
CONFS: dict[str, DetectSettings] = {
    "default": DetectSettings(),
    "small": _SMALL,
    "demo": dataclasses.replace(
        _SMALL,
        methods=["none", "alcn", "dog", "clahe", "dlcn", "whitening"],
        policies=["local"],
    ),
}

#: One line per preset of :data:`CONFS`, for ``alcn bench detect --help``.
CONF_SUMMARIES: dict[str, str] = {
    "default": "the benchmark: every normalization and the deep baselines but ResNet-56",
    "small": "a quick end-to-end run: fewer windows and epochs, one plain CNN, no ResNet-56, from 1 and 3 real images "
    "per object (as many as the small data hold)",
    "demo": "the run of `alcn demo`: small for none, alcn, dog, clahe, dlcn and whitening, from 1 and 3 real images "
    "per object",
}
