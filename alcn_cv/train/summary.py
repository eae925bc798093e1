"""The human-readable outputs of a training run: ``curves.png`` and ``summary.md``."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from alcn_cv.report import describe_machine, machine, markdown_table, new_figure, save_figure
from alcn_cv.train.checkpoint import versions
from alcn_cv.train.config import TrainConfig

if TYPE_CHECKING:
    from alcn_cv.train.trainer import TrainResult

__all__ = ["plot_curves", "summary_markdown"]


def plot_curves(history: list[dict[str, Any]], path: Path) -> None:
    """Loss and accuracy per epoch, training and held-out validation (per lighting family too)."""
    plt, fig, axes = new_figure(1, 2, figsize=(10, 4))
    ax1, ax2 = axes[0]
    epochs = [h["epoch"] for h in history]
    ax1.plot(epochs, [h["train_loss"] for h in history], "o-", label="training")
    ax1.plot(epochs, [h["val_loss"] for h in history], "o-", label="validation (held-out lightings)")
    ax1.set(xlabel="epoch", ylabel="cross-entropy", title="loss")
    ax2.plot(epochs, [h["train_acc"] for h in history], "o-", label="training")
    ax2.plot(epochs, [h["val_acc"] for h in history], "o-", lw=2, label="validation, all held-out")
    for fam in history[-1]["val_by_family"]:
        ax2.plot(epochs, [h["val_by_family"][fam] for h in history], ".--", label=f"validation, {fam}")
    ax2.set(xlabel="epoch", ylabel="accuracy", title="accuracy", ylim=(0, 1))
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(plt, fig, path, dpi=100)


def summary_markdown(cfg: TrainConfig, result: TrainResult, machine_start: dict[str, Any]) -> str:
    """A Markdown summary of a run: settings, time, machine, held-out and few-shot validation."""
    lines = [
        f"# `alcn train` run: {cfg.model.method}",
        "",
        f"- status: {result.status}; {len(result.history)} epoch(s); training "
        f"{result.history[-1]['seconds'] / 60 if result.history else 0:.1f} min (every process that ran it: a "
        f"resumed run's included), this process (data, training, few-shot validation, weight file) "
        f"{result.seconds / 60:.1f} min",
        f"- machine at start: {describe_machine(machine_start)}",
        f"- machine at end: {describe_machine(machine())}",
        f"- versions: {versions()}",
        f"- seed {cfg.seed}; configuration: `config.toml` in this folder",
        "",
        "## Held-out lightings (stage 1: the training objects, lighting families never trained on)",
        "",
        markdown_table(
            ["epoch", "train acc", "held-out acc", *result.val_by_family],
            [
                [
                    h["epoch"],
                    h["train_acc"],
                    h["val_acc"],
                    *(h["val_by_family"].get(f, float("nan")) for f in result.val_by_family),
                ]
                for h in result.history
            ],
            digits=4,
        ),
    ]
    if result.fewshot:
        families = list(next(iter(result.fewshot.values()))["by_family"])
        lines += [
            "",
            f"## Few-shot validation (stage 2: new objects, {cfg.fewshot.real_images} image(s) each under one light; "
            f"same detector and input policy `{cfg.model.detector_input}` for every method)",
            "",
            "AUC object vs. background (accuracy over background + objects in brackets)",
            "",
            markdown_table(
                ["method", "all", *families],
                [
                    [name, f"{r['auc']:.4f} ({r['accuracy']:.3f})", *(r["by_family"][f]["auc"] for f in families)]
                    for name, r in result.fewshot.items()
                ],
                digits=4,
            ),
        ]
    return "\n".join(lines)
