"""The training configurations, their named presets (hloc's ``confs``) and ``--set`` overrides.

Each training command has one configuration class whose defaults are the recipe of its shipped
weight file, and a dict of named presets: :data:`TRAIN_CONFS` (``alcn train --conf paper``,
``alcn_normalizer.npz``), :data:`REAL_LIGHT_CONFS` (``alcn train-real-light --conf gain``,
``alcn_normalizer_gain.npz``), :data:`UNET_CONFS` (``alcn train-unet --conf gain``, the U-Net
baseline) and :data:`DISTILL_CONFS` (``alcn distill --conf lite|gain-lite``), each with its one-line summaries
(``*_CONF_SUMMARIES``, for the ``--help``). :func:`alcn_cv.presets.with_settings` applies ``KEY=VALUE`` overrides
(dotted keys, values read as TOML and checked against the field's type) to any of them. The module imports no torch.

The keys of :class:`TrainConfig` (also readable from a TOML file with the tables below;
``alcn train --print-config`` writes the effective configuration as TOML):

``seed`` (int)
    Seed of everything random in a run: network initialisation, shuffling, augmentation and,
    unless ``data.seed`` is set, the rendered training windows.

``[data]`` -- the stage-1 windows (Phos-like, :mod:`alcn_cv.data.phos`)
    ``path`` (str): folder written by ``alcn data phos`` holding the training windows; empty:
    render ``n_train`` windows in the process. ``val_path`` (str): the same for the validation
    windows; empty: render ``n_val``. Both relative to the working folder; a run's checkpoint records them absolute
    (:meth:`TrainConfig.resolved`), its weight file as given, the home folder written ``~``
    (:meth:`TrainConfig.shareable`). ``n_train``, ``n_val`` (int): number of windows to render.
    ``seed`` (int, -1 = the run's ``seed``): seed of the rendered training windows (validation
    uses ``seed + 1_000_003``). ``n_objects`` (int), ``object_seed`` (int): the object catalogue
    (labels 1..n_objects). ``train_lighting``, ``val_lighting`` (list of str): lighting families
    (:data:`alcn_cv.data.lighting.LIGHT_FAMILIES`) of the training and the *held-out* validation
    windows; they must not overlap -- validation under the training light says nothing about
    robustness. ``background_fraction`` (float): fraction of background windows.
    ``gain_jitter`` (list of 2 floats): range of a random log-uniform intensity gain applied to
    training windows (``[1.0, 1.0]``: none). ``anchor_lighting`` (str, a family of
    ``train_lighting``) and ``anchor_fraction`` (float): with ``optim.objective = "meta"``, the
    fraction of training windows rendered under the anchor lighting.

``[model]`` -- the networks (Sec. 4.2)
    ``method`` (str): ``"alcn"`` trains the Normalizer with the detector (``optim.objective``);
    ``"dog"`` and ``"none"`` train the same detector on a fixed Difference-of-Gaussians or on the
    raw windows, the comparison that tells whether the learned Normalizer helps.
    ``num_kernels`` (int), ``sigma_step`` (float): the Gaussian basis, ``sigma_i = i * step``.
    ``channels`` (list of 2 ints), ``hidden`` (int): the Normalizer (tanh activations, the
    paper's); ``[10, 20]``, 256 (the shipped file) is five times cheaper than the paper's
    ``[20, 50]``, 1024 (the ``paper-full`` preset), so that it trains on a CPU.
    ``output_scale`` (float): fixed factor on its outputs. The Normalizer starts at the DoG
    below (the last layer's weights at zero, its bias the DoG).
    ``dog`` (list of 2 floats): sigmas (pixels, in the basis) of the DoG ``G_a - G_b`` the
    Normalizer starts at and ``method = "dog"`` uses. ``detector_channels`` (list of 2 ints),
    ``detector_hidden`` (int), ``detector_dropout`` (float): the detector.
    ``detector_input`` (``"standardize"`` or ``"raw"``): the detector input policy, applied to
    every method alike: per-window standardization (zero mean, unit variance over the 32x32) or
    the raw mixture output. ``working_scale`` (float): the scale recorded in the exported weight
    file, the factor from a camera frame to the resolution at which the 48x48 window applies.

``[optim]``
    ``objective``: ``"joint"`` -- Eq. 2, the detector and the Normalizer minimise the loss on
    every training window; ``"meta"`` -- the second stage rehearsed in the first: the detector
    minimises the loss on windows under ``data.anchor_lighting`` only (as a new detector will see
    one lighting), the Normalizer the loss on all windows with the detector held fixed for the
    others, so that it learns to make other lightings look like the anchor to a detector.
    Adam with a cosine learning-rate schedule per step: ``lr`` (float, the detector's),
    ``normalizer_lr`` (float), ``grad_clip`` (float, 0 = off),
    ``batch_size`` (int), ``epochs`` (int), ``warmup_steps`` (int, linear warm-up).

``[fewshot]`` -- the paper's second stage as a validation (:mod:`alcn_cv.train.fewshot`)
    ``enabled`` (bool): after training, train a fresh detector per method (the trained
    Normalizer, each DoG of ``dog``, none; same detector, same input policy) from
    ``real_images`` rendered images of each of ``n_objects`` *new* objects under the training-like
    light, augmented to ``per_image`` windows each, and test it on ``n_test`` windows under the
    held-out families ``test_lighting`` (list of str); ``epochs`` (int) of detector training;
    ``dog`` (list of [a, b] sigma pairs): the DoG baselines.

``[run]``
    ``device`` (``"cpu"`` or ``"cuda"``), ``workers`` (int: processes rendering windows, 0 =
    this one), ``threads`` (int: torch threads, 0 = torch's default), ``log_every`` (int: steps
    between log lines).

Errors (:class:`~alcn_cv.errors.InputError`) name the offending key: unknown keys, wrong
types, impossible values, a missing data folder.
"""

