"""Speed of ALCN against the classical normalizations: ``alcn bench speed``.

One run times every method on the same frames, side by side: ``none``, ``clahe``, ``dog`` and
ALCN -- the default of :func:`alcn_cv.createALCN` (``alcn``: the gain Normalizer, its exact Eq. 3
from its grid in OpenCV) and its distilled variant (``alcn gain-lite``), the paper's Normalizer
with the exact Eq. 3 (``alcn exact``), the approximations in between (coarser Normalizer grid,
pyramid mixture, the lite Normalizer, ``alcn lite`` its real-time configuration), and the
default on the other backends (OpenCV DNN, torch on the CPU, torch on CUDA where present) -- on 640x480,
1280x800 and 1920x1080 frames, grayscale and BGR colour, through the OpenCV-style
``apply(uint8 frame)``.

For every case: median and interquartile range of the wall time over repeated runs after a
warm-up, frames per second, and the **ratio to** ``dog`` **measured in the same run** (the
number least sensitive to the load of a shared machine, hence the first column); for ALCN the
split between the Normalizer network (:meth:`~alcn_cv.ALCN.weight_grid`) and the rest of
``normalize`` (map interpolation and the Gaussian mixture); the peak memory of one call (the
peak of NumPy's allocations traced by :mod:`tracemalloc`, and the process' peak resident set
from ``/proc/self/status`` after resetting it). Every approximate variant of the paper's ALCN is
compared with the exact Eq. 3 output of the paper's weights on the same frames (largest and mean
absolute difference of the raw response, also relative to the width of the output range); the
gain Normalizers with their own torch model (a target). The detection accuracy of the lite
configuration against the exact one is measured by ``alcn bench detect --methods
alcn:model=lite,alcn:model=paper:mixture=exact``. A video
test runs ALCN over a generated 1920x1080 video and records the resident memory after every
frame (it must stay flat).

The **targets** (:func:`targets`) come first in the report, each with its measured value: the default ALCN (the gain
Normalizer), its lite variant and the lite paper-family ALCN against a raw OpenCV DoG (:func:`raw_dog`) at 1280x800
(the gain ones with their difference from their torch model) and the default's frame rate at 640x480, the default
(torch-free) backend against the network in torch and the default against DLCN, BGR against gray and its difference
from the plain float Lab round trip (:func:`lab_round_trip`, within one level), the cost of the ``apply`` contract
over each method's own computation, the peak memory on an 8000x8000 image, an application's OpenCV calls right after
``apply``, the default ALCN and a raw DoG in fresh processes with glibc's malloc as it starts and keeping freed
memory (:mod:`alcn_cv.malloc`; the ``alcn`` command, and so this run, keeps it), ``alcn normalize`` on the cookie-
box video against its decoding and encoding alone, and the batched torch path (CUDA when present); with where the
default's time goes (its stages, and a profile).

Outputs in ``out_dir``: ``speed.json`` (every number, the settings, the command, the machine and
its load before and after), ``speed.md`` (machine, command, settings and the tables) and
``speed.png`` (time against pixel count for every method, log-log, :mod:`alcn_cv.bench.plots`).
"""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm.auto import tqdm

from alcn_cv.bench.plots import plot_speed
from alcn_cv.checks import FULL_SCALE
from alcn_cv.data.frames import synthetic_frame
from alcn_cv.enhance.alcn import ALCN
from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import create
from alcn_cv.errors import InputError, WeightFileError
from alcn_cv.filters.lab import lab_and_lightness, srgb_to_lab
from alcn_cv.io import atomic_paths, atomic_write, check_no_earlier_output, holds_out_dir, make_folder, write_json
from alcn_cv.malloc import GLIBC_TUNABLES, glibc_malloc
from alcn_cv.report import command_line, describe_machine, machine, markdown_table
from alcn_cv.shared_data import shared_data_dir
from alcn_cv.weight_file import load_normalizer_file

__all__ = [
    "CONFS",
    "CONF_SUMMARIES",
    "SIDES",
    "SIZES",
    "Method",
    "SpeedSettings",
    "default_methods",
    "lab_round_trip",
    "main",
    "time_calls",
]

logger = logging.getLogger(__name__)

#: Frame sizes (width, height) of the benchmark.
SIZES: tuple[tuple[int, int], ...] = ((640, 480), (1280, 800), (1920, 1080))
QUICK_SIZES: tuple[tuple[int, int], ...] = ((64, 48), (96, 72))
#: The sides (pixels) a timed frame may have, smallest and largest: a frame of 0 pixels is no image, and the
#: largest, 8192x8192 in BGR (192 MiB), leaves the float32 images of the methods in memory (8K is 7680x4320).
SIDES: tuple[int, int] = (16, 8192)
COLOURS = ("gray", "bgr")
#: The exact ALCN: the paper's Normalizer and Eq. 3, the reference of the accuracy table.
EXACT = "alcn exact"
#: The configurations of the paper's ALCN timed (fast backend), each compared with :data:`EXACT`:
#: label -> createALCN parameters. ``model: "lite"`` ones use the distilled Normalizer's weight
#: file (``alcn lite``: its real-time configuration, the pyramid mixture), the others the paper's.
ALCN_VARIANTS: dict[str, dict[str, Any]] = {
    EXACT: {"model": "paper", "mixture": "exact"},
    "alcn pyramid": {"model": "paper", "mixture": "pyramid"},
    "alcn grid16": {"model": "paper", "mixture": "exact", "grid_stride": 16},
    "alcn grid16 pyramid": {"model": "paper", "mixture": "pyramid", "grid_stride": 16},
    "alcn grid32 pyramid": {"model": "paper", "mixture": "pyramid", "grid_stride": 32},
    "alcn lite": {"model": "lite"},
    "alcn lite exact": {"model": "lite", "mixture": "exact"},
}
#: The gain Normalizers (:mod:`alcn_cv.nets.gain`), their own method: ``alcn``, the default of
#: :func:`alcn_cv.createALCN`, and its distilled variant; timed beside the others, not compared
#: with the exact paper ALCN (their difference from their torch model is a target).
GAIN_VARIANTS: dict[str, dict[str, Any]] = {"alcn": {}, "alcn gain-lite": {"model": "gain-lite"}}
REFERENCE = "dog"


@dataclass
class Method:
    """A timed method: a label, how to build it, and whether it is an ALCN variant."""

    label: str
    factory: Callable[[], Normalization]
    params: dict[str, Any] = field(default_factory=dict)
    alcn: bool = False


def _alcn(label: str, weights: str | os.PathLike | None, **params: Any) -> Method:
    """An ALCN variant of ``params``; a weight file given replaces the variant's shipped model."""
    if weights is not None:
        params = {k: v for k, v in params.items() if k != "model"}
    return Method(label, lambda: ALCN(weights=weights, **params), dict(params), alcn=True)


def default_methods(
    weights: str | os.PathLike | None = None, lite_weights: str | os.PathLike | None = None, cuda: bool | None = None
) -> list[Method]:
    """The methods of the benchmark: ``none``, ``clahe``, ``dog``, the configurations of the
    paper's ALCN of :data:`ALCN_VARIANTS` (the paper's Normalizer from ``weights``, the lite one
    from ``lite_weights``) and the gain ones of :data:`GAIN_VARIANTS` (shipped weights), and the
    default ALCN on the other backends (``fast``, ``torch`` on the CPU, and on CUDA when torch sees a GPU or
    ``cuda`` is True)."""
    methods = [Method(name, lambda name=name: create(name)) for name in ("none", "clahe", REFERENCE)]
    methods += [_alcn(label, None, **params) for label, params in GAIN_VARIANTS.items()]
    methods += [
        _alcn(label, weights if params.get("model") == "paper" else lite_weights, **params)
        for label, params in ALCN_VARIANTS.items()
    ]
    methods.append(_alcn("alcn fast", None, backend="fast"))
    methods.append(_alcn("alcn torch cpu", None, backend="torch", device="cpu"))
    if cuda is None:
        import torch

        cuda = torch.cuda.is_available()
    if cuda:
        methods.append(_alcn("alcn torch cuda", None, backend="torch", device="cuda"))
    return methods


