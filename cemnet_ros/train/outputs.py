"""A training run's log files: ``log.csv`` (one row per epoch) and ``curves.png``, rewritten atomically each epoch."""
from __future__ import annotations

import csv
import io
import math
import warnings
from pathlib import Path
from typing import Any

from cemnet_ros.io.atomic import atomic_write_bytes, atomic_write_text
from cemnet_ros.io.optional import MissingOptional, optional_module

CSV_FIELDS = ("epoch", "global_step", "train_loss", "train_loss_final", "train_loss_prior", "train_loss_match",
              "train_loss_sigma", "skipped_batches",
              "val_loss", "val_mae_r_deg", "val_mae_t", "val_recall", "val_prior_mae_r_deg", "val_prior_mae_t",
              "lr", "train_time_s", "val_time_s", "best")


def fmt(value: Any) -> Any:
    """A finite float with 6 significant digits (as logged); anything else unchanged."""
    return f"{value:.6g}" if isinstance(value, float) and math.isfinite(value) else value


def write_log(out_dir: Path, rows: list[dict[str, Any]]) -> None:
    """``out_dir/log.csv``: the :data:`CSV_FIELDS` of every row ('' where an epoch has no value)."""
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=CSV_FIELDS, lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: fmt(row.get(k, "")) for k in CSV_FIELDS} for row in rows)
    atomic_write_text(out_dir / "log.csv", text.getvalue())


def _series(rows: list[dict[str, Any]], key: str) -> tuple[list[int], list[float]]:
    points = [(int(r["epoch"]), float(r[key])) for r in rows if r.get(key) not in ("", None)]
    return [p[0] for p in points], [p[1] for p in points]


def write_curves(out_dir: Path, rows: list[dict[str, Any]]) -> None:
    """``out_dir/curves.png``: the training losses, and the validation errors and recall per epoch. Without
    matplotlib a warning (once) instead: the checkpoints and log.csv are what training needs."""
    try:
        matplotlib = optional_module("matplotlib", "the training curves (curves.png)")
    except MissingOptional as exc:
        warnings.warn(f"curves.png not written: {exc}", RuntimeWarning, stacklevel=2)
        return
    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    fig, (ax_loss, ax_val) = plt.subplots(1, 2, figsize=(11, 4))
    for key, label in (("train_loss", "total"), ("train_loss_final", "final (mu_T)"),
                       ("train_loss_prior", "prior (mu_0)"), ("train_loss_match", "matching"),
                       ("train_loss_sigma", "sigma_0 NLL"), ("val_loss", "val final")):
        ax_loss.plot(*_series(rows, key), marker=".", label=label)
    ax_loss.set(xlabel="epoch", ylabel="loss (objective's terms)", title="training loss")
    ax_loss.legend()
    for key, label in (("val_mae_r_deg", "CEM (mu_T)"), ("val_prior_mae_r_deg", "prior (mu_0)")):
        ax_val.plot(*_series(rows, key), marker=".", label=label)
    ax_val.set(xlabel="epoch", ylabel="MAE(R) [deg]", title="validation")
    ax_val.legend(loc="upper left")
    ax_recall = ax_val.twinx()
    ax_recall.plot(*_series(rows, "val_recall"), color="tab:green", linestyle="--", marker=".", label="recall")
    ax_recall.set(ylabel="recall", ylim=(0.0, 1.05))
    ax_recall.legend(loc="upper right")
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    plt.close(fig)
    atomic_write_bytes(out_dir / "curves.png", buffer.getvalue())
