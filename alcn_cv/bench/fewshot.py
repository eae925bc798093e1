"""``alcn bench fewshot``: the few-shot validation (:mod:`alcn_cv.train.fewshot`) on any registered normalization.

The validation asks whether a detector trained from one image under one light of a *new*
object still works under other lights once the windows are normalized (Rad, Roth & Lepetit,
BMVC 2017, Sec. 4.3, at the window level). Here every method is a registered normalization
spec (``NAME[:KEY=VALUE...]``, e.g. ``alcn:model=gain`` or ``alcn:weights=FILE.npz``) and
reaches the detector the same way:

1. **Windows** (:func:`alcn_cv.train.fewshot.make_fewshot_data`): the paper's simple synthetic
   images of ``n_objects`` rendered objects (``real_images`` images each, training-like light)
   and background windows; test windows of the same objects and background under held-out
   lighting families. 64x64 each, drawn once per seed and shared by every method.
2. **Normalization** through the runtime's public window API,
   :meth:`~alcn_cv.enhance.base.Normalization.normalize_windows` (ALCN: Eq. 1, one weight
   vector per window from its centre 48x48), on training and test windows alike; the windows
   are at the working scale, so ALCN runs with ``scale=1``
   (:func:`alcn_cv.bench.detect.create_normalization`, as in ``alcn bench detect``).
3. **Input policy** (:class:`alcn_cv.bench.policies.InputPolicy`, the detection benchmark's),
   the same for every method: ``raw`` (one affine map fitted on the training windows),
   ``local`` (31x31 local standardization) or ``standardize`` (each 32x32 window alone).
4. **Detector** (:func:`alcn_cv.train.fewshot.score_inputs`): the same network and training for
   every method; accuracy (background + objects) and the ROC AUC of object vs. background on
   the test windows, overall and per lighting family.

Every seed (``--seeds``, as in ``alcn bench detect``) is one repetition with its own objects (catalogue seed
``object_seed + seed``), windows and detector initialisation (seed ``seed``). The report says, per seed and
policy, whether each ALCN variant's AUC is above the best DoG's.

**Tuning** (``--tune``, as in ``alcn bench detect``): the methods of
:data:`~alcn_cv.bench.detect.TUNING_GRIDS` that the run lists by bare name (``dog``, ``slcn``, ``dlcn``) try each
setting of their grid (the default first) on a validation draw of its own: new objects (catalogue seed
``object_seed - 1``, which no seed's objects use) and windows of seed :data:`VALIDATION_SEED`; a setting scores the
validation AUC of the same detector, averaged over the run's policies, and the first best serves every seed.

Outputs: ``fewshot.json`` (every number, settings, machine, command), ``fewshot.md`` and
``fewshot.png`` (AUC per method, one point per seed).
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from alcn_cv.bench.detect import TUNING_GRIDS, best_trial, create_normalization
from alcn_cv.bench.detect_report import chosen_trial
from alcn_cv.bench.detect_settings import POLICIES, POLICY_DESCRIPTIONS
from alcn_cv.bench.methods import build_methods
from alcn_cv.bench.policies import InputPolicy
from alcn_cv.checks import check_seeds
from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import available, format_spec, parse_spec
from alcn_cv.errors import InputError
from alcn_cv.io import atomic_paths, atomic_write, check_no_earlier_output, holds_out_dir, make_folder, write_json
from alcn_cv.report import (
    command_line,
    describe_machine,
    machine,
    markdown_table,
    nan_to_none,
    new_figure,
    save_figure,
    spread,
    spread_cell,
)
from alcn_cv.train.config import FewShotSetup

__all__ = [
    "DEFAULT_METHODS",
    "VALIDATION_SEED",
    "FewShotSettings",
    "compare_to_dog",
    "fewshot_command",
    "fewshot_markdown",
    "main",
]

logger = logging.getLogger(__name__)

#: The methods compared by default.
DEFAULT_METHODS = ("none", "dog", "dlcn", "tantriggs", "alcn", "alcn:model=lite")
#: The windows' and detector's seed of the validation draw that ``--tune`` scores on (its objects: catalogue seed
#: ``object_seed - 1``); far from the seeds runs repeat with.
VALIDATION_SEED = 999_983


@dataclass
class FewShotSettings:
    """Settings of ``alcn bench fewshot`` (all recorded in ``fewshot.json``); the fields of
    :class:`~alcn_cv.train.config.FewShotSetup` are named and default as there.

    Attributes:
        methods: registered normalization specs ``NAME[:KEY=VALUE...]``.
        policies: detector input policies (:data:`~alcn_cv.bench.detect_settings.POLICIES`).
        seeds: one repetition per seed, each with its own objects, windows and detector initialisation
            (``--seeds``, as in ``alcn bench detect``); the tables give the mean and spread over seeds.
        n_objects: new objects per seed.
        object_seed: catalogue seed of seed 0 (seed ``s`` uses ``object_seed + s``).
        real_images: reference images per object.
        per_image: synthetic training windows per reference image (as many background windows).
        n_test: test windows per seed (half background).
        test_lighting: lighting families of the test windows.
        epochs, batch_size, lr: detector training (the same for every method).
        tune: tune the methods of :data:`~alcn_cv.bench.detect.TUNING_GRIDS` listed by bare name on a validation
            draw first (see the module).
        threads: torch threads (``None``: torch's default).
    """

    methods: list[str] = field(default_factory=lambda: list(DEFAULT_METHODS))
    policies: list[str] = field(default_factory=lambda: ["raw", "local"])
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2])
    n_objects: int = FewShotSetup.n_objects
    object_seed: int = FewShotSetup.object_seed
    real_images: int = FewShotSetup.real_images
    per_image: int = FewShotSetup.per_image
    n_test: int = FewShotSetup.n_test
    test_lighting: list[str] = field(default_factory=lambda: list(FewShotSetup.test_lighting))
    epochs: int = FewShotSetup.epochs
    batch_size: int = FewShotSetup.batch_size
    lr: float = FewShotSetup.lr
    tune: bool = False
    threads: int | None = None

    def check(self) -> FewShotSettings:
        """Raise :class:`~alcn_cv.errors.InputError` on an unknown method or policy, or a value out of range."""
        unknown = [m for m in self.methods if parse_spec(m)[0] not in available()]
        if unknown or not self.methods:
            raise InputError(f"unknown or no method(s) {unknown}; available: {', '.join(available())}")
        bad = [p for p in self.policies if p not in POLICIES]
        if bad or not self.policies:
            raise InputError(f"unknown or no policy {bad}; choose from {', '.join(POLICIES)}")
        check_seeds(self.seeds)
        if (
            min(
                self.n_objects,
                self.real_images,
                self.per_image,
                self.n_test,
                self.epochs,
                self.batch_size,
            )
            < 1
            or not self.lr > 0
        ):
            raise InputError("n_objects, real_images, per_image, n_test, epochs and batch_size must be >= 1 and lr > 0")
        # a catalogue seed is a non-negative integer; tuning draws its validation objects from object_seed - 1
        tunes = self.tune and any(m in TUNING_GRIDS for m in self.methods)
        if self.object_seed < (1 if tunes else 0):
            raise InputError(
                f"--object-seed must be at least 0, and at least 1 with --tune (its validation objects use it - 1), "
                f"got {self.object_seed}"
            )
        if self.threads is not None and self.threads < 1:
            raise InputError(f"threads must be >= 1 or None (torch's default), got {self.threads}")
        return self

    def setup(self, seed: int) -> FewShotSetup:
        """The few-shot setup of one seed."""
        return FewShotSetup.of(self, object_seed=self.object_seed + seed, seed=seed)


def _tune(settings: FewShotSettings, progress: bool) -> dict[str, Any]:
    """The settings chosen by ``--tune`` (see the module): ``{method: {"params", "trials": [{"params", "val_auc",
    "val_auc_by_policy"}, ...]}}``; empty without ``settings.tune`` or a tunable method."""
    from alcn_cv.train.fewshot import make_fewshot_data, score_inputs  # torch: only when tuning runs

    methods = [m for m in TUNING_GRIDS if m in settings.methods] if settings.tune else []
    if not methods:
        return {}
    setup = FewShotSetup.of(settings, object_seed=settings.object_seed - 1, seed=VALIDATION_SEED)
    train_x, train_y, val = make_fewshot_data(setup)
    tuned: dict[str, Any] = {}
    total = sum(len(TUNING_GRIDS[m]) for m in methods)
    with tqdm(total=total, desc="few-shot tuning", unit="setting", disable=not progress) as bar:
        for method in methods:
            trials = []
            for params in TUNING_GRIDS[method]:
                spec = format_spec(method, params)
                bar.set_postfix(setting=spec)
                norm = create_normalization(method, params)
                train_n, val_n = norm.normalize_windows(train_x), norm.normalize_windows(val.windows)
                by_policy = {}
                for policy_name in settings.policies:
                    policy = InputPolicy(policy_name, train_n)
                    scored = score_inputs(
                        f"{spec} ({policy_name}, validation)",
                        policy.windows(train_n),
                        train_y,
                        policy.windows(val_n),
                        val,
                        setup,
                    )
                    by_policy[policy_name] = float(scored["auc"])
                trials.append(
                    {
                        "params": params,
                        "val_auc": float(np.mean(list(by_policy.values()))),
                        "val_auc_by_policy": by_policy,
                    }
                )
                bar.update()
            best = best_trial(trials)
            tuned[method] = {"params": dict(best["params"]), "trials": trials}
            logger.info("tuned %s: %s (validation AUC %.4f)", method, best["params"], best["val_auc"])
    return tuned


def _is(spec: str, name: str) -> bool:
    return parse_spec(spec)[0] == name


def compare_to_dog(runs: dict[str, Any], settings: FewShotSettings) -> dict[str, Any]:
    """Per policy, ALCN variant and seed: its AUC against the best DoG's (every ``dog`` spec run).

    Returns:
        ``{policy: {variant: [{"seed", "auc", "dog", "dog_auc", "margin", "above"}, ...]}}``, one entry per seed
        in the order of ``settings.seeds``; empty without a DoG or an ALCN among the methods.
    """
    dogs = [m for m in settings.methods if _is(m, "dog")]
    variants = [m for m in settings.methods if _is(m, "alcn")]
    out: dict[str, Any] = {}
    for policy in settings.policies:
        out[policy] = {}
        for variant in variants:
            rows = []
            for i, seed in enumerate(settings.seeds):
                done = [(runs[policy][m][i]["auc"], m) for m in dogs if runs[policy][m][i].get("auc") is not None]
                mine = runs[policy][variant][i]
                if not done or mine.get("auc") is None:
                    rows.append({"seed": seed, "above": None})
                    continue
                dog_auc, dog = max(done)
                rows.append(
                    {
                        "seed": seed,
                        "auc": mine["auc"],
                        "dog": dog,
                        "dog_auc": dog_auc,
                        "margin": mine["auc"] - dog_auc,
                        "above": bool(mine["auc"] > dog_auc),
                    }
                )
            out[policy][variant] = rows
    return out if dogs and variants else {}


def _run_seed(
    settings: FewShotSettings, seed: int, norms: dict[str, Normalization], runs: dict[str, Any], bar: tqdm
) -> None:
    """Every method (``norms``, built once) and policy on one seed's windows; a failing method is recorded with its
    error."""
    from alcn_cv.train.fewshot import make_fewshot_data, score_inputs  # torch: only when a seed runs

    setup = settings.setup(seed)
    train_x, train_y, test = make_fewshot_data(setup)
    for method in settings.methods:
        t0 = time.perf_counter()
        try:
            norm = norms[method]
            train_n, test_n = norm.normalize_windows(train_x), norm.normalize_windows(test.windows)
            normalize_s = time.perf_counter() - t0
        except Exception as exc:  # built up front: what fails here is the run's, reported
            logger.error("few-shot %s, seed %d: %s: %s", method, seed, type(exc).__name__, exc)
            for policy in settings.policies:
                runs[policy][method].append({"seed": seed, "error": f"{type(exc).__name__}: {exc}"})
                bar.update()
            continue
        for policy_name in settings.policies:
            bar.set_postfix(run=f"{method}|{policy_name}|{seed}")
            t1 = time.perf_counter()
            try:
                policy = InputPolicy(policy_name, train_n)
                entry = nan_to_none(
                    score_inputs(
                        f"{method} ({policy_name}, seed {seed})",
                        policy.windows(train_n),
                        train_y,
                        policy.windows(test_n),
                        test,
                        setup,
                    )
                )
                entry.update(
                    seed=seed,
                    policy=policy.to_dict(),
                    seconds={"normalize": normalize_s, "train_and_test": time.perf_counter() - t1},
                )
            except Exception as exc:
                logger.error("few-shot %s, %s, seed %d: %s: %s", method, policy_name, seed, type(exc).__name__, exc)
                entry = {"seed": seed, "error": f"{type(exc).__name__}: {exc}"}
            runs[policy_name][method].append(entry)
            bar.update()


def _summary(runs: dict[str, Any]) -> dict[str, Any]:
    return {
        policy: {
            method: {
                metric: spread([r[metric] for r in seeded if r.get(metric) is not None])
                for metric in ("auc", "accuracy")
            }
            for method, seeded in by_method.items()
        }
        for policy, by_method in runs.items()
    }


def fewshot_command(out_dir: str | os.PathLike, settings: FewShotSettings) -> str:
    """The ``alcn bench fewshot`` command line that runs these settings (every setting spelled out)."""
    # the seeds in the space form of --seeds, as alcn bench detect records them (command_line joins a list with commas)
    seeds = ["--seeds", *map(str, settings.seeds)]
    return command_line(
        ["alcn", "bench", "fewshot", "--out", out_dir, *seeds],
        {
            "--methods": settings.methods,
            "--policy": settings.policies,
            "--objects": settings.n_objects,
            "--object-seed": settings.object_seed,
            "--real-images": settings.real_images,
            "--per-image": settings.per_image,
            "--n-test": settings.n_test,
            "--test-lighting": settings.test_lighting,
            "--epochs": settings.epochs,
            "--batch-size": settings.batch_size,
            "--lr": settings.lr,
            "--tune": settings.tune,
            "--threads": settings.threads,
        },
    )


def fewshot_markdown(result: dict[str, Any]) -> str:
    """``fewshot.md``: machine, command, settings, policies, AUC per seed and ALCN against DoG."""
    s = result["settings"]
    seeds = s["seeds"]
    lines = [
        "# Few-shot validation: every normalization with the same detector\n",
        "A detector is trained from the simple synthetic images of new rendered objects seen in "
        f"{s['real_images']} image(s) each under one light, and tested on windows of the same objects and background "
        f"under held-out lighting ({', '.join(s['test_lighting'])}). Every method normalizes training and test windows "
        "through `Normalization.normalize_windows` (ALCN: Eq. 1), then the same input policy and the same detector "
        "(Rad, Roth & Lepetit, BMVC 2017, Sec. 4.3). AUC = ROC AUC of object vs. background (score 1 - p(background); "
        f"chance 0.5); accuracy: the most probable of background and the {s['n_objects']} object(s), over test windows "
        "half of which are background (a detector that says background everywhere scores 0.5). Spreads are sample "
        "standard deviations over the seeds.\n",
        f"- **Machine:** {describe_machine(result['machine'])}",
        f"- **Command:** `{result['command']}`",
        f"- **Settings:** seeds {', '.join(map(str, seeds))} (seed s: objects of catalogue seed {s['object_seed']} "
        f"+ s, windows and detector seed s); {s['n_objects']} objects, {s['per_image']} synthetic windows per image "
        f"and as many background windows; {s['n_test']} test windows; detector {s['epochs']} epochs, batch "
        f"{s['batch_size']}, Adam lr {s['lr']}. Total time {result['seconds']:.0f} s.",
        "- **Input policies** (the same for every method):",
        *[f"  - `{p}`: {POLICY_DESCRIPTIONS[p]}" for p in s["policies"]],
        "",
    ]
    if result.get("tuned"):
        lines.append("## Tuned on the validation draw (AUC averaged over the policies)\n")
        rows = [
            [
                method,
                format_spec(method, t["params"]),
                chosen_trial(t)["val_auc"],
                t["trials"][0]["val_auc"],
            ]
            for method, t in result["tuned"].items()
        ]
        lines += [markdown_table(["method", "chosen", "validation AUC", "default's"], rows), ""]
    for policy, by_method in result["runs"].items():
        lines.append(f"## AUC, policy `{policy}`\n")
        rows = []
        for method, seeded in by_method.items():
            summary = result["summary"][policy][method]
            tuned = result.get("tuned", {}).get(method)
            rows.append(
                [method if tuned is None else f"{format_spec(method, tuned['params'])} (tuned)"]
                + ["failed" if "error" in r else r["auc"] for r in seeded]
                + [spread_cell(summary["auc"]), spread_cell(summary["accuracy"])]
            )
        stat = " mean ± std" if len(seeds) > 1 else ""
        lines += [
            markdown_table(["method"] + [f"seed {d}" for d in seeds] + [f"AUC{stat}", f"accuracy{stat}"], rows),
            "",
        ]
    if result["alcn_vs_dog"]:
        lines.append("## ALCN against the best DoG, per seed (AUC margin; ✓ above, ✗ not)\n")
        rows = []
        for policy, variants in result["alcn_vs_dog"].items():
            for variant, seeded in variants.items():
                cells = [
                    "-" if r["above"] is None else f"{r['margin']:+.4f} {'✓' if r['above'] else '✗'}" for r in seeded
                ]
                rows.append([variant, policy] + cells + [f"{sum(bool(r['above']) for r in seeded)}/{len(seeded)}"])
        lines += [markdown_table(["ALCN", "policy"] + [f"seed {d}" for d in seeds] + ["above"], rows), ""]
    errors = [
        f"- `{m}` ({p}, seed {r['seed']}): {r['error']}"
        for p, bm in result["runs"].items()
        for m, seeded in bm.items()
        for r in seeded
        if "error" in r
    ]
    if errors:
        lines += ["## Failed runs\n", *errors, ""]
    return "\n".join(lines)


def _figure(result: dict[str, Any], path: Path) -> Path:
    """AUC per method: the mean over seeds as a bar, every seed as a point; one panel per policy."""
    policies = list(result["runs"])
    plt, fig, axes = new_figure(1, len(policies), figsize=(5.5 * len(policies), 4.5))
    lowest = min(
        [r["auc"] for bm in result["runs"].values() for d in bm.values() for r in d if r.get("auc") is not None],
        default=0.5,
    )
    for ax, policy in zip(axes[0], policies):
        by_method = result["runs"][policy]
        methods = list(by_method)
        for i, method in enumerate(methods):
            values = [r["auc"] for r in by_method[method] if r.get("auc") is not None]
            if values:
                ax.bar(i, np.mean(values), color="tab:orange" if _is(method, "alcn") else "tab:blue", alpha=0.6)
                ax.plot([i] * len(values), values, "k.", markersize=5)
        ax.set_xticks(range(len(methods)))
        ax.set_xticklabels(methods, rotation=35, ha="right", fontsize=8)
        ax.set_ylabel("ROC AUC, object vs. background")
        ax.set_title(f"policy {policy}")
        ax.set_ylim(min(0.5, lowest - 0.02), 1.0)
        ax.grid(axis="y", alpha=0.3)
    fig.suptitle("Few-shot validation (bars: mean over seeds; points: seeds)")
    fig.tight_layout()
    return save_figure(plt, fig, path)


@holds_out_dir
def main(
    out_dir: str | os.PathLike,
    settings: FewShotSettings | None = None,
    command: str | None = None,
    progress: bool = True,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Run the few-shot validation on registered normalizations (see the module docstring) and write its report.

    Args:
        out_dir: output folder (created).
        settings: default :class:`FewShotSettings`.
        command: the command line to record (default: the one that runs ``settings``).
        progress: progress bar across runs.
        overwrite: replace the report of an earlier run in ``out_dir``.

    Returns:
        The dictionary written to ``fewshot.json``: ``runs`` (policy -> method -> one result of
        :func:`~alcn_cv.train.fewshot.score_inputs` per seed, in the order of ``settings.seeds``, or its ``error``),
        ``summary`` (mean and spread over seeds), ``alcn_vs_dog`` (:func:`compare_to_dog`), ``tuned`` (the settings
        ``--tune`` chose and every setting's validation AUC).

    Raises:
        InputError: bad settings, a method that cannot be built (a bad parameter or weight file), or an
            ``out_dir`` that holds an earlier run's report (without ``overwrite``), before any seed runs.
    """
    import torch

    settings = (settings or FewShotSettings()).check()
    check_no_earlier_output([Path(out_dir) / "fewshot.json", Path(out_dir) / "fewshot.md"], overwrite)
    # a bad spec or weight file: one line before any seed runs
    norms = build_methods(settings.methods, create_normalization)
    if settings.threads:
        torch.set_num_threads(settings.threads)
    start = time.perf_counter()
    out = Path(out_dir)
    make_folder(out)
    tuned = _tune(settings, progress)
    norms |= {method: create_normalization(method, t["params"]) for method, t in tuned.items()}
    runs: dict[str, Any] = {p: {m: [] for m in settings.methods} for p in settings.policies}
    total = len(settings.seeds) * len(settings.methods) * len(settings.policies)
    with tqdm(total=total, desc="few-shot validation", unit="run", disable=not progress) as bar:
        for seed in settings.seeds:
            _run_seed(settings, seed, norms, runs, bar)
    result = {
        "benchmark": "fewshot",
        "command": command or fewshot_command(out_dir, settings),
        "settings": asdict(settings),
        "machine": machine(),
        "tuned": nan_to_none(tuned),
        "runs": runs,
        "summary": _summary(runs),
        "alcn_vs_dog": compare_to_dog(runs, settings),
    }
    result["seconds"] = time.perf_counter() - start
    result["figure"] = str(out / "fewshot.png")
    # all or none: an interrupt leaves an earlier report whole
    with atomic_paths(out / "fewshot.png", out / "fewshot.json", out / "fewshot.md") as (png, json_path, md):
        _figure(result, png)
        write_json(json_path, result)
        atomic_write(md, fewshot_markdown(result))
    logger.info("few-shot validation written to %s in %.0f s", out, result["seconds"])
    return result