def time_calls(fn: Callable[[], Any], warmup: int, min_repeats: int, max_repeats: int, budget_s: float) -> np.ndarray:
    """Wall times (seconds) of ``fn()``: ``warmup`` untimed calls, then at least ``min_repeats``
    and at most ``max_repeats`` timed ones, stopping after ``budget_s`` seconds once the minimum
    is reached."""
    for _ in range(warmup):
        fn()
    times: list[float] = []
    start = time.perf_counter()
    while len(times) < max_repeats and (len(times) < min_repeats or time.perf_counter() - start < budget_s):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return np.array(times)


def _time_rounds(
    calls: dict[str, Callable[[], Any]], min_repeats: int, max_repeats: int, budget_s: float
) -> dict[str, np.ndarray]:
    """Wall times (seconds) of several functions timed in rounds, one call of each per round:
    each gets at least ``min_repeats`` and at most ``max_repeats`` runs and stops after
    ``budget_s`` seconds of its own once it has the minimum (see :func:`time_calls`)."""
    times: dict[str, list[float]] = {label: [] for label in calls}

    def done(label: str) -> bool:
        t = times[label]
        return len(t) >= max_repeats or (len(t) >= min_repeats and sum(t) >= budget_s)

    while not all(done(label) for label in calls):
        for label, fn in calls.items():
            if not done(label):
                t0 = time.perf_counter()
                fn()
                times[label].append(time.perf_counter() - t0)
    return {label: np.array(t) for label, t in times.items()}


def _stats(times: np.ndarray) -> dict[str, float]:
    q1, median, q3 = np.percentile(times * 1e3, [25, 50, 75])
    return {
        "median_ms": float(median),
        "iqr_ms": float(q3 - q1),
        "q1_ms": float(q1),
        "q3_ms": float(q3),
        "min_ms": float(times.min() * 1e3),
        "fps": float(1e3 / median),
        "repeats": int(len(times)),
    }


def _rss_kb(field_name: str = "VmRSS") -> int | None:
    """A memory field of ``/proc/self/status`` in kB (None where there is no /proc)."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith(field_name + ":"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def _reset_peak_rss() -> bool:
    """Reset the process' peak resident set (VmHWM) to its current size (Linux >= 4.0)."""
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as f:
            f.write("5")
        return True
    except OSError:
        return False


def peak_memory(fn: Callable[[], Any]) -> dict[str, float | None]:
    """Memory of one call of ``fn``: ``traced_peak_mb``, the peak of the Python/NumPy allocations
    made during the call (tracemalloc; OpenCV's and torch's own buffers are not traced);
    ``rss_before_mb``, the process' resident set before the call; ``rss_peak_mb``, its peak
    resident set during the call; ``rss_added_mb``, the difference (None where /proc or the
    reset of the peak is unavailable)."""
    before = _rss_kb()
    can_reset = _reset_peak_rss()
    tracemalloc.start()
    try:
        fn()
        _, traced_peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    peak = _rss_kb("VmHWM") if can_reset else None
    return {
        "traced_peak_mb": traced_peak / 2**20,
        "rss_before_mb": None if before is None else before / 1024,
        "rss_peak_mb": None if peak is None else peak / 1024,
        "rss_added_mb": None if peak is None or before is None else max(0.0, (peak - before) / 1024),
    }


def _split(
    norm: ALCN, gray: np.ndarray, repeats: int, budget_s: float
) -> tuple[dict[str, float], np.ndarray, np.ndarray]:
    """Median times of the Normalizer network (:meth:`ALCN.weight_grid`) and of the whole
    ``normalize``, run in turns 1 to ``repeats`` times (stopping after ``budget_s`` seconds);
    the rest of ``normalize`` is map interpolation and the mixture.

    Returns:
        The times (ms), the network's grid and the normalized image.
    """
    network, total = [], []
    start = time.perf_counter()
    while not network or (len(network) < repeats and time.perf_counter() - start < budget_s):
        t0 = time.perf_counter()
        grid = norm.weight_grid(gray)
        t1 = time.perf_counter()
        out = norm.normalize(gray)
        network.append(t1 - t0)
        total.append(time.perf_counter() - t1)
    net_ms, total_ms = float(np.median(network) * 1e3), float(np.median(total) * 1e3)
    times = {"network_ms": net_ms, "mixture_ms": max(0.0, total_ms - net_ms), "normalize_ms": total_ms}
    return times, grid, out


def _to_gray(frame: np.ndarray) -> np.ndarray:
    """The float32 intensities ALCN's ``normalize`` sees for a uint8 frame (gray: the frame;
    colour: CIE L / 100, as :meth:`Normalization.apply` does)."""
    if frame.ndim == 2:
        return frame.astype(np.float32) / np.float32(255)
    return lab_and_lightness(frame)[1]


