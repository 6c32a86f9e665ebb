"""Real posed sequences through each method: accuracy, the judge as a classifier, global searches, time per scan.

Sequences: the four of ``../shared/real_sets`` (:func:`real_set`: BALM, Livox keyframes ``hku``, car keyframes
``riverside``, the 10 Hz handheld ``quick_shack``; the folder that ``real_sets.py extract`` wrote), their
stand-ins (:meth:`Sequence.keyframes`: every k-th scan, thinned), the BALM folder alone (:func:`balm_sequence`)
and the 6 KITTI sample scans of ``../shared``. Nothing is downloaded here: the caller passes the folders.

A step is *off* when its motion from the previous step is wrong by more than the sequence's thresholds
(:attr:`Sequence.off`); off steps are counted apart as accepted (the node vouched for them) and flagged. The
classifier (:mod:`.adjudication`) measures each step's answer from its anchor and adjudicates it against the
data's own optimum too.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from benchmarks.adjudication import DataOptimum, confusion, judge_steps
from benchmarks.metrics import ate_first_pose, end_drift_percent, percentile, relative_error
from cemnet_ros.core.geometry import rotation_angle_deg
from cemnet_ros.data.kitti import kitti_scans
from cemnet_ros.io.console import progress
from cemnet_ros.io.pointcloud_files import read_points

OFF_M, OFF_DEG = 0.10, 1.0  # a step wrong by more than this is off (unless the sequence says otherwise)
KITTI_PERIOD_S = 0.1
REAL_SETS = ("balm", "hku", "riverside", "quick_shack")
# Per set: off by more than (m, deg), about twice what small_gicp GICP started from the reference disagrees with
# it at its 90th percentile (../shared/real_sets/README.md), and the sensor's useful range (m).
REAL_SET_OFF = {"balm": (0.10, 1.0), "hku": (0.10, 1.0), "riverside": (0.20, 1.0), "quick_shack": (0.12, 2.0)}
FASTLIO_RUNS = {"hku": ("output/HKU_MB_2020-09-20-13-34-51_bag", 0, None),
                "riverside": ("output/new_Riverside02_bag_281", 0, 166),
                "quick_shack": ("output/2020-09-16-quick-shack_bag", 0, None)}


@dataclass
class Sequence:
    """Scans (sensor frame, metres), their true poses T_world_sensor (4x4 each) and stamps (ns)."""

    name: str
    scans: list[np.ndarray]
    poses: list[np.ndarray]
    stamps_ns: list[int]
    max_range: float
    off: tuple[float, float] = (OFF_M, OFF_DEG)  # a step off by more than this (m, deg) is wrong

    @property
    def period_s(self) -> float:
        """The median time between scans (the sensor period a live node must keep up with)."""
        return float(np.median(np.diff(self.stamps_ns))) * 1e-9

    def first(self, n: int) -> "Sequence":
        """The first ``n`` scans."""
        return Sequence(self.name, self.scans[:n], self.poses[:n], self.stamps_ns[:n], self.max_range, self.off)

    def keyframes(self, stride: int, points: int = 0, seed: int = 0) -> "Sequence":
        """Every ``stride``-th scan, each thinned to ``points`` random points (seeded per scan; 0: all): a
        sparse keyframe stream with ``stride`` times the motion between scans."""
        rng = np.random.default_rng(seed)
        thinned = [s if not points or len(s) <= points else s[np.sort(rng.choice(len(s), points, replace=False))]
                   for s in self.scans[::stride]]
        name = f"{self.name}_every{stride}" + (f"_{points}pts_seed{seed}" if points else "")
        return Sequence(name, thinned, self.poses[::stride], self.stamps_ns[::stride], self.max_range, self.off)

    def subset(self, indices: list[int]) -> "Sequence":
        """The scans at ``indices`` (in order), e.g. those a live node processed."""
        return Sequence(self.name, [self.scans[k] for k in indices], [self.poses[k] for k in indices],
                        [self.stamps_ns[k] for k in indices], self.max_range, self.off)

    @property
    def length_m(self) -> float:
        """Distance travelled along the true trajectory."""
        positions = np.array([p[:3, 3] for p in self.poses])
        return float(np.sum(np.linalg.norm(np.diff(positions, axis=0), axis=1)))


def balm_sequence(folder: Path, limit: Optional[int] = None) -> Sequence:
    """The BALM real-world benchmark folder (``full0.pcd`` ... and ``alidarPose.csv``), first ``limit`` scans."""
    folder = Path(folder)
    values = np.loadtxt(folder / "alidarPose.csv", delimiter=",", usecols=range(4)).reshape(-1, 4, 4)
    n = len(values) if limit is None else min(limit, len(values))
    poses, stamps, scans = [], [], []
    for k in progress(range(n), desc="reading BALM scans"):
        pose = values[k].copy()
        stamps.append(int(round(pose[3, 3] * 1e9)))
        pose[3] = (0.0, 0.0, 0.0, 1.0)
        poses.append(pose)
        scans.append(read_points(folder / f"full{k}.pcd").astype(np.float64))
    return Sequence("balm_realworld", scans, poses, stamps, max_range=100.0)


def real_set(root: Path, name: str) -> Sequence:
    """One of the four sequences of ``../shared/real_sets`` from the folder its ``extract`` wrote: the scans
    (the frame the poses are of), the reference poses, the sequence's own stamps and its off thresholds."""
    root = Path(root)
    if name == "balm":
        sequence = balm_sequence(root / "balm" / "datas" / "benchmark_realworld")
        return Sequence("balm", sequence.scans, sequence.poses, sequence.stamps_ns, 100.0, REAL_SET_OFF[name])
    run, first, last = FASTLIO_RUNS[name]
    folder = root / "fastlio" / run
    odometry = np.loadtxt(folder / "odom_poses.txt").reshape(-1, 3, 4)  # FAST-LIO2: world <- body (the points)
    times = np.loadtxt(folder / "times.txt")
    indices = range(first, min(len(odometry), len(times)) if last is None else last + 1)
    poses = [np.vstack([odometry[k], (0.0, 0.0, 0.0, 1.0)]) for k in indices]
    scans = [_beyond(read_points(folder / "Scans" / f"{k:06d}.pcd"), 0.1)
             for k in progress(indices, desc=f"reading {name}")]
    return Sequence(name, scans, poses, [int(round(times[k] * 1e9)) for k in indices], 100.0, REAL_SET_OFF[name])


