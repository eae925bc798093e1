"""The training configuration: one TOML schema, presets, and command-line overrides.

A configuration file is TOML (read with :mod:`tomllib`) with the tables below; every key is
optional and defaults to the ``default`` preset. ``alcn train --print-config`` writes the
effective configuration as TOML, a complete, commented-free starting point.

``seed`` (int)
    Seed of everything random in a run: network initialisation, shuffling, augmentation and,
    unless ``data.seed`` is set, the rendered training windows.

``[data]`` -- the stage-1 windows (Phos-like, :mod:`alcn_cv.data.phos`)
    ``path`` (str): folder written by ``alcn data phos`` holding the training windows; empty:
    render ``n_train`` windows in the process. ``val_path`` (str): the same for the validation
    windows; empty: render ``n_val``. ``n_train``, ``n_val`` (int): number of windows to render.
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
    ``method`` (str): ``"alcn"`` trains the Normalizer jointly with the detector (Eq. 2);
    ``"dog"`` and ``"none"`` train the same detector on a fixed Difference-of-Gaussians or on the
    raw windows, the comparison that tells whether the learned Normalizer helps.
    ``num_kernels`` (int), ``sigma_step`` (float): the Gaussian basis, ``sigma_i = i * step``.
    ``channels`` (list of 2 ints), ``hidden`` (int), ``activation`` (``"tanh"``, the paper's, or
    ``"relu"``): the Normalizer; the paper's is ``[20, 50]``, 1024 (the ``paper`` preset), the
    default ``[10, 20]``, 256 is five times cheaper (it predicts 10 numbers per window), which
    is what lets it train in 30 minutes on 2 shared CPU cores and run faster in ``apply``.
    ``output_scale`` (float): fixed factor on its outputs.
    ``init`` (``"dog"`` or ``"random"``): start the Normalizer at the DoG below (the last
    layer's weights at zero, its bias the DoG) or with every window's weights near zero.
    ``dog`` (list of 2 floats): sigmas (pixels, in the basis) of the DoG ``G_a - G_b`` used
    by ``init = "dog"`` and ``method = "dog"``. ``detector_channels`` (list of 2 ints),
    ``detector_hidden`` (int), ``detector_dropout`` (float): the detector.
    ``detector_input`` (``"standardize"`` or ``"raw"``): the detector input policy, applied to
    every method alike: per-window standardization (zero mean, unit variance over the 32x32) or
    the raw mixture output. ``working_scale`` (float): the scale recorded in the exported weight
    file, the factor from a camera frame to the resolution at which the 48x48 window applies.
    ``mixture`` (``"window"`` or ``"dense"``): how the Normalizer's weights filter a training
    window: ``"window"`` -- Eq. 1, one weight vector for the window (the paper's training);
    ``"dense"`` -- Eq. 3 as at inference: the Normalizer runs fully-convolutionally over the
    window and its per-pixel weight maps multiply the image before the blurs, so the weights
    may vary inside a window (e.g. across a shadow edge). A dense step costs about 6 times a window step.

``[optim]``
    ``objective``: ``"joint"`` -- Eq. 2, the detector and the Normalizer minimise the loss on
    every training window; ``"meta"`` -- the second stage rehearsed in the first: the detector
    minimises the loss on windows under ``data.anchor_lighting`` only (as a new detector will see
    one lighting), the Normalizer the loss on all windows with the detector held fixed for the
    others, so that it learns to make other lightings look like the anchor to a detector.
    ``optimizer`` (``"adam"`` or ``"sgd"``), ``lr`` (float, the detector's), ``normalizer_lr``
    (float), ``weight_decay`` (float), ``momentum`` (float, SGD), ``grad_clip`` (float, 0 = off),
    ``batch_size`` (int), ``epochs`` (int), ``schedule`` (``"cosine"``, ``"step"`` or
    ``"constant"``, per step), ``step_epochs`` (int) and ``step_gamma`` (float) for ``"step"``,
    ``warmup_steps`` (int, linear warm-up).

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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from alcn_cv.data.lighting import LIGHT_FAMILIES
from alcn_cv.errors import InputError

__all__ = ["PRESETS", "FewShotSetup", "RealLightConfig", "TrainConfig", "dump_toml", "load_config"]


@dataclass
class FewShotSetup:
    """Settings of the few-shot validation (:mod:`alcn_cv.train.fewshot`; here, without torch,
    so that ``alcn bench fewshot`` builds its command line without importing it)."""

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
        default_factory=lambda: ["ambient", "bright", "shadow", "point", "colour", "mixed"])
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
    activation: str = "tanh"
    output_scale: float = 1.0
    init: str = "dog"
    dog: list[float] = field(default_factory=lambda: [0.5, 1.5])
    detector_channels: list[int] = field(default_factory=lambda: [20, 50])
    detector_hidden: int = 512
    detector_dropout: float = 0.0
    detector_input: str = "standardize"
    mixture: str = "window"
    working_scale: float = 0.5


@dataclass
class OptimConfig:
    objective: str = "meta"
    optimizer: str = "adam"
    lr: float = 1e-3
    normalizer_lr: float = 1e-3
    weight_decay: float = 0.0
    momentum: float = 0.9
    grad_clip: float = 5.0
    batch_size: int = 128
    epochs: int = 3
    schedule: str = "cosine"
    step_epochs: int = 2
    step_gamma: float = 0.3
    warmup_steps: int = 100


@dataclass
class FewShotConfig:
    enabled: bool = True
    n_objects: int = 5
    real_images: int = 1
    per_image: int = 200
    n_test: int = 2000
    test_lighting: list[str] = field(default_factory=lambda: ["dark", "side", "spot", "shadow", "mixed"])
    epochs: int = 8
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


#: Named configurations (overrides of the defaults). ``default``: about 30 minutes on 2 CPU
#: cores; ``paper``: the paper's scale (500,000 windows, the paper's Normalizer), for a GPU.
PRESETS: dict[str, dict[str, Any]] = {
    "default": {},
    "paper": {
        "data": {"n_train": 500_000, "n_val": 20_000},
        "model": {"channels": [20, 50], "hidden": 1024, "detector_hidden": 1024},
        "fewshot": {"n_test": 10_000, "dog": [[0.5, 1.0], [0.5, 1.5], [0.5, 2.5], [1.0, 2.0], [1.0, 3.0]]},
        "optim": {"objective": "joint", "batch_size": 256, "epochs": 30, "warmup_steps": 1000},
        "run": {"device": "cuda", "workers": 8},
    },
}

_CHOICES = {
    "model.method": ("alcn", "dog", "none"),
    "model.activation": ("tanh", "relu"),
    "model.init": ("dog", "random"),
    "model.detector_input": ("standardize", "raw"),
    "model.mixture": ("window", "dense"),
    "optim.optimizer": ("adam", "sgd"),
    "optim.objective": ("joint", "meta"),
    "optim.schedule": ("cosine", "step", "constant"),
    "run.device": ("cpu", "cuda"),
}


def _type_name(kind: Any) -> str:
    return getattr(kind, "__name__", str(kind))


def _coerce(key: str, value: Any, default: Any) -> Any:
    """Check ``value`` against the type of ``default``; ints are accepted for floats."""
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        value = float(value) if ok else value
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif isinstance(default, list):
        free = key in _FREE_LISTS
        ok = isinstance(value, list) and (free or len(value) == len(default))
        if ok and default:
            value = [_coerce(f"{key}[{i}]" if isinstance(default[0], list) else key, v, default[0])
                     for i, v in enumerate(value)]
    else:
        ok = isinstance(value, type(default))
    if not ok:
        fixed_list = isinstance(default, list) and key not in _FREE_LISTS
        what = f"a list of {len(default)}" if fixed_list else _type_name(type(default))
        raise InputError(f"config key {key!r} must be {what}, got {value!r}")
    return value


_FREE_LISTS = {"data.train_lighting", "data.val_lighting", "fewshot.test_lighting", "fewshot.dog"}


def _merge(obj: Any, values: dict[str, Any], prefix: str = "") -> None:
    if not isinstance(values, dict):
        raise InputError(f"config key {prefix.rstrip('.')!r} must be a table, got {values!r}")
    names = {f.name for f in dataclasses.fields(obj)}
    for key, value in values.items():
        full = prefix + key
        if key not in names:
            raise InputError(f"unknown config key {full!r}; known keys here: {', '.join(sorted(names))}")
        current = getattr(obj, key)
        if dataclasses.is_dataclass(current):
            _merge(current, value, full + ".")
        else:
            setattr(obj, key, _coerce(full, value, current))


def _check(cfg: TrainConfig) -> None:
    flat = _flatten(cfg.to_dict())
    for key, choices in _CHOICES.items():
        if flat[key] not in choices:
            raise InputError(f"config key {key!r} must be one of {', '.join(choices)}, got {flat[key]!r}")
    positive = ["data.n_objects", "model.num_kernels", "model.hidden", "model.detector_hidden", "optim.batch_size",
                "optim.epochs", "optim.step_epochs", "run.log_every", "fewshot.n_objects", "fewshot.real_images",
                "fewshot.per_image", "fewshot.n_test", "fewshot.epochs", "model.sigma_step", "optim.lr",
                "model.output_scale", "model.working_scale"]
    for key in positive:
        if not flat[key] > 0:
            raise InputError(f"config key {key!r} must be positive, got {flat[key]!r}")
    for key in ["data.n_train", "data.n_val", "optim.normalizer_lr", "optim.weight_decay", "optim.grad_clip",
                "optim.warmup_steps", "run.workers", "run.threads", "optim.momentum"]:
        if flat[key] < 0:
            raise InputError(f"config key {key!r} must be >= 0, got {flat[key]!r}")
    if not 0 <= cfg.data.background_fraction <= 1:
        raise InputError(f"config key 'data.background_fraction' must be in [0, 1], got {cfg.data.background_fraction}")
    if cfg.optim.objective == "meta" and not cfg.data.path:
        if cfg.data.anchor_lighting not in cfg.data.train_lighting:
            raise InputError(f"config key 'data.anchor_lighting' ({cfg.data.anchor_lighting!r}) must be one of "
                             f"'data.train_lighting' {cfg.data.train_lighting}")
        if len(cfg.data.train_lighting) < 2 or not 0 < cfg.data.anchor_fraction < 1:
            raise InputError("config key 'data.anchor_fraction' must be in (0, 1), with another lighting beside the "
                             "anchor in 'data.train_lighting', for optim.objective = 'meta'")
    if not 0 <= cfg.model.detector_dropout < 1:
        raise InputError(f"config key 'model.detector_dropout' must be in [0, 1), got {cfg.model.detector_dropout}")
    lo, hi = cfg.data.gain_jitter
    if not 0 < lo <= hi:
        raise InputError(f"config key 'data.gain_jitter' must be 0 < lo <= hi, got {cfg.data.gain_jitter}")
    for key, names in (("data.train_lighting", cfg.data.train_lighting), ("data.val_lighting", cfg.data.val_lighting),
                       ("fewshot.test_lighting", cfg.fewshot.test_lighting)):
        bad = [s for s in names if s not in LIGHT_FAMILIES]
        if bad or not names:
            raise InputError(f"config key {key!r} must list lighting families of {LIGHT_FAMILIES}, got {names}")
    for pair in cfg.fewshot.dog:
        if len(pair) != 2:
            raise InputError(f"config key 'fewshot.dog' must list [a, b] sigma pairs, got {cfg.fewshot.dog}")
    overlap = set(cfg.data.train_lighting) & set(cfg.data.val_lighting)
    if overlap and not (cfg.data.path and cfg.data.val_path):
        raise InputError(f"config keys 'data.train_lighting' and 'data.val_lighting' share {sorted(overlap)}: "
                         "validation must use held-out lightings")
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


def _flatten(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[prefix + k] = v
    return out


def _parse_override(item: str) -> dict[str, Any]:
    """``"optim.lr=3e-4"`` -> ``{"optim": {"lr": 0.0003}}`` (the value is read as TOML, or a bare string)."""
    if "=" not in item:
        raise InputError(f"override {item!r} must be KEY=VALUE, e.g. optim.lr=3e-4")
    key, text = (s.strip() for s in item.split("=", 1))
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        value = text
    out: dict[str, Any] = {}
    node = out
    parts = key.split(".")
    for p in parts[:-1]:
        node = node.setdefault(p, {})
    node[parts[-1]] = value
    return out


def load_config(
    source: str | Path | dict[str, Any] | TrainConfig | None = None,
    overrides: list[str | dict[str, Any]] | dict[str, Any] | None = None,
) -> TrainConfig:
    """Build and check a configuration.

    Args:
        source: a preset name of :data:`PRESETS` (default ``"default"``), a path to a TOML
            file (applied over the defaults), a dict of the same shape, or a :class:`TrainConfig`.
        overrides: applied last, in order: ``"optim.lr=3e-4"`` strings (command-line ``--set``)
            and nested dicts (``{"optim": {"lr": 3e-4}}``), or one nested dict.

    Raises:
        InputError: unknown key, wrong type or impossible value (the message names the key),
            an unreadable TOML file, a missing data folder.
    """
    cfg = TrainConfig()
    if isinstance(source, TrainConfig):
        cfg = copy.deepcopy(source)
    elif isinstance(source, dict):
        _merge(cfg, source)
    elif source is None or str(source) in PRESETS:
        _merge(cfg, copy.deepcopy(PRESETS[str(source or "default")]))
    else:
        path = Path(source)
        if not path.is_file():
            raise InputError(f"config {source!r} is neither a preset ({', '.join(PRESETS)}) nor a file")
        try:
            values = tomllib.loads(path.read_text())
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise InputError(f"config file {path}: invalid TOML: {exc}") from None
        _merge(cfg, values)
    if isinstance(overrides, dict):
        _merge(cfg, overrides)
    else:
        for item in overrides or []:
            _merge(cfg, item if isinstance(item, dict) else _parse_override(item))
    _check(cfg)
    return cfg


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(v)


def dump_toml(cfg: TrainConfig) -> str:
    """The configuration as TOML text that :func:`load_config` reads back to the same values."""
    d = cfg.to_dict()
    lines = [f"{k} = {_toml_value(v)}" for k, v in d.items() if not isinstance(v, dict)]
    for table, values in d.items():
        if isinstance(values, dict):
            lines += ["", f"[{table}]"] + [f"{k} = {_toml_value(v)}" for k, v in values.items()]
    return "\n".join(lines) + "\n"


@dataclass
class RealLightConfig:
    """Settings of :func:`train_real_light` (defaults: the recipe of the shipped weights).

    Attributes:
        scenes: folders of registered frames, one per scene.
        rendered: folders of rendered registered scenes (``alcn data scenes``), drawn
            apart from ``scenes`` so that their number does not set their share.
        rendered_fraction: the share of steps that draw a rendered scene (0 when none).
        steps: optimisation steps; each sees 2 frames x ``locations`` crops of one scene.
        locations: textured locations (classes) per step.
        crop: side of the window the network sees (pixels).
        patch: side of the identified centre (pixels).
        min_distance: smallest distance between two locations of a step (pixels, Chebyshev).
        temperature: of the softmax over cosine similarities.
        consistency: weight of :func:`~alcn_cv.train.real_light.consistency_loss` (the output the
            same under both lights, on the textured and on ``anywhere`` other locations).
        anywhere: locations per step drawn anywhere in the frame (flat, dark and noisy regions
            too) for the consistency term only.
        lr: Adam's learning rate.
        seed: seeds numpy and torch (data draws and initialisation).
        save_every: steps between checkpoints and intermediate weight files.
        net: :class:`~alcn_cv.nets.gain.GainNormalizer` arguments (``divisive_sigma`` among them:
            the divisive normalization's per-pixel energy, absent for the grid's cells).
        command: the command line that ran the training, recorded in the weight file.
    """

    scenes: list[str] = field(default_factory=list)
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
    lr: float = 1e-3
    seed: int = 0
    save_every: int = 100
    net: dict = field(default_factory=dict)
    command: str = ""