from __future__ import annotations

import copy
import dataclasses
import tomllib
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Self

from alcn_cv.data.lighting import LIGHT_FAMILIES
from alcn_cv.errors import InputError
from alcn_cv.presets import preset_named, with_settings

__all__ = [
    "DISTILL_CONFS",
    "DISTILL_CONF_SUMMARIES",
    "FOLDER_SETTINGS",
    "REAL_LIGHT_CONFS",
    "REAL_LIGHT_CONF_SUMMARIES",
    "TRAIN_CONFS",
    "TRAIN_CONF_SUMMARIES",
    "TRAIN_FOLDER_SETTINGS",
    "UNET_CONFS",
    "UNET_CONF_SUMMARIES",
    "FewShotSetup",
    "GainDistillConfig",
    "LiteDistillConfig",
    "RealLightConfig",
    "TrainConfig",
    "UNetConfig",
    "absolute_path",
    "home_path",
    "load_config",
]


@dataclass
class FewShotSetup:
    """Settings of the few-shot validation (:mod:`alcn_cv.train.fewshot`; here, without torch,
    so that ``alcn bench fewshot`` builds its command line without importing it).

    The one owner of their names and defaults: ``[fewshot]`` of :class:`TrainConfig` and
    :class:`alcn_cv.bench.fewshot.FewShotSettings` name a field as here and default to it, and
    :meth:`of` builds the setup from either. ``test_lighting`` is stored as a tuple.
    """

    n_objects: int = 5
    object_seed: int = 424242
    real_images: int = 1
    per_image: int = 200
    n_test: int = 2000
    test_lighting: tuple[str, ...] = ("dark", "side", "spot", "shadow", "mixed")
    epochs: int = 8
    batch_size: int = 64
    lr: float = 1e-3
    seed: int = 0

    def __post_init__(self) -> None:
        self.test_lighting = tuple(self.test_lighting)

    @classmethod
    def of(cls, settings: Any, **given: Any) -> FewShotSetup:
        """The setup with every field of ``settings`` named as one here (the others at their defaults), then
        ``given``."""
        shared = {f.name: getattr(settings, f.name) for f in dataclasses.fields(cls) if hasattr(settings, f.name)}
        return cls(**{**shared, **given})


@dataclass
class DataConfig:
    path: str = ""
    val_path: str = ""
    n_train: int = 30_000
    n_val: int = 3_000
    seed: int = -1
    n_objects: int = 100
    object_seed: int = 0
    train_lighting: list[str] = field(
        default_factory=lambda: ["ambient", "bright", "shadow", "point", "colour", "mixed"]
    )
    val_lighting: list[str] = field(default_factory=lambda: ["dark", "side", "spot"])
    background_fraction: float = 0.35
    gain_jitter: list[float] = field(default_factory=lambda: [0.5, 2.0])
    anchor_lighting: str = "ambient"
    anchor_fraction: float = 0.5


@dataclass
class ModelConfig:
    method: str = "alcn"
    num_kernels: int = 10
    sigma_step: float = 0.5
    channels: list[int] = field(default_factory=lambda: [10, 20])
    hidden: int = 256
    output_scale: float = 1.0
    dog: list[float] = field(default_factory=lambda: [0.5, 1.5])
    detector_channels: list[int] = field(default_factory=lambda: [20, 50])
    detector_hidden: int = 512
    detector_dropout: float = 0.0
    detector_input: str = "standardize"
    working_scale: float = 0.5