def _beyond(points: np.ndarray, min_range: float) -> np.ndarray:
    """The points farther than ``min_range`` (m) from the sensor (the keyframes keep a few at the origin)."""
    return points[np.linalg.norm(points, axis=1) > min_range]


def kitti_sequence(root: Path) -> Sequence:
    """The 6 KITTI sample scans at 10 Hz (full resolution)."""
    scans, poses = zip(*kitti_scans(root))
    stamps = [int(round(k * KITTI_PERIOD_S * 1e9)) for k in range(len(scans))]
    return Sequence("kitti_6scans", [s.astype(np.float64) for s in scans], list(poses), stamps, max_range=100.0)


@dataclass
class StepResult:
    """One scan through one method."""

    pose: Optional[np.ndarray]
    accepted: bool
    recovered: bool
    ms: float
    reason: str
    answer: Optional[np.ndarray] = None  # the registered answer judged (None: the published pose, or none)
    restarted: bool = False  # the method's map restarted at this scan


def run_method(factory: Callable, sequence: Sequence) -> list[StepResult]:
    """A fresh odometry of ``factory`` over the whole sequence (an exception is a failed scan)."""
    odometry = factory(sequence.max_range)
    out = []
    for points, stamp in progress(list(zip(sequence.scans, sequence.stamps_ns)), desc=sequence.name):
        start = time.perf_counter()
        try:
            result = odometry.process(points, stamp)
        except Exception as exc:  # noqa: BLE001 - the benchmark counts every failure
            out.append(StepResult(None, False, False, 1e3 * (time.perf_counter() - start), repr(exc)))
            continue
        out.append(StepResult(result.pose, result.accepted, result.recovered, 1e3 * (time.perf_counter() - start),
                              result.reason, result.answer, result.restarted))
    return out


