"""The node's published covariance against ground truth on real sequences, for each ``covariance_mode``.

Each sequence goes once through the node's pipeline (a ScanAligner with the node's defaults, the sensor as the
base); every step is turned into what align_node publishes (:func:`~cemnet_ros.runtime.odometry_output.
odometry_output`) once per mode: the modes change only the covariance, never the trajectory. Per mode: the NEES
of every step with a known motion (:mod:`.nees`; the first step and map restarts have none), flagged steps
included (a back end receives them too), and a pose graph of the odometry closed by the true first-to-last
motion (:mod:`.pose_graph`): how much closing the loop helps depends on how well the covariances share the error.
"""
from __future__ import annotations

import dataclasses
from typing import Optional

import numpy as np

from benchmarks.metrics import ate_first_pose
from benchmarks.nees import step_consistency, step_error
from benchmarks.pose_graph import close_loop
from benchmarks.real import Sequence
from cemnet_ros.io.console import progress
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.ros.node_config import NodeConfig
from cemnet_ros.runtime.extrinsic import BaseFrame, in_body_axes
from cemnet_ros.runtime.odometry_output import odometry_output

MODES = ("registration", "fixed")


@dataclasses.dataclass
class ModeTrace:
    """What one covariance mode published over a sequence."""

    poses: list[np.ndarray] = dataclasses.field(default_factory=list)  # T_odom_base of every step
    errors: list[np.ndarray] = dataclasses.field(default_factory=list)  # step errors (steps with a motion)
    covariances: list[np.ndarray] = dataclasses.field(default_factory=list)  # their pose covariances
    body_covariances: list[Optional[np.ndarray]] = dataclasses.field(default_factory=list)  # per step, base axes


def run_modes(sequence: Sequence, config: Optional[AlignerConfig] = None) -> tuple[dict[str, ModeTrace], list]:
    """Every scan through one ScanAligner; the outputs of each mode; and per-step records for the report."""
    from cemnet_ros.pipeline.aligner import ScanAligner

    config = config or AlignerConfig()
    aligner, base = ScanAligner(config), BaseFrame(np.eye(4))
    nodes = {mode: dataclasses.replace(NodeConfig(), covariance_mode=mode) for mode in MODES}
    traces = {mode: ModeTrace() for mode in MODES}
    records, previous_stamp = [], None
    for k in progress(range(len(sequence.scans)), desc=sequence.name):
        step = aligner.process(sequence.scans[k], sequence.stamps_ns[k])
        dt_s = None if previous_stamp is None else (step.stamp_ns - previous_stamp) * 1e-9
        previous_stamp = step.stamp_ns
        known = step.relative is not None  # a motion to compare: not the first step, nor a map restart
        record: dict = {"index": k, "accepted": bool(step.accepted)}
        for mode, trace in traces.items():
            out = odometry_output(step, base, dt_s, nodes[mode], config.health.covariance_inflation)
            trace.body_covariances.append(in_body_axes(out.pose_covariance, out.T_odom_base) if known else None)
            if known:
                error = step_error(trace.poses[-1], out.T_odom_base, sequence.poses[k - 1], sequence.poses[k])
                trace.errors.append(error)
                trace.covariances.append(out.pose_covariance)
                record["error"] = error
                record[f"std_{mode}"] = np.sqrt(np.diag(out.pose_covariance))
            trace.poses.append(out.T_odom_base)
        records.append(record)
    return traces, records


def loop_closure(sequence: Sequence, trace: ModeTrace) -> dict[str, float]:
    """ATE (m, first poses aligned) of the odometry and of the pose graph that the true first-to-last motion
    closes (std 1 mm / 1 mrad), the odometry's factors weighted by this mode's covariances."""
    T_first_last = np.linalg.inv(sequence.poses[0]) @ sequence.poses[-1]
    closed = close_loop(trace.poses, trace.body_covariances, T_first_last)
    return {"ate_odometry_m": ate_first_pose(trace.poses, sequence.poses),
            "ate_closed_m": ate_first_pose(closed, sequence.poses)}


def evaluate(sequence: Sequence, config: Optional[AlignerConfig] = None) -> dict:
    """Per mode: NEES consistency (:func:`~.nees.step_consistency`) and the loop closure; the RMS of the step
    errors per axis (what ``fixed`` variances would have to be); the per-step records."""
    traces, records = run_modes(sequence, config)
    modes = {mode: {**step_consistency(t.errors, t.covariances), **loop_closure(sequence, t)}
             for mode, t in traces.items()}
    errors = np.array(traces[MODES[0]].errors).reshape(-1, 6)
    rms = np.sqrt(np.mean(errors ** 2, axis=0)) if len(errors) else np.full(6, np.nan)
    return {"scans": len(sequence.scans), "flagged": sum(not r["accepted"] for r in records[1:]),
            "rms_step_error": {"x_y_z_m": rms[:3], "roll_pitch_yaw_rad": rms[3:]}, "modes": modes, "steps": records}


def nees_table(results: dict) -> str:
    """A markdown table: one row per sequence and mode."""
    rows = ["| sequence | mode | steps | mean NEES (6) | within 12.59 | mean / 6 | transl. NEES (3) | rot. NEES (3) "
            "| ATE odometry | ATE loop closed |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name, result in results.items():
        for mode, m in result["modes"].items():
            pose = m["pose"]
            if pose["steps"] == 0:
                rows.append(f"| {name} | {mode} | 0 | - | - | - | - | - | - | - |")
                continue
            rows.append(f"| {name} | {mode} | {pose['steps']} | {pose['mean']:.3g} | {100 * pose['within_95']:.0f} % "
                        f"| {pose['ratio']:.3g} | {m['translation']['mean']:.3g} | {m['rotation']['mean']:.3g} "
                        f"| {m['ate_odometry_m']:.3f} m | {m['ate_closed_m']:.3f} m |")
    return "\n".join(rows)


def rms_lines(results: dict) -> str:
    """One line per sequence: the RMS step error per axis (what ``fixed`` variances would be the squares of)."""
    lines = []
    for name, result in results.items():
        rms = result["rms_step_error"]
        lines.append(f"{name}: RMS step error x y z {' '.join(f'{v:.4f}' for v in rms['x_y_z_m'])} m, roll pitch "
                     f"yaw {' '.join(f'{v:.5f}' for v in rms['roll_pitch_yaw_rad'])} rad ({result['flagged']} "
                     "steps flagged)")
    return "\n".join(lines)