@dataclass
class OptimConfig:
    objective: str = "meta"
    lr: float = 1e-3
    normalizer_lr: float = 1e-3
    grad_clip: float = 5.0
    batch_size: int = 128
    epochs: int = 3
    warmup_steps: int = 100


@dataclass
class FewShotConfig:
    """``[fewshot]``: the few-shot validation after training; the keys of :class:`FewShotSetup` default to its."""

    enabled: bool = True
    n_objects: int = FewShotSetup.n_objects
    real_images: int = FewShotSetup.real_images
    per_image: int = FewShotSetup.per_image
    n_test: int = FewShotSetup.n_test
    test_lighting: list[str] = field(default_factory=lambda: list(FewShotSetup.test_lighting))
    epochs: int = FewShotSetup.epochs
    dog: list[list[float]] = field(default_factory=lambda: [[0.5, 1.5]])


@dataclass
class RunConfig:
    device: str = "cpu"
    workers: int = 0
    threads: int = 0
    log_every: int = 50


@dataclass
class TrainConfig:
    """A complete training configuration (see the module docstring for every key)."""

    seed: int = 0
    data: DataConfig = field(default_factory=DataConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
    fewshot: FewShotConfig = field(default_factory=FewShotConfig)
    run: RunConfig = field(default_factory=RunConfig)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @property
    def data_seed(self) -> int:
        return self.seed if self.data.seed < 0 else self.data.seed

    def folders(self) -> dict[str, str]:
        """Its settings that name folders (:data:`TRAIN_FOLDER_SETTINGS`), by key."""
        flat = _flatten(self.to_dict())
        return {key: flat[key] for key in TRAIN_FOLDER_SETTINGS}

    def resolved(self) -> Self:
        """A copy whose folders (:meth:`folders`) are absolute paths (:func:`absolute_path`): the settings a run's
        checkpoint records and a resumed run is checked against, so that they name the same data from any working
        folder."""
        return self._folders_as(absolute_path)

    def shareable(self) -> Self:
        """A copy whose folders (:meth:`folders`) are as a weight file, which users share, records them
        (:func:`home_path`: as given, the home folder written ``~``)."""
        return self._folders_as(home_path)

    def _folders_as(self, path: Callable[[str], str]) -> Self:
        copied = copy.deepcopy(self)
        for key, value in self.folders().items():
            table, name = key.split(".")
            setattr(getattr(copied, table), name, path(value))
        return copied


#: The settings of :class:`TrainConfig` that name folders, as ``--set`` spells them (those of
#: :class:`RealLightConfig`: :data:`FOLDER_SETTINGS`).
TRAIN_FOLDER_SETTINGS = ("data.path", "data.val_path")

#: ``alcn train`` presets, as overrides of :class:`TrainConfig`'s defaults. ``paper``: the recipe of
#: the shipped ``alcn_normalizer.npz`` (the defaults, objective ``meta``; for a CPU);
#: ``paper-full``: the paper's widths, data scale (Sec. 4.2) and Eq. 2 (objective ``joint``), for a GPU (no
#: shipped file).
TRAIN_CONFS: dict[str, dict[str, Any]] = {
    "paper": {},
    "paper-full": {
        "data": {"n_train": 500_000, "n_val": 20_000},
        "model": {"channels": [20, 50], "hidden": 1024, "detector_hidden": 1024},
        "fewshot": {"n_test": 10_000, "dog": [[0.5, 1.0], [0.5, 1.5], [0.5, 2.5], [1.0, 2.0], [1.0, 3.0]]},
        "optim": {"objective": "joint", "batch_size": 256, "epochs": 30, "warmup_steps": 1000},
        "run": {"device": "cuda", "workers": 8},
    },
}

#: One line per preset of :data:`TRAIN_CONFS`, for ``alcn train --help``.
TRAIN_CONF_SUMMARIES: dict[str, str] = {
    "paper": "the recipe of the shipped alcn_normalizer.npz: objective meta, widths for a CPU",
    "paper-full": "the paper's widths, data scale and Eq. 2 (objective joint), for a GPU; no shipped file",
}

_CHOICES = {
    "model.method": ("alcn", "dog", "none"),
    "model.detector_input": ("standardize", "raw"),
    "optim.objective": ("joint", "meta"),
    "run.device": ("cpu", "cuda"),
}
#: Lists of a fixed length (the others take any length).
_PAIRS = ("model.channels", "model.dog", "model.detector_channels", "data.gain_jitter")


def absolute_path(entry: str) -> str:
    """A setting naming a folder, as an absolute path (``~`` expanded, a relative path taken from the working folder,
    symbolic links resolved) where it names an existing folder; as given otherwise (empty, the name of a webcam scene,
    a path that is missing or a file: the checks name it as the user wrote it). A run's settings pass through it
    before its checkpoint records them, so that they name the same data from any working folder (its weight file,
    which users share, records them by :func:`home_path`)."""
    path = Path(entry).expanduser()
    return str(path.resolve()) if entry and path.is_dir() else entry


def home_path(entry: str) -> str:
    """A setting naming a folder as a weight file, which users share, records it: as given, but for an absolute path
    under the home folder (``/home/<user>/...``, as the user wrote it or as a resumed run's checkpoint holds it),
    written from ``~`` (``~/...``). A relative path stays relative: no absolute path of the machine where the user
    gave none, and the user's name in none."""
    path = Path(entry)
    for home in dict.fromkeys((Path.home(), Path.home().resolve())):  # the checkpoint's folders are resolved
        if path.is_absolute() and path.is_relative_to(home):
            return str(Path("~") / path.relative_to(home))
    return entry


def _check(cfg: TrainConfig) -> None:
    flat = _flatten(cfg.to_dict())
    for key in _PAIRS:
        if len(flat[key]) != 2:
            raise InputError(f"config key {key!r} must be a list of 2, got {flat[key]!r}")
    for key, choices in _CHOICES.items():
        if flat[key] not in choices:
            raise InputError(f"config key {key!r} must be one of {', '.join(choices)}, got {flat[key]!r}")
    positive = [
        "data.n_objects",
        "model.num_kernels",
        "model.hidden",
        "model.detector_hidden",
        "optim.batch_size",
        "optim.epochs",
        "run.log_every",
        "fewshot.n_objects",
        "fewshot.real_images",
        "fewshot.per_image",
        "fewshot.n_test",
        "fewshot.epochs",
        "model.sigma_step",
        "optim.lr",
        "model.output_scale",
        "model.working_scale",
    ]
    non_negative = [
        "seed",
        "data.n_train",
        "data.n_val",
        "data.object_seed",
        "optim.normalizer_lr",
        "optim.grad_clip",
        "optim.warmup_steps",
        "run.workers",
        "run.threads",
    ]
    _check_ranges(flat, positive, non_negative)
    if not 0 <= cfg.data.background_fraction <= 1:
        raise InputError(f"config key 'data.background_fraction' must be in [0, 1], got {cfg.data.background_fraction}")
    # the families first: a misspelt one is named, not the anchor it then leaves out
    for key, names in (
        ("data.train_lighting", cfg.data.train_lighting),
        ("data.val_lighting", cfg.data.val_lighting),
        ("fewshot.test_lighting", cfg.fewshot.test_lighting),
    ):
        bad = [s for s in names if s not in LIGHT_FAMILIES]
        if bad or not names:
            raise InputError(f"config key {key!r} must list lighting families of {LIGHT_FAMILIES}, got {names}")
    if cfg.optim.objective == "meta" and not cfg.data.path:
        if cfg.data.anchor_lighting not in cfg.data.train_lighting:
            raise InputError(
                f"config key 'data.anchor_lighting' ({cfg.data.anchor_lighting!r}) must be one of "
                f"'data.train_lighting' {cfg.data.train_lighting}"
            )
        if len(cfg.data.train_lighting) < 2 or not 0 < cfg.data.anchor_fraction < 1:
            raise InputError(
                "config key 'data.anchor_fraction' must be in (0, 1), with another lighting beside the "
                "anchor in 'data.train_lighting', for optim.objective = 'meta'"
            )
        n_anchor = round(cfg.data.n_train * cfg.data.anchor_fraction)  # as windows.load_windows renders them
        if cfg.data.n_train and not 0 < n_anchor < cfg.data.n_train:
            raise InputError(
                f"config keys 'data.n_train' ({cfg.data.n_train}) and 'data.anchor_fraction' "
                f"({cfg.data.anchor_fraction}) leave {n_anchor} anchor windows of {cfg.data.n_train}: "
                "optim.objective = 'meta' needs windows under the anchor lighting and under others"
            )
    if not 0 <= cfg.model.detector_dropout < 1:
        raise InputError(f"config key 'model.detector_dropout' must be in [0, 1), got {cfg.model.detector_dropout}")
    lo, hi = cfg.data.gain_jitter
    if not 0 < lo <= hi:
        raise InputError(f"config key 'data.gain_jitter' must be 0 < lo <= hi, got {cfg.data.gain_jitter}")
    for pair in cfg.fewshot.dog:
        if len(pair) != 2:
            raise InputError(f"config key 'fewshot.dog' must list [a, b] sigma pairs, got {cfg.fewshot.dog}")
    overlap = set(cfg.data.train_lighting) & set(cfg.data.val_lighting)
    if overlap and not (cfg.data.path and cfg.data.val_path):
        raise InputError(
            f"config keys 'data.train_lighting' and 'data.val_lighting' share {sorted(overlap)}: "
            "validation must use held-out lightings"
        )
    steps = [cfg.model.sigma_step * (i + 1) for i in range(cfg.model.num_kernels)]
    for key, pairs in (("model.dog", [cfg.model.dog]), ("fewshot.dog", cfg.fewshot.dog)):
        for s in (s for pair in pairs for s in pair):
            if not any(abs(s - t) < 1e-6 for t in steps):
                raise InputError(f"config key {key!r} needs sigmas of the basis {steps}, got {pairs}")
    for key in ("path", "val_path"):
        value = getattr(cfg.data, key)
        if value and not Path(value).is_dir():
            raise InputError(f"config key 'data.{key}': folder not found: {value}")
    if not cfg.data.path and cfg.data.n_train == 0:
        raise InputError("config key 'data.n_train' must be positive when 'data.path' is empty")
    if not cfg.data.val_path and cfg.data.n_val == 0:
        raise InputError("config key 'data.n_val' must be positive when 'data.val_path' is empty")


def _check_ranges(settings: dict[str, Any], positive: Iterable[str] = (), non_negative: Iterable[str] = ()) -> None:
    """Check the ``positive`` keys of ``settings`` (flat, by key as ``--set`` spells it) are above 0 and the
    ``non_negative`` ones not below 0.

    Raises:
        InputError: the first key out of range, named with its value.
    """
    for key in positive:
        if not settings[key] > 0:  # `not >`: NaN is no value in range
            raise InputError(f"config key {key!r} must be positive, got {settings[key]!r}")
    for key in non_negative:
        if not settings[key] >= 0:
            raise InputError(f"config key {key!r} must be >= 0, got {settings[key]!r}")


def _flatten(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[prefix + k] = v
    return out


def load_config(
    source: str | Path | dict[str, Any] | TrainConfig | None = None,
    overrides: list[str | dict[str, Any]] | dict[str, Any] | None = None,
) -> TrainConfig:
    """Build and check a configuration.

    Args:
        source: a preset name of :data:`TRAIN_CONFS` (default ``"paper"``), a path to a TOML
            file (applied over the defaults), a dict of the same shape, or a :class:`TrainConfig`.
        overrides: applied last, in order: ``"optim.lr=3e-4"`` strings (command-line ``--set``)
            and nested dicts (``{"optim": {"lr": 3e-4}}``), or one nested dict.

    Raises:
        InputError: an unknown preset (a name that is no path; :func:`~alcn_cv.presets.preset_named`), unknown key,
            wrong type or impossible value (the message names the key), a missing or unreadable TOML file, a missing
            data folder.
    """
    cfg = TrainConfig()
    if isinstance(source, TrainConfig):
        cfg = copy.deepcopy(source)
    elif isinstance(source, dict):
        cfg = with_settings(cfg, [source])
    else:
        name = str(source or "paper")
        path = Path(name)
        # a name is a preset's (an unknown one refused as every command refuses it), a path is a TOML file's
        if name in TRAIN_CONFS or not (path.is_file() or path.suffix or path.name != name):
            cfg = with_settings(cfg, [copy.deepcopy(preset_named(TRAIN_CONFS, name))])
        elif not path.is_file():
            raise InputError(f"config file {name}: not found")
        else:
            try:
                values = tomllib.loads(path.read_text(encoding="utf-8"))
            except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
                raise InputError(f"config file {path}: invalid TOML: {exc}") from None
            cfg = with_settings(cfg, [values])
    cfg = with_settings(cfg, [overrides] if isinstance(overrides, dict) else overrides or [])
    _check(cfg)
    return cfg


def _gain_network() -> dict[str, Any]:
    """The shipped gain Normalizer's :class:`~alcn_cv.nets.gain.GainNormalizer` arguments."""
    return {
        "channels": 16,
        "stride": 8,
        "dilations": [1, 2, 4],
        "num_kernels": 2,
        "sigma_step": 1.0,
        "eps": 0.01,
        "floor_scale": 1.0,
        "divisive_sigma": 2.0,
        "tau": 3.0,
        "learn_scales": False,
        "band": 0.15,
    }


@dataclass
class RealLightConfig:
    """Settings of :func:`~alcn_cv.train.real_light.train_real_light`; the defaults are the
    ``gain`` preset, the recipe of the shipped ``alcn_normalizer_gain.npz``: relit copies of photographs
    that permit any use, no webcam frame (those are its validation).

    Attributes:
        scenes: registered scenes: folders of frames, or names of scenes of the shared ``webcam`` data.
        relit: relit copies of each permissive photograph
            (:func:`~alcn_cv.data.permissive_images.training_photographs`) and of each of ``photos``, drawn with
            ``scenes`` as scenes of their own (0: none).
        photos: folders of your own photographs (any of jpg, png, tif, bmp...; gray or colour, 8 or 16 bits; ``~``
            expanded, relative to the working folder; a run's checkpoint records them absolute, :meth:`resolved`,
            its weight file as given, :meth:`shareable`), each image relit ``relit`` times like the shipped
            photographs and **added** to them (their copies are unchanged: the ``i``-th photograph's draws are seeded
            ``[seed, i]``, yours come after); every image at least ``crop`` pixels on a side. A folder, not an image
            file: the run's checkpoint records each folder's files.
        shipped_photos: relight the permissive photographs too; ``false`` with ``photos`` trains on your
            photographs alone.
        light: the light changes of those copies (:data:`~alcn_cv.data.light_changes.LIGHTS`).
        jitter: their registration error (pixels; 0: pixel-exact).
        rendered: folders of rendered registered scenes (``alcn data scenes``; a folder
            without images stands for its sub-folders), drawn apart from ``scenes``.
        rendered_fraction: the share of steps that draw a rendered scene (0 when none).
        steps: optimisation steps; each sees 2 frames x ``locations`` crops of one scene.
        locations: textured locations (classes) per step.
        crop: side of the window the network sees (pixels).
        patch: side of the identified centre (pixels).
        min_distance: smallest distance between two locations of a step (pixels, Chebyshev).
        temperature: of the softmax over cosine similarities.
        consistency: weight of :func:`~alcn_cv.train.real_light.consistency_loss`.
        anywhere: locations per step drawn anywhere in the frame, for the consistency term only.
        repeatability: weight of :func:`~alcn_cv.train.real_light.repeatability_loss` (the same locations).
        lr: Adam's learning rate.
        seed: seeds numpy and torch (data draws and initialisation).
        save_every: steps between checkpoints and intermediate weight files.
        net: :class:`~alcn_cv.nets.gain.GainNormalizer` arguments (``--set net.channels=8``).
    """

    scenes: list[str] = field(default_factory=list)
    relit: int = 4
    photos: list[str] = field(default_factory=list)
    shipped_photos: bool = True
    light: str = "relief"
    jitter: float = 0.0
    rendered: list[str] = field(default_factory=list)
    rendered_fraction: float = 0.0
    steps: int = 300
    locations: int = 48
    crop: int = 160
    patch: int = 32
    min_distance: int = 24
    temperature: float = 0.05
    consistency: float = 1.0
    anywhere: int = 24
    repeatability: float = 1.0
    lr: float = 1e-3
    seed: int = 0
    save_every: int = 100
    net: dict[str, Any] = field(default_factory=_gain_network)

    def resolved(self) -> Self:
        """A copy whose folders (:data:`FOLDER_SETTINGS`) are absolute paths (:func:`absolute_path`: a webcam scene's
        name, and a missing folder, stay as given): the settings a run's checkpoint records and a resumed run is
        checked against, so that ``--resume`` finds the same data from any working folder."""
        return dataclasses.replace(self, **{k: [absolute_path(p) for p in getattr(self, k)] for k in FOLDER_SETTINGS})

    def shareable(self) -> Self:
        """A copy whose folders (:data:`FOLDER_SETTINGS`) are as a weight file, which users share, records them
        (:func:`home_path`: as given, the home folder written ``~``)."""
        return dataclasses.replace(self, **{k: [home_path(p) for p in getattr(self, k)] for k in FOLDER_SETTINGS})

    def check(self) -> None:
        """What a run on these settings needs: scenes or relit photographs, a rendered share in [0, 1) with rendered
        scenes, at least 2 locations, 1 step and 1 step between snapshots, relit copies 0 or at least 2 (a copy is a
        frame: a scene needs two), no negative count of locations drawn anywhere or seed, and a positive learning rate
        and temperature; each of ``scenes`` a folder or a webcam scene's name; ``photos`` relit, each an existing folder
        holding images (listed, not read: the images' sizes are checked as they are read). The network's own needs, such
        as the crop's size, are its trainer's to check.

        Raises:
            InputError: the first setting out of range, named.
        """
        if self.photos and self.relit < 2:
            raise InputError(f"photos are trained on as relit copies: they need relit >= 2, got relit={self.relit}")
        if self.relit == 1:
            raise InputError("relit must be 0 (no relit copies) or at least 2 (a pair of lights to train on), got 1")
        # imported here, not with the module: the configurations import no data module
        from alcn_cv.data.permissive_images import photo_files
        from alcn_cv.data.scenes import scene_dirs

        scene_dirs(self.scenes)
        photo_files(self.photos)
        if not self.scenes and not (self.relit and (self.shipped_photos or self.photos)):
            raise InputError("no scenes given (scenes, or relit with shipped_photos or photos)")
        if not 0 <= self.rendered_fraction < 1 or (self.rendered_fraction > 0 and not self.rendered):
            raise InputError(
                f"rendered_fraction must be in [0, 1) and needs rendered scenes, got {self.rendered_fraction}"
            )
        if self.locations < 2 or self.steps < 1 or self.save_every < 1:
            raise InputError(
                f"need locations >= 2, steps >= 1 and save_every >= 1, got {self.locations}, {self.steps}, "
                f"{self.save_every}"
            )
        if self.relit < 0 or self.anywhere < 0 or self.seed < 0:
            raise InputError(
                f"relit, anywhere and seed must be >= 0, got {self.relit}, {self.anywhere} and {self.seed}"
            )
        if not self.lr > 0:
            raise InputError(f"lr must be > 0, got {self.lr}")
        if not self.temperature > 0:
            raise InputError(f"temperature must be > 0, got {self.temperature}")


#: The settings of :class:`RealLightConfig` (and :class:`UNetConfig`) that list folders (those of :class:`TrainConfig`:
#: :data:`TRAIN_FOLDER_SETTINGS`).
FOLDER_SETTINGS = ("scenes", "photos", "rendered")

#: ``alcn train-real-light`` presets: ``gain`` makes ``alcn_normalizer_gain.npz``.
REAL_LIGHT_CONFS: dict[str, RealLightConfig] = {"gain": RealLightConfig()}

#: One line per preset of :data:`REAL_LIGHT_CONFS`, for ``alcn train-real-light --help``.
REAL_LIGHT_CONF_SUMMARIES: dict[str, str] = {
    "gain": "the recipe of the shipped alcn_normalizer_gain.npz: relit photographs with no known restriction on use",
}


def _unet_network() -> dict[str, Any]:
    """The :class:`~alcn_cv.train.unet_normalizer.UNetNormalizer` arguments of the U-Net baseline, every one of
    them (its defaults)."""
    return {"channels": 8, "levels": 3, "eps": 0.01}


#: The most channels the U-Net baseline's widest level may have (the default's has 32; 1024 is 8 levels of 8): its
#: 3x3 convolutions hold 9 * width**2 weights each, 38 MB at 1024, and a wider one would fill the memory quadratically.
MAX_UNET_WIDTH = 1024


@dataclass
class UNetConfig(RealLightConfig):
    """Settings of :func:`~alcn_cv.train.unet.train_unet`: the gain Normalizer's data, objective and budget
    (:class:`RealLightConfig`, whose attributes it shares), with a U-Net for network.

    Attributes:
        net: :class:`~alcn_cv.train.unet_normalizer.UNetNormalizer` arguments (``--set net.channels=16``).
    """

    net: dict[str, Any] = field(default_factory=_unet_network)

    def check(self) -> None:
        """:meth:`RealLightConfig.check`, then the U-Net's: a ``crop`` of at least ``patch``, and ``net.levels`` from 1
        to the most whose coarsest level holds a pixel of the crop (level L sees it pooled 2 ** (L - 1) times; the
        widths double per level, so a count far past that builds a network of astronomic width, whose memory is gone
        before the first step), and ``net.channels`` from 1 to what keeps the widest level within
        :data:`MAX_UNET_WIDTH`.

        Raises:
            InputError: the first setting out of range, named by its key.
        """
        super().check()
        if self.crop < self.patch:
            raise InputError(f"need crop >= patch, got crop {self.crop} and patch {self.patch}")
        # the largest L with 2 ** (L - 1) <= crop, and with a channel at least at the widest level
        most = min(self.crop.bit_length(), MAX_UNET_WIDTH.bit_length())
        if not 1 <= self.net["levels"] <= most:
            raise InputError(
                f"config key 'net.levels' must be from 1 to {most} (level L sees the {self.crop}-pixel crop pooled to "
                f"1/2**(L-1), with 2**(L-1) times the channels, at most {MAX_UNET_WIDTH}), got {self.net['levels']}"
            )
        widest = MAX_UNET_WIDTH >> (self.net["levels"] - 1)
        if not 1 <= self.net["channels"] <= widest:
            raise InputError(
                f"config key 'net.channels' must be from 1 to {widest} (the widths double per level, and the widest "
                f"of {self.net['levels']} levels may have {MAX_UNET_WIDTH}), got {self.net['channels']}"
            )


#: ``alcn train-unet`` presets: ``gain``, the U-Net baseline trained as the ``gain`` preset of
#: :data:`REAL_LIGHT_CONFS` trains the gain Normalizer.
UNET_CONFS: dict[str, UNetConfig] = {"gain": UNetConfig()}

#: One line per preset of :data:`UNET_CONFS`, for ``alcn train-unet --help``.
UNET_CONF_SUMMARIES: dict[str, str] = {
    "gain": "train-real-light's gain preset with a U-Net of 8 channels and 3 levels for network",
}


@dataclass
class LiteDistillConfig:
    """Settings of :func:`~alcn_cv.train.distill.distill` (a :class:`~alcn_cv.nets.lite.LiteNormalizer`
    student); the defaults are the ``lite`` preset, the recipe of ``alcn_normalizer_lite.npz``.

    Attributes:
        teacher: a shipped model's name (``paper``) or a weight file.
        n_windows, n_val: training and validation windows rendered by
            :func:`alcn_cv.data.phos.render_windows` (seeds ``seed`` and ``seed + 1``).
        seed: seeds the windows and the student.
        epochs, batch_size, lr: Adam with a cosine learning-rate schedule.
        channels: the student's widths.
        weight_decay_w: weight of the plain squared weight error, relative to the output error.
        n_objects: catalogue size of the rendered windows.
    """

    teacher: str = "paper"
    n_windows: int = 20000
    n_val: int = 2000
    seed: int = 0
    epochs: int = 30
    batch_size: int = 256
    lr: float = 3e-3
    channels: list[int] = field(default_factory=lambda: [8, 16])
    weight_decay_w: float = 0.01
    n_objects: int = 100

    def check(self) -> None:
        """Before any work: ``channels`` two positive widths; the counts, ``lr`` and ``n_objects`` positive;
        ``seed`` and ``weight_decay_w`` not negative.

        Raises:
            InputError: the first setting out of range, named by its key.
        """
        if len(self.channels) != 2 or min(self.channels) < 1:
            raise InputError(f"config key 'channels' must list 2 positive widths, got {self.channels!r}")
        positive = ("n_windows", "n_val", "epochs", "batch_size", "lr", "n_objects")
        _check_ranges(dataclasses.asdict(self), positive, ("seed", "weight_decay_w"))


@dataclass
class GainDistillConfig:
    """Settings of :func:`~alcn_cv.train.distill.distill_gain` (a smaller gain Normalizer); the
    defaults are the ``gain-lite`` preset, the recipe of ``alcn_normalizer_gain_lite.npz``.

    Attributes:
        teacher: a shipped model's name (``gain``) or a gain weight file.
        scenes: registered scenes (as :attr:`RealLightConfig.scenes`; never the test scenes).
        relit, light: relit copies of the permissive photographs added to the data (as
            :attr:`RealLightConfig.relit` and :attr:`RealLightConfig.light`; 0: none).
        n_rendered: how many registered scenes are rendered and added to the data (256x256, 4 lights each).
        seed: seeds the student's initialisation, the relighting and the rendering.
        epochs, lr: Adam over every training frame once per epoch, cosine schedule.
        channels, dilations: the student's hidden width and its dilated 3x3 convolutions.
    """

    teacher: str = "gain"
    scenes: list[str] = field(default_factory=list)
    relit: int = 5
    light: str = "relief"
    n_rendered: int = 0
    seed: int = 0
    epochs: int = 60
    lr: float = 3e-3
    channels: int = 8
    dilations: list[int] = field(default_factory=lambda: [1, 2, 4])

    def check(self) -> None:
        """Before any work: ``epochs``, ``lr`` and ``channels`` positive; ``relit``, ``n_rendered`` and ``seed`` not
        negative; ``dilations`` a non-empty list of positive dilations.

        Raises:
            InputError: the first setting out of range, named by its key.
        """
        _check_ranges(dataclasses.asdict(self), ("epochs", "lr", "channels"), ("relit", "n_rendered", "seed"))
        if not self.dilations or min(self.dilations) < 1:
            raise InputError(f"config key 'dilations' must list positive dilations, got {self.dilations!r}")


#: ``alcn distill`` presets: ``lite`` makes ``alcn_normalizer_lite.npz``, ``gain-lite``
#: ``alcn_normalizer_gain_lite.npz``.
DISTILL_CONFS: dict[str, LiteDistillConfig | GainDistillConfig] = {
    "lite": LiteDistillConfig(),
    "gain-lite": GainDistillConfig(),
}

#: One line per preset of :data:`DISTILL_CONFS`, for ``alcn distill --help``.
DISTILL_CONF_SUMMARIES: dict[str, str] = {
    "lite": "the recipe of the shipped alcn_normalizer_lite.npz: a LiteNormalizer taught by the paper model",
    "gain-lite": "the recipe of the shipped alcn_normalizer_gain_lite.npz: a smaller gain Normalizer taught by the "
    "gain model",
}
