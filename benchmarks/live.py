"""Posed sequences played live into the node's session: what the node keeps up with at RATE x the sensor's timing.

Each run is a fresh :class:`~cemnet_ros.runtime.aligner_session.AlignerSession` (the node's aligner, its
``behind_effort`` rule) fed through :func:`~cemnet_ros.replay.realtime.play_live`: the node's queue on a virtual
clock, each scan taking the time its processing really takes here. Offline (rate None) every scan is aligned
with the full budgets. What came out (the processed scans) is scored against the reference as in
:mod:`.real`: ATE, end drift, steps off between consecutive processed scans, accepted apart from flagged, and
every step adjudicated as ``bench_real.py`` does (:mod:`.adjudication`: wrong only when off the data's own
optimum too).
"""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any, Mapping, Optional

import numpy as np

from benchmarks.adjudication import DataOptimum
from benchmarks.real import Sequence, StepResult, sequence_metrics
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.errors import ScanRejected
from cemnet_ros.replay.realtime import live_summary, play_live
from cemnet_ros.ros.node_config import NodeConfig
from cemnet_ros.runtime.aligner_session import AlignerSession
from cemnet_ros.runtime.extrinsic import BaseFrame
from cemnet_ros.schema import build

KEPT = ("ate_m", "end_drift_pct", "off_accepted", "off_flagged", "flagged", "recovered_share", "ms_p50", "ms_p95",
        "period_ms", "accepted_right", "accepted_wrong", "flagged_right", "flagged_wrong", "accepted_wrong_steps")


def live_run(sequence: Sequence, rate: Optional[float], overrides: Optional[Mapping[str, Any]] = None,
             node: Optional[NodeConfig] = None) -> dict[str, Any]:
    """``sequence`` through a fresh session, live at ``rate`` (None: offline); the live and accuracy figures."""
    node = node or NodeConfig()
    config = build(AlignerConfig(), {"preprocess.max_range": sequence.max_range, **(overrides or {})})
    session = AlignerSession(config, node, BaseFrame(np.eye(4)))
    if session.load() is None:
        raise RuntimeError(session.fatal_error)
    results: dict[int, StepResult] = {}
    index_of = {stamp_ns: k for k, stamp_ns in enumerate(sequence.stamps_ns)}
    def handle(k: int, backlog: Optional[int], period_s: Optional[float] = None) -> None:
        scan = SimpleNamespace(points=sequence.scans[k], stamp_ns=sequence.stamps_ns[k], times=None)
        try:
            step = session.process(scan, "", None, backlog, period_s).step
        except ScanRejected as exc:
            results[k] = StepResult(None, False, False, 0.0, str(exc))
            return
        results[k] = StepResult(step.pose, step.accepted, step.recovered, 1e3 * step.latency_s, step.reason,
                                step.answer, step.map_restarted)
        for stamp_ns in step.vouched_late:  # the node vouches for these now
            results[index_of[stamp_ns]].accepted = True

    indices = range(len(sequence.scans))
    if rate is None:
        for k in indices:
            handle(k, None)
        live = {"scans": len(indices), "processed": len(indices), "dropped": 0, "processed_share": 1.0,
                "behind": 0}
    else:
        live = live_summary(play_live(indices, lambda k: sequence.stamps_ns[k], rate, node.queue_size, handle))
    kept = sorted(results)
    processed = sequence.subset(kept)
    metrics = sequence_metrics(processed, [results[k] for k in kept], DataOptimum(processed.scans))
    return {"rate": rate, **live, **{k: metrics[k] for k in KEPT}, "off_steps": metrics["off_steps"]}


def bag_sequence(path: Path) -> Sequence:
    """A bag's decoded scans with the reference pose of each (the ground-truth message at its stamp)."""
    from cemnet_ros.replay.bag_io import BagReader, CloudFrame

    with BagReader(path) as reader:
        gt_stamps, gt_poses, _ = reader.ground_truth()
        frames = [f for f in reader.scans() if isinstance(f, CloudFrame)]
    if not len(gt_stamps):
        raise ValueError(f"{path}: no ground truth in the bag")
    nearest = [int(np.argmin(np.abs(gt_stamps - f.stamp_ns))) for f in frames]
    return Sequence(Path(path).name.split(".")[0], [f.points for f in frames], [gt_poses[i] for i in nearest],
                    [f.stamp_ns for f in frames], max_range=100.0)


def live_table(rows: list[dict[str, Any]]) -> str:
    """A markdown table: one row per sequence, method and rate."""
    out = ["| sequence | method | rate | processed | behind | latency p50 / p95 / p99 ms | step ms p50 / p95 "
           "| ATE m | drift % | off accepted / flagged | accepted right / wrong, flagged right / wrong |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]

    def f(value: Any, fmt: str = ".0f") -> str:
        return "-" if value is None else format(value, fmt)

    for r in rows:
        rate = "offline" if r["rate"] is None else f"{r['rate']:g}x"
        latency = " / ".join(f(r.get(f"latency_ms_p{q}")) for q in (50, 95, 99))
        out.append(f"| {r['sequence']} | {r['method']} | {rate} | {r['processed']} / {r['scans']} | "
                   f"{f(r['behind'])} | {latency} | {f(r['ms_p50'])} / {f(r['ms_p95'])} | {f(r['ate_m'], '.3f')} | "
                   f"{f(r['end_drift_pct'], '.2f')} | {r['off_accepted']} / {r['off_flagged']} | "
                   + " / ".join(f(r.get(k), "d") for k in ("accepted_right", "accepted_wrong", "flagged_right",
                                                           "flagged_wrong")) + " |")
    return "\n".join(out)
