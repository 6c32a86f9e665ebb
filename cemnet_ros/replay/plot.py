"""Replay figure (matplotlib Agg): top-down trajectory, estimate vs ground truth, and per-pair error curves."""
from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Optional

import numpy as np

from cemnet_ros.io.atomic import atomic_write_bytes
from cemnet_ros.io.optional import optional_module
from cemnet_ros.replay.trajectory import RPEResult


def _plane_axes(positions: np.ndarray) -> tuple[int, int]:
    """The two world axes along which the trajectory spreads most (the 'top-down' view for any up axis)."""
    if len(positions) < 2:
        return 0, 1
    spread = positions.max(axis=0) - positions.min(axis=0)
    a, b = sorted(np.argsort(spread)[-2:])
    return int(a), int(b)


def _plot_rpe(axes, rpe: RPEResult) -> None:
    """Per-pair translation (cm) and rotation (deg) errors on two axes."""
    pairs = np.arange(1, len(rpe.trans_errors) + 1)
    for axis, values, color, what in ((axes[0], rpe.trans_errors * 100.0, "tab:blue", "translation error [cm]"),
                                      (axes[1], rpe.rot_errors_deg, "tab:orange", "rotation error [deg]")):
        axis.plot(pairs, values, "o-", color=color, ms=3)
        axis.set_xlabel("pair (scan i-1 -> i)")
        axis.set_ylabel(what)
        axis.set_title(f"relative {what.split()[0]} error")
        axis.grid(alpha=0.3)
        axis.set_ylim(bottom=0)


def save_replay_plot(path: str | os.PathLike, estimate: np.ndarray, ground_truth: Optional[np.ndarray] = None,
                     rpe: Optional[RPEResult] = None, title: str = "") -> Path:
    """Write the figure atomically. ``estimate``/``ground_truth``: (n,4,4) poses, the estimate already
    aligned onto the ground truth (see ATEResult.alignment); without ground truth only the path is drawn."""
    # no pyplot: Agg canvas, no global state, safe from threads; MissingOptional without matplotlib
    Figure = optional_module("matplotlib.figure", "the replay figure (replay.png)").Figure

    est = np.asarray(estimate, dtype=np.float64).reshape(-1, 4, 4)[:, :3, 3]
    gt = None if ground_truth is None else np.asarray(ground_truth, dtype=np.float64).reshape(-1, 4, 4)[:, :3, 3]
    has_rpe = rpe is not None and rpe.trans_errors.size > 0
    fig = Figure(figsize=(12 if has_rpe else 6, 5.5), constrained_layout=True)
    axes = fig.subplots(1, 3 if has_rpe else 1, squeeze=False)[0]
    a, b = _plane_axes(gt if gt is not None and len(gt) else est)
    names = "xyz"
    ax = axes[0]
    if gt is not None and len(gt):
        ax.plot(gt[:, a], gt[:, b], "k-", lw=2, label="ground truth")
    ax.plot(est[:, a], est[:, b], "o-", color="tab:red", ms=3, lw=1, label="CEMNet")
    if len(est):
        ax.plot(est[0, a], est[0, b], "s", color="tab:green", ms=7, label="start")
    ax.set_xlabel(f"{names[a]} [m]")
    ax.set_ylabel(f"{names[b]} [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(title or "trajectory (top-down)")
    if has_rpe:
        _plot_rpe(axes[1:], rpe)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_bytes(path, buf.getvalue())