def video_memory(norm: Normalization, size: tuple[int, int], frames: int, budget_s: float) -> dict[str, Any]:
    """Resident memory while ``norm`` normalizes a generated grayscale video frame after frame.

    Frames are :func:`synthetic_frame` (gray) with the light moving; the loop stops after ``frames``
    frames or ``budget_s`` seconds (at least 2 frames). Returns the RSS after every frame (MB),
    its first, last and largest value, the growth per frame (least-squares slope over the
    second half, kB per frame) and the frames run; where there is no ``/proc`` (macOS, Windows), no RSS: an empty
    list and None.
    """
    width, height = size
    base = [synthetic_frame(width, height, False, seed=1, t=0.1 * i) for i in range(4)]
    rss: list[float] = []
    times: list[float] = []
    start = time.perf_counter()
    for i in range(frames):
        frame = base[i % len(base)]
        t0 = time.perf_counter()
        norm.apply(frame)
        times.append(time.perf_counter() - t0)
        value = _rss_kb()
        if value is not None:  # no /proc (macOS, Windows): no resident set recorded
            rss.append(value / 1024)
        if i >= 1 and time.perf_counter() - start > budget_s:
            break
    half = np.array(rss[len(rss) // 2 :])
    slope = float(np.polyfit(np.arange(len(half)), half, 1)[0] * 1024) if len(half) >= 2 else None
    return {
        "size": [width, height],
        "colour": False,
        "frames": len(times),
        "median_frame_ms": float(np.median(times) * 1e3),
        "rss_mb": [round(v, 2) for v in rss],
        "rss_first_mb": rss[0] if rss else None,
        "rss_last_mb": rss[-1] if rss else None,
        "rss_max_mb": max(rss) if rss else None,
        "growth_kb_per_frame": slope,
    }


def _accuracy(approx: np.ndarray, exact: np.ndarray, output_range: Sequence[float]) -> dict[str, float]:
    diff = np.abs(approx.astype(np.float64) - exact)
    span = float(output_range[1] - output_range[0])
    return {
        "max_abs": float(diff.max()),
        "mean_abs": float(diff.mean()),
        "max_rel_range": float(diff.max() / span),
        "mean_rel_range": float(diff.mean() / span),
        "exact_std": float(exact.std()),
    }


@dataclass
class SpeedSettings:
    """Settings of a speed benchmark run (all recorded in ``speed.json``).

    Attributes:
        sizes: frame sizes ``(width, height)``.
        colours: ``"gray"`` and/or ``"bgr"``.
        methods: labels of :func:`default_methods` to run (default: all; ``dog`` is always
            run, it is the reference of the ratios).
        weights: Normalizer weight file of the paper-model ALCN variants (default: the shipped one).
        lite_weights: weight file of the ``lite`` variants (default: the shipped lite one).
        image: an image file resized to every size instead of :func:`synthetic_frame`.
        warmup, min_repeats, max_repeats, budget_s: see :func:`time_calls` (per case).
        video_frames, video_budget_s: the video-memory test (grayscale; 0 frames: skip).
        target_size, fps_size, target_repeats: frame sizes and timed rounds of the targets
            (:func:`targets`: the default against a raw DoG, BGR against gray, the overhead of
            ``apply``, the OpenCV calls after ``apply``, the batched torch path).
        large_size: the large grayscale image of the peak-memory target.
        normalize_video, normalize_video_frames: the video of the ``alcn normalize`` target
            (default: the shared cookie-box video when present, else a generated one of
            ``normalize_video_frames`` frames of ``fps_size``).
        video_size: frame size ``(width, height)`` of the video-memory test.
        video_methods: labels run in the video test (default: ``alcn`` and the fastest variant).
        threads: OpenCV and torch threads (default: their defaults).
        device, device_batches: with a device, only the batched torch path on it is measured, at ``target_size``
            with these batch sizes (:mod:`alcn_cv.bench.device_speed`).
    """

    sizes: list[tuple[int, int]] = field(default_factory=lambda: list(SIZES))
    colours: list[str] = field(default_factory=lambda: list(COLOURS))
    methods: list[str] | None = None
    weights: str | None = None
    lite_weights: str | None = None
    image: str | None = None
    warmup: int = 1
    min_repeats: int = 3
    max_repeats: int = 15
    budget_s: float = 10.0
    video_frames: int = 100
    video_budget_s: float = 180.0
    video_size: tuple[int, int] = SIZES[-1]
    video_methods: list[str] | None = None
    threads: int | None = None
    target_size: tuple[int, int] = (1280, 800)
    fps_size: tuple[int, int] = (640, 480)
    target_repeats: int = 31
    large_size: tuple[int, int] = (8000, 8000)
    normalize_video: str | None = None
    normalize_video_frames: int = 0
    device: str | None = None
    device_batches: list[int] = field(default_factory=lambda: [1, 8, 64, 128])

    def check(self) -> None:
        """Raise :class:`~alcn_cv.errors.InputError` on an unknown colour, a frame side (``sizes``, ``video_size``)
        outside :data:`SIDES`, a negative warm-up, settings that time no run (a median of none: ``max_repeats`` or
        ``target_repeats`` below 1, or ``min_repeats`` below 1 without a time budget), more ``min_repeats`` than
        ``max_repeats``, a negative budget or video frame count, fewer than one thread, or, with a device, no batch
        size or one below 1."""
        low, high = SIDES
        bad_sizes = [size for size in [*self.sizes, self.video_size] if not all(low <= side <= high for side in size)]
        if bad_sizes or not self.sizes:
            raise InputError(
                f"frame sides (--sizes, --video-size) must be from {low} to {high} pixels, got "
                + (", ".join(f"{w}x{h}" for w, h in bad_sizes) or "no size")
            )
        bad = [c for c in self.colours if c not in COLOURS]
        if bad or not self.colours:
            raise InputError(f"colours must be among {COLOURS}, got {list(self.colours)}")
        if self.warmup < 0 or min(self.max_repeats, self.target_repeats) < 1:
            raise InputError(
                f"need warmup >= 0 and max_repeats (--repeats) and target_repeats >= 1, got {self.warmup}, "
                f"{self.max_repeats} and {self.target_repeats}"
            )
        if self.min_repeats < 1 and not self.budget_s > 0:
            raise InputError(
                f"min_repeats {self.min_repeats} with a budget of {self.budget_s} s times no run: give min_repeats >= 1"
            )
        if self.min_repeats > self.max_repeats:  # the command line caps a preset's minimum at --repeats alone
            raise InputError(f"--min-repeats {self.min_repeats} is more than --repeats {self.max_repeats}")
        if not min(self.budget_s, self.video_budget_s) >= 0 or self.video_frames < 0:
            raise InputError(
                "budget_s (--budget), video_budget_s (--video-budget) and video_frames (--video-frames) must be >= 0, "
                f"got {self.budget_s}, {self.video_budget_s} and {self.video_frames}"
            )
        if self.threads is not None and self.threads < 1:
            raise InputError(f"threads must be >= 1 or None (their defaults), got {self.threads}")
        if self.device is not None and (not self.device_batches or min(self.device_batches) < 1):
            raise InputError(f"device_batches must be batch sizes >= 1, got {self.device_batches}")


#: The named presets of the benchmark (hloc's ``confs``; ``alcn bench speed --conf NAME``), shared: a user takes a
#: copy (:func:`alcn_cv.presets.preset`) and changes that. ``default``: the benchmark; ``quick``: tiny frames,
#: 2 repeats, no warm-up, a 3-frame video of tiny frames (seconds, for tests).
CONFS: dict[str, SpeedSettings] = {
    "default": SpeedSettings(),
    "quick": SpeedSettings(
        sizes=list(QUICK_SIZES),
        warmup=0,
        min_repeats=2,
        max_repeats=2,
        budget_s=0.0,
        video_frames=3,
        video_budget_s=10.0,
        video_size=QUICK_SIZES[-1],
        target_size=QUICK_SIZES[-1],
        fps_size=QUICK_SIZES[0],
        target_repeats=2,
        large_size=(256, 192),
        normalize_video="generated",
        normalize_video_frames=4,
        device_batches=[1, 2],
    ),
}

#: One line per preset of :data:`CONFS`, for ``alcn bench speed --help``.
CONF_SUMMARIES: dict[str, str] = {
    "default": "the benchmark: the frame sizes, repeats and video test of the options' defaults",
    "quick": "tiny frames and few repeats (seconds; for tests)",
}


def speed_command(out_dir: str | os.PathLike, settings: SpeedSettings) -> str:
    """The ``alcn bench speed`` command line that runs these settings."""
    return command_line(
        ["alcn", "bench", "speed", "--out", out_dir],
        {
            "--sizes": [f"{w}x{h}" for w, h in settings.sizes],
            "--colours": settings.colours,
            "--methods": settings.methods,
            "--weights": settings.weights,
            "--lite-weights": settings.lite_weights,
            "--image": settings.image,
            "--warmup": settings.warmup,
            "--min-repeats": settings.min_repeats,
            "--repeats": settings.max_repeats,
            "--budget": settings.budget_s,
            "--video-frames": settings.video_frames,
            "--video-budget": settings.video_budget_s,
            "--video-size": "x".join(map(str, settings.video_size)),
            "--video-methods": settings.video_methods,
            "--threads": settings.threads,
            "--device": settings.device,
            "--device-batches": ",".join(map(str, settings.device_batches)) if settings.device else None,
        },
    )


def _select_methods(settings: SpeedSettings) -> list[Method]:
    """The methods of :func:`default_methods` that the settings name, and ``dog``.

    Raises:
        InputError: an unknown label, or a label of ``video_methods`` that is not among them.
    """
    methods = default_methods(settings.weights, settings.lite_weights)
    labels = [m.label for m in methods]
    if settings.methods is not None:
        unknown = [m for m in settings.methods if m not in labels]
        if unknown:
            raise InputError(f"unknown method(s) {unknown}; available: {', '.join(labels)}")
        keep = set(settings.methods) | {REFERENCE}
        methods = [m for m in methods if m.label in keep]
    selected = [m.label for m in methods]
    unknown = [m for m in settings.video_methods or [] if m not in selected]
    if unknown:
        raise InputError(f"video method(s) {unknown} are not among this run's methods: {', '.join(selected)}")
    return methods


def _frame_source(image: str | os.PathLike | None) -> Callable[[int, int, str], np.ndarray]:
    """``frame(width, height, colour)``: the image resized, or :func:`synthetic_frame`."""
    if image is None:
        return lambda width, height, colour: synthetic_frame(width, height, colour == "bgr")
    try:  # decoded from the bytes Python read: cv2.imread opens a path by a narrow string (Windows' code page)
        source = cv2.imdecode(np.fromfile(image, np.uint8), cv2.IMREAD_COLOR)
    except OSError as exc:
        raise InputError(f"cannot read image {image}: {exc.strerror}") from None
    if source is None:
        raise InputError(f"cannot read image {image}")

    def frame(width: int, height: int, colour: str) -> np.ndarray:
        resized = cv2.resize(source, (width, height), interpolation=cv2.INTER_AREA)
        return resized if colour == "bgr" else cv2.cvtColor(resized, cv2.COLOR_BGR2GRAY)

    return frame


def _ready(
    methods: list[Method], built: dict[str, Normalization], errors: dict[str, str], frame: np.ndarray, warmup: int
) -> dict[str, tuple[Method, Normalization]]:
    """Build (once) and warm up every method on the frame; a method that fails is recorded in
    ``errors`` and left out from then on."""
    ready: dict[str, tuple[Method, Normalization]] = {}
    for method in methods:
        if method.label in errors:
            continue
        try:
            norm = built.get(method.label) or built.setdefault(method.label, method.factory())
            for _ in range(warmup):
                norm.apply(frame)
        except Exception as exc:  # a backend this machine cannot run: report it, go on
            logger.warning("%s failed: %s", method.label, exc)
            errors[method.label] = f"{type(exc).__name__}: {exc}"
            continue
        ready[method.label] = (method, norm)
    return ready


def _time_case(
    ready: dict[str, tuple[Method, Normalization]],
    frame: np.ndarray,
    colour: str,
    settings: SpeedSettings,
    progress: tqdm,
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The timing rows of one frame size and colour, and the accuracy rows of the ALCN
    variants against the exact one (grayscale frames only)."""
    height, width = frame.shape[:2]
    gray = _to_gray(frame)
    # The methods are timed in rounds (one call of each per round) so that all of them see the
    # same load of a shared machine.
    times = _time_rounds(
        {label: (lambda norm=norm: norm.apply(frame)) for label, (_, norm) in ready.items()},
        settings.min_repeats,
        settings.max_repeats,
        settings.budget_s,
    )
    rows, outputs, map_std = [], {}, float("nan")
    for label, (method, norm) in ready.items():
        progress.set_postfix_str(f"{label} {width}x{height} {colour}")
        progress.update()
        row: dict[str, Any] = {
            "method": label,
            "params": method.params,
            "width": width,
            "height": height,
            "pixels": width * height,
            "colour": colour,
            **_stats(times[label]),
        }
        if isinstance(norm, ALCN):
            split, grid, result = _split(norm, gray, settings.min_repeats, settings.budget_s)
            row.update(split)
            if colour == "gray" and label in ALCN_VARIANTS:
                outputs[label] = result.astype(np.float64)
                if label == EXACT:
                    # How much the weight maps vary over the frame: coarser grids cost nothing
                    # in accuracy when they are constant (an untrained Normalizer).
                    map_std = float(grid.std(axis=(1, 2)).mean())
        row.update(peak_memory(lambda norm=norm: norm.apply(frame)))
        rows.append(row)
    accuracy = []
    if EXACT in outputs:
        exact_norm = ready[EXACT][1]
        accuracy = [
            {
                "method": label,
                "params": ready[label][0].params,
                "width": width,
                "height": height,
                "exact_map_std": map_std,
                **_accuracy(out, outputs[EXACT], exact_norm.output_range),
            }
            for label, out in outputs.items()
            if label != EXACT
        ]
    reference = next((r["median_ms"] for r in rows if r["method"] == REFERENCE), None)
    for row in rows:
        row["ratio_to_dog"] = None if reference is None else row["median_ms"] / reference
    return rows, accuracy


def _video_test(
    methods: list[Method],
    built: dict[str, Normalization],
    errors: dict[str, str],
    rows: list[dict[str, Any]],
    settings: SpeedSettings,
) -> list[dict[str, Any]]:
    """Memory over a generated video of the chosen ALCN variants (default: ``alcn`` and the
    fastest variant on the largest grayscale frames)."""
    if settings.video_frames <= 0:
        return []
    alcn_labels = [m.label for m in methods if m.alcn and m.label not in errors]
    video_methods = settings.video_methods
    if video_methods is None:
        gray = [r for r in rows if r["method"] in alcn_labels and r["colour"] == "gray"]
        fastest = min(gray, key=lambda r: (-r["pixels"], r["median_ms"]))["method"] if gray else None
        video_methods = [label for label in dict.fromkeys(["alcn", fastest]) if label in alcn_labels]
    for label in (label for label in video_methods if label in errors):
        logger.warning("video memory: %s left out, it failed to run (%s)", label, errors[label])
    video_methods = [label for label in video_methods if label not in errors]
    video = []
    for label in video_methods:
        if label not in built:
            built[label] = next(m for m in methods if m.label == label).factory()
        logger.info("video memory: %s on %dx%d", label, *settings.video_size)
        video.append(
            {
                "method": label,
                **video_memory(built[label], settings.video_size, settings.video_frames, settings.video_budget_s),
            }
        )
    return video


# --- The targets: ratios taken in one run, the methods timed in turns ------------------------


def raw_dog(frame: np.ndarray) -> np.ndarray:
    """The reference of the targets: a raw OpenCV DoG (uint8 to float32, two ``cv2.GaussianBlur``
    of sigma 0.5 and 1.5, subtract), what an application would write by hand."""
    unit = frame.astype(np.float32) * np.float32(1 / 255)
    return cv2.GaussianBlur(unit, (0, 0), 0.5) - cv2.GaussianBlur(unit, (0, 0), 1.5)


def lab_round_trip(method: Normalization, img: np.ndarray, out_dtype: np.dtype | None = None) -> np.ndarray:
    """The reference of ``apply``'s colour path, written plainly: a BGR image decoded to linear intensities and
    converted to float CIE Lab (:mod:`alcn_cv.filters.lab`), L / 100 normalized (:meth:`Normalization.normalize`)
    and mapped to [0, 1] (``to_unit``), times 100 back into L, Lab to BGR, clipped and converted with NumPy (``rint``
    for integer types)."""
    out_dtype = np.dtype(img.dtype if out_dtype is None else out_dtype)
    unit = img.astype(np.float32) * np.float32(1 / FULL_SCALE[img.dtype]) if img.dtype != np.float32 else img.copy()
    lab = srgb_to_lab(unit)
    lightness = np.ascontiguousarray(lab[..., 0]) * np.float32(0.01)
    lab[..., 0] = method.to_unit(method.normalize(lightness)) * 100.0
    bgr = np.clip(cv2.cvtColor(lab, cv2.COLOR_Lab2BGR), 0, 1)
    return bgr if out_dtype == np.float32 else np.rint(bgr * FULL_SCALE[out_dtype]).astype(out_dtype)


def _medians(calls: dict[str, Callable[[], Any]], repeats: int) -> dict[str, float]:
    """Median milliseconds of each call, timed in turns (one call of each per round) after one warm-up."""
    for fn in calls.values():
        fn()
    return {label: float(np.median(t) * 1e3) for label, t in _time_rounds(calls, repeats, repeats, 0.0).items()}


def _target(name: str, measured: float | None, goal: str, met: bool | None, note: str = "") -> dict[str, Any]:
    return {"target": name, "measured": measured, "goal": goal, "met": met, "note": note}


def _profile(norm: ALCN, frame: np.ndarray, calls: int) -> list[dict[str, Any]]:
    """The functions where ``apply`` spends its time (cProfile, own time per call), largest first."""
    import cProfile
    import pstats

    profiler = cProfile.Profile()
    profiler.enable()
    for _ in range(calls):
        norm.apply(frame)
    profiler.disable()
    stats = pstats.Stats(profiler).stats  # type: ignore[attr-defined]
    rows = [
        {
            "function": f"{Path(file).name}:{line}({fn})" if file != "~" else fn,
            "calls_per_apply": nc / calls,
            "own_ms_per_apply": tt * 1e3 / calls,
        }
        for (file, line, fn), (_, nc, tt, _, _) in stats.items()
    ]
    return sorted(rows, key=lambda r: -r["own_ms_per_apply"])[:12]


def _stages(norm: ALCN, frame: np.ndarray, repeats: int) -> dict[str, float]:
    """Median ms of ALCN's stages on a gray uint8 frame, timed in turns: the Normalizer network
    (``weight_grid``, with the working-scale resize), the mixture (``normalize`` minus the
    network), the ``apply`` contract (``apply`` minus ``normalize``)."""
    gray = frame.astype(np.float32) / np.float32(255)
    t = _medians(
        {
            "network": lambda: norm.weight_grid(gray),
            "normalize": lambda: norm.normalize(gray),
            "apply": lambda: norm.apply(frame),
        },
        repeats,
    )
    return {
        "network_ms": t["network"],
        "mixture_ms": max(0.0, t["normalize"] - t["network"]),
        "contract_ms": max(0.0, t["apply"] - t["normalize"]),
        "apply_ms": t["apply"],
    }


def _contract_overhead(frame: np.ndarray, repeats: int) -> list[dict[str, Any]]:
    """For every registered method: ``apply(uint8 frame)`` against the method's own computation
    (``_normalize`` on the float32 intensities), timed in turns."""
    from alcn_cv.enhance.registry import available

    gray = frame.astype(np.float32) / np.float32(255)
    rows = []
    for name in available():
        method = create(name)
        calls = {
            "apply": lambda method=method: method.apply(frame),
            "own": lambda method=method: method._normalize(gray),
        }
        for fn in calls.values():
            fn()
        times = _time_rounds(calls, 3, repeats, 2.0)  # at most about 2 s each: sqi takes seconds
        t = {label: float(np.median(v) * 1e3) for label, v in times.items()}
        fastest = {label: float(v.min() * 1e3) for label, v in times.items()}
        # The fastest runs are the least disturbed by a shared machine's load: the overhead is
        # taken from them, the medians are reported beside.
        rows.append(
            {
                "method": name,
                "apply_ms": t["apply"],
                "own_ms": t["own"],
                "apply_min_ms": fastest["apply"],
                "own_min_ms": fastest["own"],
                "overhead": fastest["apply"] / fastest["own"] - 1 if fastest["own"] > 0 else None,
                "overhead_of_medians": t["apply"] / t["own"] - 1 if t["own"] > 0 else None,
            }
        )
    return rows


def _after_apply(frame: np.ndarray, repeats: int, threads: int | None) -> dict[str, Any]:
    """An application's own OpenCV calls (a Gaussian blur and Canny on the frame) timed right after
    ``apply`` and right after themselves, in turns, with the Normalizer on ``threads`` torch threads."""
    import torch

    norm = ALCN(backend="fast", threads=threads)
    before_threads = torch.get_num_threads()

    def app() -> None:
        cv2.GaussianBlur(frame, (0, 0), 2.0)
        cv2.Canny(frame, 50, 150)

    after, alone, applied = [], [], []
    norm.apply(frame)
    app()
    for _ in range(repeats):
        app()
        t0 = time.perf_counter()
        app()
        alone.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        norm.apply(frame)
        applied.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        app()
        after.append(time.perf_counter() - t0)
    alone_ms, after_ms = float(np.median(alone) * 1e3), float(np.median(after) * 1e3)
    return {
        "threads": threads,
        "app_ms": alone_ms,
        "app_after_apply_ms": after_ms,
        "ratio": after_ms / alone_ms,
        "apply_ms": float(np.median(applied) * 1e3),
        "torch_threads_kept": torch.get_num_threads() == before_threads,
    }


def fresh_process_main() -> None:
    """The child of :func:`_fresh_processes`: ``argv`` is a frame (``.npy``), a method (``alcn``, the default ALCN,
    or ``dog``, a raw DoG) and a number of calls; prints the median ms per call after the first and the page faults
    per call as JSON."""
    import resource  # Unix only: the parent runs this on glibc alone

    frame, method, calls = np.load(sys.argv[1]), sys.argv[2], int(sys.argv[3])
    fn = ALCN().apply if method == "alcn" else raw_dog
    fn(frame)
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    times = time_calls(lambda: fn(frame), 0, calls, calls, 0.0)
    faults = (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults) / calls
    print(json.dumps({"ms": float(np.median(times) * 1e3), "page_faults_per_call": faults}))


def _fresh_processes(frame: np.ndarray, work: Path, calls: int) -> dict[str, dict[str, Any]]:
    """The default ALCN and a raw DoG on ``frame``, each timed in a fresh Python process (:func:`fresh_process_main`)
    as an application that starts, builds it and normalizes frames sees them: with glibc's malloc as it starts, and
    with it keeping freed memory (:data:`~alcn_cv.malloc.GLIBC_TUNABLES`, as :func:`~alcn_cv.malloc.keep_freed_memory`
    does, and as this process runs)."""
    path = work / "fresh_process_frame.npy"
    np.save(path, frame)
    code = "from alcn_cv.bench.speed import fresh_process_main; fresh_process_main()"
    result: dict[str, dict[str, Any]] = {}
    for malloc, tunables in (("glibc", None), ("kept", GLIBC_TUNABLES)):
        env = {k: v for k, v in os.environ.items() if k != "GLIBC_TUNABLES"}
        if tunables:
            env["GLIBC_TUNABLES"] = tunables
        for method in ("alcn", "dog"):
            argv = [sys.executable, "-c", code, str(path), method, str(calls)]
            done = subprocess.run(argv, env=env, capture_output=True, text=True, check=True)
            result[f"{method} {malloc}"] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def _large_memory(size: tuple[int, int]) -> list[dict[str, Any]]:
    """Peak memory of ``apply`` on a large grayscale uint8 image (a synthetic frame tiled), for the
    default ALCN and the DoG, against the image's float32 size."""
    width, height = size
    tile = synthetic_frame(min(width, 1280), min(height, 800), False)
    image = np.ascontiguousarray(
        np.tile(tile, (-(-height // tile.shape[0]), -(-width // tile.shape[1])))[:height, :width]
    )
    float_mb = image.size * 4 / 2**20
    rows = []
    for label, norm in (("alcn", ALCN()), ("dog", create("dog"))):
        t0 = time.perf_counter()
        memory = peak_memory(lambda norm=norm: norm.apply(image))
        added = memory["rss_added_mb"]
        rows.append(
            {
                "method": label,
                "size": [width, height],
                "seconds": time.perf_counter() - t0,
                "float32_mb": float_mb,
                **memory,
                "added_per_float32": None if added is None else added / float_mb,
                "strips": len(norm._strips(image.shape) or []),
            }
        )
    return rows


#: Turns of the ``alcn normalize`` target's three timings (the fastest of each kept): one pass of a 455-frame
#: video moved their ratio by 0.3 from run to run on the same code.
VIDEO_TURNS = 3


def _normalize_video(settings: SpeedSettings, work: Path, progress: bool = True) -> dict[str, Any]:
    """``alcn normalize`` on a video (:func:`alcn_cv.io.map_video` with the default's ``apply``, what
    the command runs) against its decoding and encoding alone and ``apply`` alone: :data:`VIDEO_TURNS` turns of
    the three, the fastest of each."""
    from alcn_cv.io import VideoReader, map_video, open_video_writer

    source = settings.normalize_video
    shared = shared_data_dir() / "cookie_box" / "box.mp4"
    if source is None and shared.is_file():
        source = str(shared)
    if source is None or source == "generated":
        width, height = settings.fps_size
        source = str(work / "generated.avi")
        writer = open_video_writer(source, 30.0, (width, height))
        for i in range(max(2, settings.normalize_video_frames)):
            writer.write(synthetic_frame(width, height, True, seed=1, t=0.1 * i))
        writer.close()
    with VideoReader(source) as video:
        frames = list(video)
    norm = ALCN()
    codec_s = apply_s = whole_s = float("inf")
    for _ in range(VIDEO_TURNS):
        t0 = time.perf_counter()
        map_video(source, work / "copy.mp4", lambda frame: frame, desc="decode+encode", progress=progress)
        codec_s = min(codec_s, time.perf_counter() - t0)
        t0 = time.perf_counter()
        for frame in frames:
            norm.apply(frame)
        apply_s = min(apply_s, time.perf_counter() - t0)
        t0 = time.perf_counter()
        map_video(source, work / "normalized.mp4", create("alcn").apply, desc="alcn normalize", progress=progress)
        whole_s = min(whole_s, time.perf_counter() - t0)
    return {
        "video": source,
        "frames": len(frames),
        "size": [frames[0].shape[1], frames[0].shape[0]],
        "decode_encode_s": codec_s,
        "apply_s": apply_s,
        "normalize_s": whole_s,
        "sequential_s": codec_s + apply_s,
        "bound_s": max(codec_s, apply_s),
        "normalize_fps": len(frames) / whole_s,
    }


def _batched(frame: np.ndarray, small: np.ndarray, repeats: int) -> dict[str, Any]:
    """The batched torch path (:meth:`ALCN.apply_batch`, the exact Eq. 3): on CUDA when torch sees
    a GPU (batches of 16 frames), and on the CPU (2 small frames: there it only checks the
    path); ms per frame, and the float16 network's difference from float32."""
    import torch

    result: dict[str, Any] = {"cuda_available": torch.cuda.is_available()}
    cases = [("cpu", np.stack([small] * 2), 2)]
    if torch.cuda.is_available():
        cases.append(("cuda", np.stack([frame] * 16), repeats))
    for device, batch, rounds in cases:
        norm = ALCN(backend="torch", device=device)
        full = norm.apply_batch(batch, out_dtype=np.float32)
        half = norm.apply_batch(batch, out_dtype=np.float32, half=True)
        t = _medians(
            {
                "float32": lambda norm=norm, batch=batch: norm.apply_batch(batch),
                "float16": lambda norm=norm, batch=batch: norm.apply_batch(batch, half=True),
            },
            rounds,
        )
        result[device] = {
            "size": [batch.shape[2], batch.shape[1]],
            "batch": len(batch),
            "ms_per_frame": t["float32"] / len(batch),
            "ms_per_frame_half": t["float16"] / len(batch),
            "fps": 1e3 * len(batch) / t["float32"],
            "half_max_abs": float(np.abs(half - full).max()),
        }
    return result


def _gain_error(gain: ALCN, frame: np.ndarray) -> float:
    """Largest difference of a gain ALCN's ``normalize`` from its torch model's output
    (:meth:`GainNormalizer.forward <alcn_cv.nets.gain.GainNormalizer.forward>`) on a uint8 frame."""
    import torch

    from alcn_cv.nets.lite import normalizer_from_file
    from alcn_cv.weight_file import load_normalizer_file

    model = normalizer_from_file(load_normalizer_file(gain.weights_path))
    gray = frame.astype(np.float32) / np.float32(255)
    with torch.inference_mode():
        expected = model(torch.from_numpy(gray)[None, None])[0, 0].numpy()
    return float(np.abs(gain.normalize(gray) - expected).max())


def targets(settings: SpeedSettings, work: Path, progress: bool = True) -> dict[str, Any]:
    """Every target of the real-time work, measured in this run (ratios of medians of methods
    timed in turns, so that they see the same load)."""
    width, height = settings.target_size
    gray, bgr = synthetic_frame(width, height, False), synthetic_frame(width, height, True)
    small = synthetic_frame(*settings.fps_size, False)
    default, gain_lite, lite = ALCN(), ALCN(model="gain-lite"), ALCN(model="lite")
    torch_network, torch_cpu, dlcn = ALCN(backend="fast"), ALCN(backend="torch", device="cpu"), create("dlcn")
    repeats = settings.target_repeats
    logger.info("targets: ratios at %dx%d", width, height)
    t = _medians(
        {
            "dog raw": lambda: raw_dog(gray),
            "dlcn gray": lambda: dlcn.apply(gray),
            "alcn gray": lambda: default.apply(gray),
            "alcn fast gray": lambda: torch_network.apply(gray),
            "alcn bgr": lambda: default.apply(bgr),
            "alcn fast bgr": lambda: torch_network.apply(bgr),
            "alcn gain-lite gray": lambda: gain_lite.apply(gray),
            "alcn lite gray": lambda: lite.apply(gray),
            "alcn lite bgr": lambda: lite.apply(bgr),
            "dog raw small": lambda: raw_dog(small),
            "alcn gray small": lambda: default.apply(small),
            # in the same turns: its CPU inference is apply()'s runtime, and leaves no torch threads spinning
            "alcn torch gray": lambda: torch_cpu.apply(gray),
        },
        repeats,
    )
    logger.info("targets: stages, contract, threads, memory, video, batches")
    stages = {
        "alcn": _stages(default, gray, repeats),
        "alcn gain-lite": _stages(gain_lite, gray, repeats),
        "alcn lite": _stages(lite, gray, repeats),
    }
    profile = _profile(default, gray, repeats)
    contract = _contract_overhead(gray, max(3, repeats // 2))
    threads = [_after_apply(gray, repeats, 1), _after_apply(gray, repeats, None)]
    fresh = _fresh_processes(gray, work, max(5, 2 * repeats)) if glibc_malloc() else {}  # glibc's thresholds alone
    memory = _large_memory(settings.large_size)
    video = _normalize_video(settings, work, progress)
    batched = _batched(gray, small, repeats)
    ratio, gain_lite_ratio, lite_ratio = (t[f"alcn{m} gray"] / t["dog raw"] for m in ("", " gain-lite", " lite"))
    fps = 1e3 / t["alcn gray small"]
    colour = t["alcn bgr"] / t["alcn gray"]
    torch_free_ratio, dlcn_ratio = t["alcn gray"] / t["alcn fast gray"], t["alcn gray"] / t["dlcn gray"]
    torch_cpu_ratio = t["alcn torch gray"] / t["alcn gray"]
    gain_error, gain_lite_error = _gain_error(default, gray), _gain_error(gain_lite, gray)
    colour_levels = max(
        int(np.abs(norm.apply(bgr).astype(np.int16) - lab_round_trip(norm, bgr)).max()) for norm in (default, lite)
    )
    worst = max(
        (r for r in contract if r["method"] != "none" and r["overhead"] is not None), key=lambda r: r["overhead"]
    )
    alcn_memory = next(r for r in memory if r["method"] == "alcn")
    size = f"{width}x{height}"
    fresh_target = []
    if fresh:  # glibc's thresholds: Linux only
        fresh_target.append(
            _target(
                f"default ALCN in a fresh process: glibc's malloc as it starts / keeping freed memory, {size} gray",
                fresh["alcn glibc"]["ms"] / fresh["alcn kept"]["ms"],
                "1 with alcn_cv.keep_freed_memory()",
                None,
                f"{fresh['alcn glibc']['ms']:.2f} ms against {fresh['alcn kept']['ms']:.2f} "
                f"({fresh['alcn glibc']['page_faults_per_call']:.0f} page faults per call against "
                f"{fresh['alcn kept']['page_faults_per_call']:.0f}); raw DoG {fresh['dog glibc']['ms']:.2f} against "
                f"{fresh['dog kept']['ms']:.2f} ms",
            )
        )
    summary = [
        _target(
            f"default ALCN (the gain Normalizer) / raw DoG, {size} gray",
            ratio,
            "<= 2 (stretch 1.5)",
            ratio <= 2,
            f"{t['alcn gray']:.2f} ms against {t['dog raw']:.2f} ms; "
            f"largest difference from the torch model's output: {gain_error:.1e}",
        ),
        _target(
            f"default ALCN / raw DoG, {size} gray: real time (issue 15)", ratio, "<= 4", ratio <= 4, "the same ratio"
        ),
        _target(
            f"its lite variant (alcn:model=gain-lite) / raw DoG, {size} gray",
            gain_lite_ratio,
            "<= 4",
            gain_lite_ratio <= 4,
            f"{t['alcn gain-lite gray']:.2f} ms; "
            f"largest difference from the torch model's output: {gain_lite_error:.1e}",
        ),
        _target(
            f"lite paper-family ALCN (alcn:model=lite, pyramid) / raw DoG, {size} gray",
            lite_ratio,
            "<= 2",
            lite_ratio <= 2,
            f"{t['alcn lite gray']:.2f} ms; the default before the gain Normalizer",
        ),
        _target("default ALCN fps, {}x{} gray".format(*settings.fps_size), fps, ">= 200", fps >= 200),
        _target(
            f"torch-free backend (backend='opencv', the default) / the network in torch (backend='fast'), {size} gray "
            "(issue 40)",
            torch_free_ratio,
            "<= 1.1",
            torch_free_ratio <= 1.1,
            f"{t['alcn gray']:.2f} ms against {t['alcn fast gray']:.2f} ms; BGR "
            f"{t['alcn bgr']:.2f} against {t['alcn fast bgr']:.2f} ms",
        ),
        _target(
            f"torch backend on the CPU (backend='torch', ALCN2d) / the default backend, {size} gray (issue 40: every "
            "CPU backend at the speed of the fastest)",
            torch_cpu_ratio,
            "<= 1.1",
            torch_cpu_ratio <= 1.1,
            f"{t['alcn torch gray']:.2f} ms",
        ),
        _target(
            f"default ALCN / DLCN, {size} gray (issue 40, stretch)",
            dlcn_ratio,
            "<= 1",
            dlcn_ratio <= 1,
            f"DLCN {t['dlcn gray']:.2f} ms, {t['dlcn gray'] / t['dog raw']:.2f} raw DoGs",
        ),
        _target(
            f"BGR / gray, {size}",
            colour,
            "<= 1.3",
            colour <= 1.3,
            f"lite model: {t['alcn lite bgr'] / t['alcn lite gray']:.2f}",
        ),
        _target(
            f"BGR output against the float Lab round trip, {size}: largest difference (levels)",
            colour_levels,
            "<= 1",
            colour_levels <= 1,
            "default and lite models, uint8",
        ),
        _target(
            "apply() overhead over the method's own computation (worst method but none)",
            worst["overhead"],
            "<= 0.2",
            worst["overhead"] <= 0.2,
            worst["method"],
        ),
        _target(
            "peak memory added / float32 image, {}x{} gray".format(*settings.large_size),
            alcn_memory["added_per_float32"],
            "<= 3",
            None if alcn_memory["added_per_float32"] is None else alcn_memory["added_per_float32"] <= 3,
            f"{alcn_memory['strips']} strips",
        ),
        _target(
            "OpenCV calls after apply / alone",
            threads[0]["ratio"],
            "about 1",
            threads[0]["ratio"] <= 1.1,
            f"torch's threads: {threads[1]['ratio']:.2f}, apply {threads[1]['apply_ms']:.1f} ms against "
            f"{threads[0]['apply_ms']:.1f} ms",
        ),
        *fresh_target,
        _target(
            "alcn normalize video / (decode+encode + apply, in sequence)",
            video["normalize_s"] / video["sequential_s"],
            "< 1: decoding and encoding hidden",
            video["normalize_s"] < video["sequential_s"],
            f"bound max(decode+encode, apply): {video['bound_s'] / video['sequential_s']:.2f}",
        ),
        _target(
            f"batched torch path, {size} frames per second on CUDA",
            batched["cuda"]["fps"] if batched["cuda_available"] else None,
            ">= 2000 on an H100",
            batched["cuda"]["fps"] >= 2000 if batched["cuda_available"] else None,
            "no CUDA device in this run: path tested on the CPU" if not batched["cuda_available"] else "",
        ),
    ]
    return {
        "times_ms": t,
        "summary": summary,
        "stages": stages,
        "profile": profile,
        "contract": contract,
        "threads": threads,
        "fresh_processes": fresh,
        "memory": memory,
        "video": video,
        "batched": batched,
    }


@holds_out_dir
def main(
    out_dir: str | os.PathLike, settings: SpeedSettings | None = None, progress: bool = True, overwrite: bool = False
) -> dict[str, Any]:
    """Run the speed benchmark and write ``speed.json``, ``speed.md`` and ``speed.png`` into ``out_dir``.

    Args:
        out_dir: output folder (created).
        settings: the run's settings; default :class:`SpeedSettings`, the preset ``CONFS["default"]`` (:data:`CONFS`).
        progress: the progress bars (the cases, the video row's pipelines).
        overwrite: replace the report of an earlier run in ``out_dir``.

    Returns:
        The contents of ``speed.json``.

    Raises:
        InputError: bad settings (a device torch does not have among them), or an ``out_dir`` that holds an earlier
            run's report (without ``overwrite``), before any work.
        WeightFileError: ``weights`` or ``lite_weights`` is missing or not a weight file, before any work.
    """
    settings = settings or SpeedSettings()
    settings.check()
    check_no_earlier_output([Path(out_dir) / "speed.json", Path(out_dir) / "speed.md"], overwrite)
    # a weight file the user named: a missing or bad one is refused here, not logged as every variant's failure
    for option, weights in (("--weights", settings.weights), ("--lite-weights", settings.lite_weights)):
        if weights is not None:
            try:
                load_normalizer_file(weights)
            except WeightFileError as exc:
                raise WeightFileError(f"{option}: {exc}") from None
    import torch

    from alcn_cv.nets.device import torch_device

    if settings.device is not None:
        torch_device(settings.device, "--device")
    out = Path(out_dir)
    make_folder(out)

    if settings.threads is not None:
        cv2.setNumThreads(settings.threads)
        torch.set_num_threads(settings.threads)
    if settings.device is not None:
        return _device_main(out, settings)
    methods = _select_methods(settings)
    machine_before = machine()
    frame_for = _frame_source(settings.image)

    built: dict[str, Normalization] = {}
    rows: list[dict[str, Any]] = []
    accuracy: list[dict[str, Any]] = []
    errors: dict[str, str] = {}
    cases = [(w, h, c) for (w, h) in settings.sizes for c in settings.colours]
    with tqdm(total=len(cases) * len(methods), desc="speed", unit="case", disable=not progress) as bar:
        for width, height, colour in cases:
            frame = frame_for(width, height, colour)
            ready = _ready(methods, built, errors, frame, settings.warmup)
            case_rows, case_accuracy = _time_case(ready, frame, colour, settings, bar)
            rows += case_rows
            accuracy += case_accuracy
    video = _video_test(methods, built, errors, rows, settings)
    with tempfile.TemporaryDirectory() as work:
        target_results = targets(settings, Path(work), progress)

    result = {
        "command": speed_command(out_dir, settings),
        "settings": {
            **asdict(settings),
            "sizes": [list(size) for size in settings.sizes],
            "video_size": list(settings.video_size),
            "target_size": list(settings.target_size),
            "fps_size": list(settings.fps_size),
            "large_size": list(settings.large_size),
            "frames": settings.image or "synthetic_frame(seed=0)",
            "opencv_threads": cv2.getNumThreads(),
            "torch_threads": torch.get_num_threads(),
        },
        "machine_before": machine_before,
        "machine_after": machine(),
        "reference": REFERENCE,
        "rows": rows,
        "accuracy": accuracy,
        "video": video,
        "targets": target_results,
        "errors": errors,
    }
    # all or none: an interrupt leaves an earlier report whole
    with atomic_paths(out / "speed.json", out / "speed.md", out / "speed.png") as (json_path, md, png):
        write_json(json_path, result)
        atomic_write(md, _markdown(result))
        plot_speed(result, png)
    return result


def _device_main(out: Path, settings: SpeedSettings) -> dict[str, Any]:
    from alcn_cv.bench.device_speed import device_markdown, device_speed

    before = machine()
    frame = _frame_source(settings.image)(*settings.target_size, "gray")
    device = device_speed(settings.device, frame, settings.device_batches, settings.target_repeats)
    result = {
        "command": speed_command(out, settings),
        "machine_before": before,
        "machine_after": machine(),
        "rows": device["rows"],
        "device": device,
    }
    lines = [
        f"# alcn bench speed --device {settings.device}",
        "",
        f"`{result['command']}`",
        "",
        f"Machine: {describe_machine(before)}",
        "",
        *device_markdown(device),
        "",
    ]
    # a CPU run's plot, which this report does not describe, goes with them
    with atomic_paths(out / "speed.json", out / "speed.md", stale=[out / "speed.png"]) as (json_path, md):
        write_json(json_path, result)
        atomic_write(md, "\n".join(lines))
    return result


def _markdown(result: dict[str, Any]) -> str:
    before, after = result["machine_before"], result["machine_after"]
    lines = [
        "# Speed of ALCN against the classical normalizations",
        "",
        f"- **Machine:** {describe_machine(before)}; load average after the run "
        f"{', '.join(map(str, after.get('load_average_1_5_15', [])))}; OpenCV threads "
        f"{result['settings']['opencv_threads']}.",
        f"- **Command:** `{result['command']}`",
        f"- **Settings:** sizes {', '.join(f'{w}x{h}' for w, h in result['settings']['sizes'])}; colours "
        f"{', '.join(result['settings']['colours'])}; time budget {result['settings']['budget_s']} s per case; "
        f"video test {result['settings']['video_frames']} frames of "
        f"{'x'.join(map(str, result['settings']['video_size']))}; weights "
        f"{result['settings']['weights'] or 'shipped'} (paper model), "
        f"{result['settings']['lite_weights'] or 'shipped'} (lite), shipped (gain and gain-lite).",
        "",
        f"Frames: {result['settings']['frames']}. Times: `apply(uint8 frame)`, median and interquartile range over "
        f"{result['settings']['min_repeats']}-{result['settings']['max_repeats']} runs "
        f"after {result['settings']['warmup']} "
        "warm-up, the methods timed in turns (one call each per round); `x dog` is the ratio of medians to `dog` in "
        "the same run. ALCN's network / mixture split: medians of `weight_grid` and `normalize` run in turns on "
        "the frame's intensities (network: `weight_grid`; mixture: the rest, map interpolation and Eq. 3); the "
        "memory columns are of one more `apply`.",
        "",
    ]
    lines += _targets_markdown(result["targets"]) + ["## Time", ""]
    headers = [
        "size",
        "colour",
        "method",
        "x dog",
        "median ms",
        "IQR ms",
        "fps",
        "network ms",
        "mixture ms",
        "traced peak MB",
        "RSS peak MB",
        "RSS added MB",
        "runs",
    ]
    table = [
        [
            f"{r['width']}x{r['height']}",
            r["colour"],
            r["method"],
            r["ratio_to_dog"],
            r["median_ms"],
            r["iqr_ms"],
            r["fps"],
            r.get("network_ms"),
            r.get("mixture_ms"),
            r["traced_peak_mb"],
            r["rss_peak_mb"],
            r["rss_added_mb"],
            r["repeats"],
        ]
        for r in result["rows"]
    ]
    lines.append(markdown_table(headers, table, digits=2))
    if result["accuracy"]:
        lines += [
            "## Accuracy of the approximations and backends",
            "",
            f"Raw response (`normalize`) of each ALCN configuration and backend against `{EXACT}` (the "
            "paper's Normalizer and the exact Eq. 3, same grayscale frame); relative: divided by the width of "
            "the exact output range.",
            "",
        ]
        lines.append(
            markdown_table(
                [
                    "size",
                    "method",
                    "max abs",
                    "mean abs",
                    "max / range",
                    "mean / range",
                    "std of exact",
                    "spatial std of the maps",
                ],
                [
                    [
                        f"{a['width']}x{a['height']}",
                        a["method"],
                        a["max_abs"],
                        a["mean_abs"],
                        a["max_rel_range"],
                        a["mean_rel_range"],
                        a["exact_std"],
                        a["exact_map_std"],
                    ]
                    for a in result["accuracy"]
                ],
                digits=5,
            )
        )
    if result["video"]:
        lines += [
            "",
            "## Memory over a video",
            "",
            "Resident set (RSS) of the process after each frame of a generated video (`apply` on uint8 frames).",
            "",
        ]
        lines.append(
            markdown_table(
                [
                    "method",
                    "size",
                    "frames",
                    "ms / frame",
                    "RSS first MB",
                    "RSS last MB",
                    "RSS max MB",
                    "growth kB / frame",
                ],
                [
                    [
                        v["method"],
                        "x".join(map(str, v["size"])),
                        v["frames"],
                        v["median_frame_ms"],
                        v["rss_first_mb"],
                        v["rss_last_mb"],
                        v["rss_max_mb"],
                        v["growth_kb_per_frame"],
                    ]
                    for v in result["video"]
                ],
                digits=1,
            )
        )
    if result["errors"]:
        lines += ["", "## Not run", ""] + [f"- `{k}`: {v}" for k, v in result["errors"].items()]
    return "\n".join(lines) + "\n"


def _targets_markdown(t: dict[str, Any]) -> list[str]:
    """The targets' section of ``speed.md``."""
    yes_no = {True: "met", False: "missed", None: "-"}
    lines = [
        "## Targets",
        "",
        "Ratios of medians of calls timed in turns in this run (see `speed.json` for every time).",
        "",
    ]
    lines.append(
        markdown_table(
            ["target", "measured", "goal", "", "note"],
            [[r["target"], r["measured"], r["goal"], yes_no[r["met"]], r["note"]] for r in t["summary"]],
            digits=2,
        )
    )
    lines += ["", "### Where the time goes (ms, medians in turns; frame of the first target)", ""]
    lines.append(
        markdown_table(
            ["model", "network", "mixture", "apply contract", "apply"],
            [[m, s["network_ms"], s["mixture_ms"], s["contract_ms"], s["apply_ms"]] for m, s in t["stages"].items()],
            digits=2,
        )
    )
    lines += ["", "Profile of the default's `apply` (cProfile, own time per call, with its overhead):", ""]
    lines.append(
        markdown_table(
            ["function", "calls per apply", "own ms per apply"],
            [[p["function"], p["calls_per_apply"], p["own_ms_per_apply"]] for p in t["profile"]],
            digits=2,
        )
    )
    lines += [
        "",
        "### apply() against each method's own computation (`_normalize` on float32 intensities)",
        "",
        "Overhead from the fastest runs of each (the least disturbed by the load); medians beside.",
        "",
    ]
    lines.append(
        markdown_table(
            ["method", "apply ms", "own ms", "apply min ms", "own min ms", "overhead", "of medians"],
            [
                [
                    r["method"],
                    r["apply_ms"],
                    r["own_ms"],
                    r["apply_min_ms"],
                    r["own_min_ms"],
                    r["overhead"],
                    r["overhead_of_medians"],
                ]
                for r in t["contract"]
            ],
            digits=3,
        )
    )
    lines += ["", "### An application's OpenCV calls (GaussianBlur + Canny) alone and right after apply", ""]
    lines.append(
        markdown_table(
            ["Normalizer torch threads", "alone ms", "after apply ms", "ratio", "apply ms", "torch threads kept"],
            [
                [
                    r["threads"] or "torch's",
                    r["app_ms"],
                    r["app_after_apply_ms"],
                    r["ratio"],
                    r["apply_ms"],
                    r["torch_threads_kept"],
                ]
                for r in t["threads"]
            ],
            digits=2,
        )
    )
    lines += ["", "### Peak memory on a large grayscale image", ""]
    lines.append(
        markdown_table(
            ["method", "size", "s", "float32 image MB", "RSS added MB", "added / float32", "strips"],
            [
                [
                    r["method"],
                    "x".join(map(str, r["size"])),
                    r["seconds"],
                    r["float32_mb"],
                    r["rss_added_mb"],
                    r["added_per_float32"],
                    r["strips"],
                ]
                for r in t["memory"]
            ],
            digits=2,
        )
    )
    v = t["video"]
    lines += [
        "",
        f"### `alcn normalize` on {Path(v['video']).name} ({v['frames']} frames of {'x'.join(map(str, v['size']))})",
        "",
    ]
    lines.append(
        markdown_table(
            ["decode+encode s", "apply alone s", "sequential sum s", "alcn normalize s", "fps"],
            [[v["decode_encode_s"], v["apply_s"], v["sequential_s"], v["normalize_s"], v["normalize_fps"]]],
            digits=2,
        )
    )
    b = t["batched"]
    lines += ["", "### Batched torch path (`ALCN.apply_batch`; frames: batch x size)", ""]
    lines.append(
        markdown_table(
            ["device", "frames", "ms per frame", "ms per frame float16", "fps", "float16 max abs diff"],
            [
                [
                    d,
                    f"{b[d]['batch']} x {b[d]['size'][0]}x{b[d]['size'][1]}",
                    b[d]["ms_per_frame"],
                    b[d]["ms_per_frame_half"],
                    b[d]["fps"],
                    b[d]["half_max_abs"],
                ]
                for d in ("cpu", "cuda")
                if d in b
            ],
            digits=4,
        )
    )
    if not b["cuda_available"]:
        lines += ["", "No CUDA device in this run: the CUDA path is tested on the CPU only (the CUDA test skips)."]
    return lines + [""]
