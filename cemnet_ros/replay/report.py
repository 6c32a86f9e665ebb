"""The replay's report: accuracy against the ground truth, speed, skipped messages, and the printed summary."""
from __future__ import annotations

from typing import Optional

import numpy as np

from cemnet_ros.replay.runner import ReplayResult
from cemnet_ros.replay.trajectory import absolute_trajectory_error, associate, relative_pose_errors


def evaluate(result: ReplayResult, gt_stamps: np.ndarray, gt_poses: np.ndarray) -> Optional[dict]:
    """ATE/RPE of the estimate against the ground truth at matching stamps (None without ground truth)."""
    if len(gt_stamps) == 0 or not result.poses:
        return None
    period = np.median(np.diff(gt_stamps)) if len(gt_stamps) > 1 else 1e8
    match = associate(result.stamps_ns, gt_stamps, max_dt_ns=int(max(period * 0.25, 1e6)))
    pairs = [(k, j) for k, j in enumerate(match) if j is not None]
    if len(pairs) < 1:
        return {"matched": 0, "error": "no scan stamp matches a ground-truth stamp"}
    est = np.stack([result.poses[k] for k, _ in pairs])
    gt = np.stack([gt_poses[j] for _, j in pairs])
    ate = absolute_trajectory_error(est, gt)
    rpe = relative_pose_errors(est, gt)
    per_pair = [{"pair": f"{result.steps[pairs[p][0]]['index']}->{result.steps[pairs[p + 1][0]]['index']}",
                 "trans_m": float(rpe.trans_errors[p]), "rot_deg": float(rpe.rot_errors_deg[p]),
                 "fitness": result.steps[pairs[p + 1][0]]["fitness"],
                 "accepted": result.steps[pairs[p + 1][0]]["accepted"]}
                for p in range(len(pairs) - 1)]
    return {"matched": len(pairs), "ate": {"rmse_m": ate.rmse, "mean_m": ate.mean, "median_m": ate.median,
                                           "max_m": ate.max},
            "rpe": rpe.stats(), "per_pair": per_pair, "_aligned": ate.alignment, "_est": est, "_gt": gt,
            "_rpe": rpe}


def speed(result: ReplayResult) -> dict:
    """Latency percentiles of the registrations, throughput of the pipeline and the wall time of the run."""
    lat = np.array([s["latency_s"] for s in result.steps], dtype=np.float64)
    # The first scan only sets the reference (no registration): keep it out of the latency figures.
    reg = np.array([s["latency_s"] for s in result.steps if not s["first"]], dtype=np.float64)
    busy = float(lat.sum())
    return {"latency_p50_s": float(np.percentile(reg, 50)) if reg.size else float("nan"),
            "latency_p95_s": float(np.percentile(reg, 95)) if reg.size else float("nan"),
            "latency_max_s": float(reg.max()) if reg.size else float("nan"),
            "throughput_scans_per_s": len(lat) / busy if busy > 0 else float("nan"),
            "wall_s": result.wall_s}


def format_report(bag: str, summary: dict, max_pairs: int = 20, worst: int = 10) -> str:
    """The printed report of a summary: accuracy (the ``worst`` pairs of long runs), speed, skipped messages."""
    lines = [f"bag: {bag}  ({summary['cloud_topic']}, {summary['scans']} scans, "
             f"scale {summary['scale_m_per_unit']:.3f} m/unit)"]
    acc = summary.get("accuracy")
    if acc and "ate" in acc:
        ate, rpe = acc["ate"], acc["rpe"]
        lines.append(f"ATE RMSE: {ate['rmse_m'] * 100:.2f} cm (max {ate['max_m'] * 100:.2f} cm, "
                     f"{acc['matched']} poses matched to ground truth)")
        lines.append(f"RPE translation: mean {rpe['trans_mean_m'] * 100:.2f} cm, "
                     f"median {rpe['trans_median_m'] * 100:.2f} cm, max {rpe['trans_max_m'] * 100:.2f} cm")
        lines.append(f"RPE rotation:    mean {rpe['rot_mean_deg']:.3f} deg, median {rpe['rot_median_deg']:.3f} deg, "
                     f"max {rpe['rot_max_deg']:.3f} deg")
        pairs = acc["per_pair"]
        shown = pairs if len(pairs) <= max_pairs else sorted(pairs, key=lambda p: -p["trans_m"])[:worst]
        lines.append("per-pair errors" + ("" if len(pairs) <= max_pairs else f" ({worst} worst of {len(pairs)})")
                     + ": pair  trans[cm]  rot[deg]  fitness")
        lines += [f"  {p['pair']:>7}  {p['trans_m'] * 100:8.2f}  {p['rot_deg']:8.3f}  {p['fitness']:.3f}"
                  + ("" if p["accepted"] else "  FLAGGED") for p in shown]
    elif acc:
        lines.append(f"ground truth present but unusable: {acc['error']}")
    else:
        lines.append("no ground truth in the bag: speed only")
    sp = summary["speed"]
    lines.append(f"latency p50 {sp['latency_p50_s'] * 1e3:.0f} ms, p95 {sp['latency_p95_s'] * 1e3:.0f} ms; "
                 f"throughput {sp['throughput_scans_per_s']:.2f} scans/s (wall {sp['wall_s']:.1f} s)")
    live = summary.get("live")
    if live:
        lines.append(f"live at {live['rate']:g}x the bag's timing (queue of {live['queue_size']}, scan budget "
                     f"{live['scan_budget']:g} periods): "
                     f"{live['processed']} of {live['scans']} scans processed, {live['dropped']} dropped, "
                     f"{live['behind']} started behind (effort {live['behind_effort']:g}); latency p50 "
                     f"{live['latency_ms_p50']:.0f} ms, p95 {live['latency_ms_p95']:.0f} ms, "
                     f"p99 {live['latency_ms_p99']:.0f} ms")
    lines.append(skipped_line(summary["skipped"], summary["messages"]))
    lines.append(f"rejected scans: {len(summary['rejected'])}; flagged steps: {len(summary['flagged'])}")
    lines += [f"  scan {r['index']}: {r['reason']}" for r in summary["rejected"] + summary["flagged"]]
    return "\n".join(lines)


def skipped_line(skipped: list[dict], n_messages: int, shown: int = 5) -> str:
    """E.g. ``skipped 2 of 120 messages: 1 truncated (t=12.300 s), 1 empty (t=15.100 s)``: the count per kind
    (first seen first) with the bag times (s since the bag's start) of its first ``shown`` messages."""
    times: dict[str, list[float]] = {}
    for s in skipped:
        times.setdefault(s["kind"], []).append(s["t_s"])
    parts = [f"{len(t)} {kind} (t={', '.join(f'{v:.3f}' for v in t[:shown])}{', ...' if len(t) > shown else ''} s)"
             for kind, t in times.items()]
    return f"skipped {len(skipped)} of {n_messages} messages" + (": " + ", ".join(parts) if parts else "")