def sequence_metrics(sequence: Sequence, results: list[StepResult], optimum: Optional[DataOptimum] = None) -> dict:
    """ATE, end drift, worst step, off steps (accepted / flagged), the judge's confusion counts
    (:mod:`.adjudication`, against ``optimum`` where given), global searches and time per scan."""
    poses = [r.pose if r.pose is not None else np.full((4, 4), np.nan) for r in results]
    steps = []
    for k in range(1, len(results)):
        truth = np.linalg.inv(sequence.poses[k - 1]) @ sequence.poses[k]
        if results[k].pose is None or results[k - 1].pose is None:
            steps.append({"index": k, "rte_m": np.inf, "rre_deg": np.inf, "accepted": False,
                          "recovered": False, "reason": results[k].reason})
            continue
        rte, rre = relative_error(np.linalg.inv(poses[k - 1]) @ poses[k], truth)
        steps.append({"index": k, "rte_m": rte, "rre_deg": rre, "accepted": results[k].accepted,
                      "recovered": results[k].recovered, "reason": results[k].reason,
                      "true_m": float(np.linalg.norm(truth[:3, 3])),
                      "true_deg": rotation_angle_deg(truth[:3, :3])})
    off = [s for s in steps if not (s["rte_m"] <= sequence.off[0] and s["rre_deg"] <= sequence.off[1])]
    judged = judge_steps(sequence.poses, [r.pose for r in results],
                         [r.pose if r.answer is None else r.answer for r in results],
                         [r.accepted for r in results], [r.restarted for r in results], sequence.off, optimum)
    worst = max(steps, key=lambda s: (s["rte_m"], s["rre_deg"])) if steps else None
    ms = [r.ms for r in results[1:]]
    finite = all(r.pose is not None for r in results)
    return {
        "scans": len(results),
        "ate_m": ate_first_pose(poses, sequence.poses) if finite else None,
        "end_drift_pct": end_drift_percent(poses, sequence.poses, sequence.length_m) if finite else None,
        "worst_step_m": worst["rte_m"] if worst else None,
        "worst_step_deg": worst["rre_deg"] if worst else None,
        "off_accepted": sum(s["accepted"] for s in off),
        "off_flagged": sum(not s["accepted"] for s in off),
        "flagged": sum(not s["accepted"] for s in steps),
        **confusion(judged),
        "accepted_wrong_steps": [{"index": j.index, "anchor": j.anchor, "error_m": round(j.error_m, 3),
                                  "error_deg": round(j.error_deg, 2), "reason": results[j.index].reason}
                                 for j in judged if j.accepted and not j.right],
        "recovered_share": float(np.mean([s["recovered"] for s in steps])) if steps else None,
        "ms_p50": percentile(ms, 50),
        "ms_p95": percentile(ms, 95),
        "period_ms": 1e3 * sequence.period_s,
        "off_steps": [{k: (round(v, 4) if isinstance(v, float) else v) for k, v in s.items()} for s in off],
    }


def run_sequences(sequences: list[Sequence], methods: dict[str, Callable]) -> dict:
    """Every method over every sequence: {sequence: {method: metrics}}."""
    out = {}
    for seq in sequences:
        optimum = DataOptimum(seq.scans)
        out[seq.name] = {name: sequence_metrics(seq, run_method(factory, seq), optimum)
                         for name, factory in methods.items()}
    return out


def real_table(results: dict) -> str:
    """A markdown table: one row per sequence and method, the judge's confusion counts beside the accuracy."""
    rows = ["| sequence | method | ATE m | end drift % | accepted right | accepted wrong | flagged right "
            "| flagged wrong | right accepted | global search | ms p50 | ms p95 | period ms |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]

    def f(value, fmt=".3f"):
        return "-" if value is None else format(value, fmt)

    for seq, methods in results.items():
        for name, m in methods.items():
            share = None if m["recovered_share"] is None else 100 * m["recovered_share"]
            right = None if m["right_accepted_share"] is None else 100 * m["right_accepted_share"]
            rows.append(f"| {seq} | {name} | {f(m['ate_m'])} | {f(m['end_drift_pct'], '.2f')} | "
                        f"{m['accepted_right']} | {m['accepted_wrong']} | {m['flagged_right']} | "
                        f"{m['flagged_wrong']} | {f(right, '.1f')} % | {f(share, '.0f')} % | "
                        f"{f(m['ms_p50'], '.0f')} | {f(m['ms_p95'], '.0f')} | {f(m['period_ms'], '.0f')} |")
    return "\n".join(rows)
