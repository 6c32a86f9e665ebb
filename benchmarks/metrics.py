"""The benchmark's step metrics: relative errors, recall / precision thresholds, summaries, ATE and end drift."""
from __future__ import annotations

from typing import Optional

import numpy as np

from cemnet_ros.core.geometry import rotation_angle_deg

RECALL_M, RECALL_DEG = 2.0, 5.0
PRECISE_M, PRECISE_DEG = 0.10, 0.5


def relative_error(estimated: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(RTE m, RRE deg) of an estimated relative motion against the true one."""
    error = np.linalg.inv(truth) @ estimated
    return float(np.linalg.norm(error[:3, 3])), rotation_angle_deg(error[:3, :3])


def within(rte: Optional[float], rre: Optional[float], max_m: float, max_deg: float) -> bool:
    """Whether a step's error is below both thresholds (a failed step, rte None, never is)."""
    return rte is not None and rte < max_m and rre < max_deg


def accepted_wrong(step: dict) -> bool:
    """Accepted although RTE > PRECISE_M or RRE > PRECISE_DEG (a non-finite error is wrong too)."""
    return bool(step["accepted"]) and not (step["rte_m"] <= PRECISE_M and step["rre_deg"] <= PRECISE_DEG)


def percentile(values: list[float], q: float) -> Optional[float]:
    """The ``q``-th percentile, None for no values."""
    return float(np.percentile(values, q)) if values else None


def summarize(steps: list[dict]) -> dict:
    """Counts and rates over step records (keys: accepted, rte_m, rre_deg, ms, error, case, index)."""
    n = len(steps)
    ok = [s for s in steps if s["error"] is None]
    acc = [s for s in ok if s["accepted"]]
    wrong = [s for s in steps if accepted_wrong(s)]
    return {
        "steps": n,
        "failed": n - len(ok),
        "flagged": sum(1 for s in ok if not s["accepted"]),
        "recall": sum(within(s["rte_m"], s["rre_deg"], RECALL_M, RECALL_DEG) for s in steps) / n if n else None,
        "precise": sum(within(s["rte_m"], s["rre_deg"], PRECISE_M, PRECISE_DEG) for s in steps) / n if n else None,
        "accepted_wrong": len(wrong),
        "accepted_wrong_steps": [{k: s[k] for k in ("case", "index", "rte_m", "rre_deg", "reason")} for s in wrong],
        "rte_median_accepted_m": percentile([s["rte_m"] for s in acc], 50),
        "rre_median_accepted_deg": percentile([s["rre_deg"] for s in acc], 50),
        "ms_median": percentile([s["ms"] for s in steps if s["ms"] is not None], 50),
        "ms_p90": percentile([s["ms"] for s in steps if s["ms"] is not None], 90),
        "errors": sorted({s["error"] for s in steps if s["error"] is not None}),
    }


def ate_first_pose(estimated: list[np.ndarray], truth: list[np.ndarray]) -> float:
    """Position RMSE (m) after expressing both trajectories in their first pose's frame (no other alignment)."""
    est0, gt0 = np.linalg.inv(estimated[0]), np.linalg.inv(truth[0])
    diff = [(est0 @ e)[:3, 3] - (gt0 @ g)[:3, 3] for e, g in zip(estimated, truth)]
    return float(np.sqrt(np.mean(np.sum(np.square(diff), axis=1))))


def end_drift_percent(estimated: list[np.ndarray], truth: list[np.ndarray], distance_m: float) -> Optional[float]:
    """End position error (both trajectories in their first pose's frame) as % of the driven ``distance_m``."""
    if distance_m <= 0:
        return None
    end_est = (np.linalg.inv(estimated[0]) @ estimated[-1])[:3, 3]
    end_gt = (np.linalg.inv(truth[0]) @ truth[-1])[:3, 3]
    return float(100.0 * np.linalg.norm(end_est - end_gt) / distance_m)
