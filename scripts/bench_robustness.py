#!/usr/bin/env python3
"""Robustness benchmark of the odometry pipeline (``ScanAligner``) and of KISS-ICP / small_gicp peers.

Sets (``--sets``; seeds are fixed and printed):

* ``kitti_gaps``: the 6 full-resolution KITTI scans of ../shared, every pair (i, i+g), g = 1..``--max-gap``,
  as the first two scans of a fresh odometry (stamps 0 and g * 100 ms).
* ``large_motion``: ``--pairs`` ray-cast courtyard pairs, 32 beams, yaw U[-180, 180] deg, |t| U[0, 10] m.
* ``sequences``: ``--sequences`` courtyard drives of ``--seq-scans`` ticks at 10 Hz, 1-10 m/s, with dropouts,
  a stop-and-go, a 40 deg/s yaw swing and a kidnap (5-8 m, 30-90 deg).
* ``corridor``: ``--corridor-scans`` scans at 1.5 m/s along a featureless corridor (x unobservable).
* ``speed``: the 6 KITTI scans played ping-pong for ``--speed-scans`` scans; median ms per scan.

Every method sees the same points (float64, sensor frame). ``ScanAligner`` is used with default parameters;
KISS-ICP with its default config (max_range of the sensor, voxel = max_range / 100), a fresh instance per
pair/sequence; small_gicp GICP scan-to-scan from the identity. The peers have no failure flag: all their
steps count as accepted. Exceptions are caught per step and counted as failures with their message.

    python scripts/bench_robustness.py --quick
    python scripts/bench_robustness.py --sets large_motion sequences --pairs 40 --out results/robust.json
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional

import numpy as np
from scipy.spatial.transform import Rotation

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from cemnet_ros.core.geometry import rotation_angle_deg  # noqa: E402
from cemnet_ros.data.kitti import kitti_scans  # noqa: E402
from cemnet_ros.data.scenes import (  # noqa: E402
    COURTYARD_BOUNDS,
    LidarModel,
    corridor_scene,
    courtyard_scene,
    inside_obstacle,
    lidar_scan,
    random_sensor_pose,
)
from cemnet_ros.data.shared import shared_dir  # noqa: E402
from cemnet_ros.io.atomic import atomic_write_text, jsonable  # noqa: E402
from cemnet_ros.io.console import log, progress  # noqa: E402

SETS = ("kitti_gaps", "large_motion", "sequences", "corridor", "speed")
METHODS = ("cemnet", "kiss-icp", "gicp")
RECALL_M, RECALL_DEG = 2.0, 5.0
PRECISE_M, PRECISE_DEG = 0.10, 0.5
PERIOD_NS = 100_000_000  # 10 Hz
DT = PERIOD_NS * 1e-9
FULL = {"pairs": 40, "sequences": 3, "seq_scans": 100, "corridor_scans": 60, "speed_scans": 60, "max_gap": 5}
QUICK = {"pairs": 3, "sequences": 1, "seq_scans": 60, "corridor_scans": 12, "speed_scans": 10, "max_gap": 1}
TOL = f"{PRECISE_M} m / {PRECISE_DEG} deg"
DEFINITIONS = "\n".join([
    "Definitions. RTE / RRE: translation (m) / rotation angle (deg) of inv(T_true) @ T_est for a step's relative",
    "motion (pairs: scan 1 -> scan 2; sequences: previous processed scan -> this scan).",
    f"recall: RTE < {RECALL_M} m and RRE < {RECALL_DEG} deg; precise: RTE < {PRECISE_M} m and RRE < {PRECISE_DEG} deg;",
    "both over ALL steps whatever their flag (failed = exception or no earlier processed scan: a miss).",
    f"flagged: accepted False. accepted wrong: accepted and (RTE > {PRECISE_M} m or RRE > {PRECISE_DEG} deg);",
    "peers accept every step. ms: wall time of the call that produced the step (median / p90).",
    "ATE: position RMSE with both trajectories expressed in their first pose's frame (no other alignment).",
    "drift: end position error / driven distance (the kidnap's teleport is not driven).",
    "Events: e = the first delivered scan after the event, a = the last delivered scan before it, candidates =",
    "the first two delivered scans at or after e.",
    f"recovered: a candidate is accepted and its pose relative to a is within {TOL} of the truth",
    "(the trajectory is still right across the event; after a kidnap that needs a re-localisation).",
    f"resumed: a candidate is accepted and its own step is within {TOL} (tracking goes on).",
    "kidnap flagged: scan e (the first teleported scan) is not accepted.",
])


# ----------------------------------------------------------------------------------------------------------
# Metrics
# ----------------------------------------------------------------------------------------------------------
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


def _percentile(values: list[float], q: float) -> Optional[float]:
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
        "rte_median_accepted_m": _percentile([s["rte_m"] for s in acc], 50),
        "rre_median_accepted_deg": _percentile([s["rre_deg"] for s in acc], 50),
        "ms_median": _percentile([s["ms"] for s in steps if s["ms"] is not None], 50),
        "ms_p90": _percentile([s["ms"] for s in steps if s["ms"] is not None], 90),
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


# ----------------------------------------------------------------------------------------------------------
# Methods: a fresh odometry per pair / sequence, process(points, stamp_ns) -> Output
# ----------------------------------------------------------------------------------------------------------
@dataclass
class Output:
    """One scan's result: pose T_odom_sensor (odom = first scan), flag, reason, covariance (None: not given)."""

    pose: np.ndarray
    accepted: bool = True
    reason: str = ""
    covariance: Optional[np.ndarray] = None


class CemnetOdometry:
    """The pipeline under test, through its public interface only."""

    def __init__(self, max_range: float) -> None:
        from cemnet_ros.pipeline.aligner import AlignerConfig, ScanAligner

        self._aligner = ScanAligner(AlignerConfig())

    def process(self, points: np.ndarray, stamp_ns: int) -> Output:
        step = self._aligner.process(points, stamp_ns)
        return Output(np.asarray(step.pose), bool(step.accepted), str(step.reason), np.asarray(step.covariance))


class KissOdometry:
    """KISS-ICP with its default config; ``max_range`` set for the sensor (voxel = max_range / 100)."""

    def __init__(self, max_range: float) -> None:
        from kiss_icp.config import KISSConfig
        from kiss_icp.kiss_icp import KissICP

        config = KISSConfig()
        config.data.max_range = max_range
        config.mapping.voxel_size = max_range / 100.0
        self._kiss = KissICP(config)

    def process(self, points: np.ndarray, stamp_ns: int) -> Output:
        self._kiss.register_frame(points, np.empty(0))  # no per-point timestamps: no deskewing
        return Output(self._kiss.last_pose.copy())


class GicpOdometry:
    """small_gicp GICP scan-to-scan from the identity (0.25 m voxels, 1 m correspondences, 2 threads)."""

    voxel, max_distance, threads = 0.25, 1.0, 2

    def __init__(self, max_range: float) -> None:
        import small_gicp

        self._gicp = small_gicp
        self._pose = np.eye(4)
        self._previous = None

    def process(self, points: np.ndarray, stamp_ns: int) -> Output:
        cloud, tree = self._gicp.preprocess_points(points, self.voxel, num_threads=self.threads)
        if self._previous is not None:
            target, target_tree = self._previous
            result = self._gicp.align(target, cloud, target_tree, registration_type="GICP",
                                      max_correspondence_distance=self.max_distance, num_threads=self.threads)
            self._pose = self._pose @ np.asarray(result.T_target_source)
        self._previous = (cloud, tree)
        return Output(self._pose.copy())


FACTORIES: dict[str, Callable] = {"cemnet": CemnetOdometry, "kiss-icp": KissOdometry, "gicp": GicpOdometry}
PEER_MODULES = {"kiss-icp": "kiss_icp.kiss_icp", "gicp": "small_gicp"}


def available_methods(wanted: list[str]) -> dict[str, Callable]:
    """The wanted methods, less the peers that do not import (reported on stderr).

    The pipeline under test is always kept: if it cannot even be built, every step counts as failed.
    """
    import importlib

    out = {}
    for name in wanted:
        if name in PEER_MODULES:
            try:
                importlib.import_module(PEER_MODULES[name])
            except ImportError as exc:
                log(f"{name}: not importable ({exc}); left out (pip install -e .[bench])")
                continue
        out[name] = FACTORIES[name]
    return out


@dataclass
class Scan:
    """What a method returned for one delivered scan (pose None: the call raised ``error``)."""

    tick: int
    pose: Optional[np.ndarray]
    accepted: bool
    reason: str
    ms: float
    error: Optional[str]
    covariance: Optional[np.ndarray] = None


def run_scan(odometry, points: np.ndarray, stamp_ns: int, tick: int) -> Scan:
    """One timed call; an exception becomes a failed Scan with its message."""
    start = time.perf_counter()
    try:
        out = odometry.process(points, stamp_ns)
    except Exception as exc:  # noqa: BLE001 - the benchmark counts every failure
        return Scan(tick, None, False, "", 1e3 * (time.perf_counter() - start), f"{type(exc).__name__}: {exc}")
    return Scan(tick, out.pose, out.accepted, out.reason, 1e3 * (time.perf_counter() - start), None, out.covariance)


def warm_up(methods: dict[str, Callable]) -> None:
    """One small untimed pair through each method, so that no timed step pays for loading or JIT compiling."""
    scene, lidar, rng = courtyard_scene(), LidarModel(n_beams=16, n_azimuth=360), np.random.default_rng(0)
    pose = random_sensor_pose(COURTYARD_BOUNDS, rng, scene)
    scans = [lidar_scan(scene, pose, lidar, rng).astype(np.float64) for _ in range(2)]
    for name, factory in methods.items():
        log(f"warm-up: {name}")
        run_stream(factory, lidar.max_range, scans, [0, 1])


def scan_dicts(results: list[Scan]) -> list[dict]:
    """Per delivered scan: tick, pose (None: failed), accepted, reason, ms, error."""
    return [{"tick": s.tick, "pose": s.pose, "accepted": s.accepted, "reason": s.reason, "ms": s.ms,
             "error": s.error} for s in results]


def run_stream(factory: Callable, max_range: float, scans: list[np.ndarray], ticks: list[int]) -> list[Scan]:
    """A fresh odometry over ``scans`` with stamps ``tick * 100 ms``; a failed construction fails every scan."""
    try:
        odometry = factory(max_range)
    except Exception as exc:  # noqa: BLE001
        return [Scan(t, None, False, "", 0.0, f"{type(exc).__name__}: {exc}") for t in ticks]
    return [run_scan(odometry, pts, t * PERIOD_NS, t) for pts, t in zip(scans, ticks)]


def step_records(case: str, results: list[Scan], truth: dict[int, np.ndarray]) -> list[dict]:
    """One record per delivered scan after the first: its motion from the previous processed scan.

    A scan whose call raised, or that has no processed scan before it, is a failed step.
    """
    records, previous = [], None
    for k, scan in enumerate(results):
        if k and (scan.pose is None or previous is None):
            records.append(_record(case, scan, None, None, scan.error or "no earlier scan was processed"))
        elif k:
            est = np.linalg.inv(previous.pose) @ scan.pose
            gt = np.linalg.inv(truth[previous.tick]) @ truth[scan.tick]
            records.append(_record(case, scan, *relative_error(est, gt)))
        if scan.pose is not None:
            previous = scan
    return records


def _record(case: str, scan: Scan, rte: Optional[float], rre: Optional[float], error: Optional[str] = None) -> dict:
    error = error or scan.error
    return {"case": case, "index": scan.tick, "accepted": scan.accepted and error is None,
            "reason": error or scan.reason, "rte_m": rte, "rre_deg": rre, "ms": scan.ms, "error": error}


# ----------------------------------------------------------------------------------------------------------
# Pair sets
# ----------------------------------------------------------------------------------------------------------
@dataclass
class Pair:
    """Two scans (sensor frames) and the true motion T_1_2 between them; ``gap`` scans apart at 10 Hz."""

    name: str
    first: np.ndarray
    second: np.ndarray
    truth: np.ndarray
    gap: int = 1


def run_pairs(pairs: list[Pair], methods: dict[str, Callable], max_range: float, label: str) -> dict:
    """Each pair through a fresh odometry of each method; the step is the second scan."""
    out = {}
    for name, factory in methods.items():
        steps = [pair_record(pair, run_stream(factory, max_range, [pair.first, pair.second], [0, pair.gap]))
                 for pair in progress(pairs, f"{label} {name}")]
        out[name] = {"summary": summarize(steps), "steps": steps}
    return out


def pair_record(pair: Pair, results: list[Scan]) -> dict:
    """The step record of a pair's second scan; a failed first scan fails the pair."""
    if results[0].pose is None:
        return _record(pair.name, results[1], None, None, f"first scan: {results[0].error}")
    return step_records(pair.name, results, {0: np.eye(4), pair.gap: pair.truth})[0]


def kitti_pairs(root: Path, max_gap: int) -> list[Pair]:
    """Every pair (i, i + g), g = 1..max_gap, of the full-resolution KITTI sample scans."""
    frames = [(pts.astype(np.float64), pose) for pts, pose in kitti_scans(root)]
    return [Pair(f"{i}-{i + g}", frames[i][0], frames[i + g][0], np.linalg.inv(frames[i][1]) @ frames[i + g][1], g)
            for g in range(1, max_gap + 1) for i in range(len(frames) - g)]


def random_motion(rng: np.random.Generator, max_translation: float = 10.0, max_tilt_deg: float = 2.0) -> np.ndarray:
    """Yaw U[-180, 180] deg, |t| U[0, max] m in a uniform ground-plane direction, roll/pitch U[-2, 2] deg."""
    motion = np.eye(4)
    roll, pitch = rng.uniform(-max_tilt_deg, max_tilt_deg, 2)
    motion[:3, :3] = Rotation.from_euler("zyx", [rng.uniform(-180, 180), pitch, roll], degrees=True).as_matrix()
    heading, distance = rng.uniform(0, 2 * np.pi), rng.uniform(0, max_translation)
    motion[:3, 3] = distance * np.cos(heading), distance * np.sin(heading), 0.0
    return motion


def _free(scene, positions: np.ndarray, bounds, margin: float = 1.0) -> bool:
    """Whether every sensor position ((n, 3) metres) is inside ``bounds`` and ``margin`` clear of obstacles
    (checked at its height and at 0.3 m, the vehicle's body)."""
    positions = np.atleast_2d(positions)
    x, y = positions[:, 0], positions[:, 1]
    if not np.all((bounds[0] <= x) & (x <= bounds[1]) & (bounds[2] <= y) & (y <= bounds[3])):
        return False
    low = np.c_[x, y, np.full(len(x), 0.3)]
    return not np.any(inside_obstacle(scene, positions, margin)) and not np.any(inside_obstacle(scene, low, margin))


def large_motion_pairs(n: int, seed: int) -> list[Pair]:
    """Courtyard pairs: a random pose, then that pose moved by ``random_motion`` (redrawn until in free space)."""
    rng, scene, lidar = np.random.default_rng(seed), courtyard_scene(), LidarModel()
    pairs = []
    for i in range(n):
        first = random_sensor_pose(COURTYARD_BOUNDS, rng, scene)
        while True:
            motion = random_motion(rng)
            if _free(scene, (first @ motion)[:3, 3], COURTYARD_BOUNDS):
                break
        a = lidar_scan(scene, first, lidar, rng).astype(np.float64)
        b = lidar_scan(scene, first @ motion, lidar, rng).astype(np.float64)
        pairs.append(Pair(f"pair{i}", a, b, motion))
    return pairs


# ----------------------------------------------------------------------------------------------------------
# Sequences
# ----------------------------------------------------------------------------------------------------------
EVENT_TICKS = {"dropout": 6, "stop_and_go": 16, "yaw_swing": 16, "kidnap": 1}  # ticks each event occupies
SWING_RATE = np.radians(40.0)  # rad/s
LEAD_TICKS, TAIL_TICKS = 6, 2  # undisturbed ticks before the first event and after the last
MIN_SEQ_TICKS = LEAD_TICKS + TAIL_TICKS + 2 * EVENT_TICKS["dropout"] + sum(
    EVENT_TICKS[k] for k in ("stop_and_go", "yaw_swing", "kidnap"))


@dataclass
class Drive:
    """A simulated drive: every tick's true pose, the delivered ticks (dropouts removed), events, odometer."""

    poses: list[np.ndarray]
    delivered: list[int]
    events: list[dict]  # {"kind", "tick" (first delivered scan after it), ...}
    odometer: np.ndarray  # driven metres at each tick (the teleport excluded)
    kidnap_tick: Optional[int] = None
    extra: dict = field(default_factory=dict)


def _schedule(n_ticks: int, rng: np.random.Generator) -> list[tuple[str, int]]:
    """Start ticks of two dropouts, a stop-and-go, a yaw swing and a kidnap (in the middle), not overlapping."""
    if n_ticks < MIN_SEQ_TICKS:
        raise ValueError(f"{n_ticks} ticks are too few for the events (need {MIN_SEQ_TICKS})")
    others = list(rng.permutation(["dropout", "dropout", "stop_and_go", "yaw_swing"]))
    order = others[:2] + ["kidnap"] + others[2:]
    slack = n_ticks - MIN_SEQ_TICKS
    gaps = np.diff(np.sort(rng.integers(0, slack + 1, len(order))), prepend=0)
    start, out = LEAD_TICKS, []
    for kind, gap in zip(order, gaps):
        start += int(gap)
        out.append((kind, start))
        start += EVENT_TICKS[kind]
    return out


def _profiles(n_ticks: int, schedule: list[tuple[str, int]], rng: np.random.Generator):
    """Per-tick speed (m/s), path yaw rate and sensor swing rate (rad/s), dropped ticks, kidnap, events."""
    knots = np.arange(0, n_ticks + 20, 20)
    levels = rng.uniform(1.0, 10.0, len(knots))
    levels[rng.integers(1, len(knots) - 1)] = 10.0  # every drive reaches 10 m/s once
    speed = np.interp(np.arange(n_ticks), knots, levels)
    turn_knots = np.arange(0, n_ticks + 15, 15)
    turn = np.interp(np.arange(n_ticks), turn_knots, np.radians(rng.uniform(-30.0, 30.0, len(turn_knots))))
    swing, dropped, events, kidnap = np.zeros(n_ticks), set(), [], None
    for kind, s in schedule:
        if kind == "dropout":
            length = int(rng.integers(1, 6))
            dropped.update(range(s, s + length))
            events.append({"kind": "dropout", "tick": s + length, "missing": length})
        elif kind == "stop_and_go":
            factor = np.r_[2 / 3, 1 / 3, np.zeros(10), 1 / 3, 2 / 3]  # to 0 in 0.3 s, 1 s still, back in 0.3 s
            speed[s:s + len(factor)] *= factor
            events += [{"kind": "stop", "tick": s + 2}, {"kind": "go", "tick": s + 12}]
        elif kind == "yaw_swing":
            swing[s:s + 8], swing[s + 8:s + 16] = SWING_RATE, -SWING_RATE
            events += [{"kind": "yaw_swing", "tick": s}, {"kind": "yaw_reverse", "tick": s + 8}]
        else:
            kidnap = s
            events.append({"kind": "kidnap", "tick": s})
    return speed, turn, swing, dropped, kidnap, events


def _path(start: np.ndarray, heading: float, speed, turn, kidnap, rng):
    """Unicycle path: positions (n, 3) and headings per tick, odometer, and the teleport at the kidnap tick."""
    n = len(speed)
    jump, direction = rng.uniform(5.0, 8.0), rng.uniform(0, 2 * np.pi)
    yaw = rng.choice([-1.0, 1.0]) * rng.uniform(30.0, 90.0)
    moved = np.arange(n) >= (kidnap if kidnap is not None else n)
    step = np.r_[0.0, speed[1:] * DT]
    headings = heading + np.cumsum(np.r_[0.0, turn[1:] * DT]) + moved * np.radians(yaw)
    xy = start[:2] + np.cumsum(step[:, None] * np.c_[np.cos(headings), np.sin(headings)], axis=0)
    xy += moved[:, None] * jump * np.array([np.cos(direction), np.sin(direction)])
    positions = np.c_[xy, 1.8 + 0.05 * np.sin(0.6 * np.arange(n) + rng.uniform(0, 2 * np.pi))]
    teleport = {"jump_m": float(jump), "yaw_deg": float(yaw)} if kidnap is not None else {}
    return positions, headings, np.cumsum(step), teleport


def _poses(positions: np.ndarray, headings: np.ndarray, swing: np.ndarray, rng) -> list[np.ndarray]:
    """T_world_sensor per tick: yaw = heading + the swing's offset, small roll/pitch oscillations."""
    phase = rng.uniform(0, 2 * np.pi, 2)
    offsets = np.cumsum(np.r_[0.0, swing[1:] * DT])
    poses = []
    for i, (position, heading, offset) in enumerate(zip(positions, headings, offsets)):
        pose = np.eye(4)
        roll, pitch = 0.015 * np.cos(0.4 * i + phase[0]), 0.02 * np.sin(0.5 * i + phase[1])
        pose[:3, :3] = Rotation.from_euler("zyx", [heading + offset, pitch, roll]).as_matrix()
        pose[:3, 3] = position
        poses.append(pose)
    return poses


def make_drive(n_ticks: int, rng: np.random.Generator, scene=None, max_tries: int = 100_000) -> Drive:
    """A courtyard drive with events whose every tick is in free space (start and path redrawn until so)."""
    scene = scene or courtyard_scene()
    schedule = _schedule(n_ticks, rng)
    for _ in range(max_tries):
        speed, turn, swing, dropped, kidnap, events = _profiles(n_ticks, schedule, rng)
        start = random_sensor_pose(COURTYARD_BOUNDS, rng, scene)
        heading = float(Rotation.from_matrix(start[:3, :3]).as_euler("zyx")[0])
        positions, headings, odometer, teleport = _path(start[:3, 3], heading, speed, turn, kidnap, rng)
        if _free(scene, positions, COURTYARD_BOUNDS):
            delivered = [i for i in range(n_ticks) if i not in dropped]
            return Drive(_poses(positions, headings, swing, rng), delivered, events, odometer, kidnap,
                         {"teleport": teleport, "speed_max_mps": float(speed.max()), "path_m": float(odometer[-1])})
    raise RuntimeError(f"no free drive of {n_ticks} ticks found in {max_tries} tries")


def event_outcome(event: dict, results: list[Scan], truth: list[np.ndarray]) -> dict:
    """recovered / resumed / flagged for one event (see DEFINITIONS); None where the sequence ended too early."""
    processed = [s for s in results if s.pose is not None]
    before = [s for s in processed if s.tick < event["tick"]]
    after = [s for s in processed if s.tick >= event["tick"]][:2]
    out = {"kind": event["kind"], "tick": event["tick"], "recovered": None, "resumed": None, "flagged": None}
    if not before or not after:
        return out
    anchor = before[-1]
    previous = {s.tick: p for p, s in zip(processed, processed[1:])}

    def good(a: Scan, b: Scan) -> bool:
        est = np.linalg.inv(a.pose) @ b.pose
        return b.accepted and within(*relative_error(est, np.linalg.inv(truth[a.tick]) @ truth[b.tick]),
                                     PRECISE_M, PRECISE_DEG)

    out["recovered"] = any(good(anchor, s) for s in after)
    out["resumed"] = any(good(previous[s.tick], s) for s in after)
    out["flagged"] = after[0].tick == event["tick"] and not after[0].accepted
    return out


def sequence_metrics(drive: Drive, results: list[Scan]) -> dict:
    """ATE, end drift (whole drive and before the kidnap) and the events' outcomes of one method's run."""
    processed = [s for s in results if s.pose is not None]
    out = {"delivered": len(results), "failed": len(results) - len(processed), "ate_m": None, "drift_pct": None,
           "ate_before_kidnap_m": None, "drift_before_kidnap_pct": None,
           "events": [event_outcome(e, results, drive.poses) for e in drive.events]}
    before = [s for s in processed if drive.kidnap_tick is None or s.tick < drive.kidnap_tick]
    for suffix, part in (("", processed), ("_before_kidnap", before)):
        if len(part) < 2:
            continue
        est, gt = [s.pose for s in part], [drive.poses[s.tick] for s in part]
        distance = drive.odometer[part[-1].tick] - drive.odometer[part[0].tick]
        out[f"ate{suffix}_m"] = ate_first_pose(est, gt)
        out[f"drift{suffix}_pct"] = end_drift_percent(est, gt, distance)
    return out


def run_sequences(n: int, n_ticks: int, seed: int, methods: dict[str, Callable]) -> dict:
    """``n`` drives (seeds seed, seed + 1, ...), each through a fresh odometry of each method."""
    scene, lidar = courtyard_scene(), LidarModel()
    out = {name: {"steps": [], "sequences": []} for name in methods}
    drives = []
    for k in range(n):
        rng = np.random.default_rng(seed + k)
        drive = make_drive(n_ticks, rng, scene)
        scans = [lidar_scan(scene, drive.poses[t], lidar, rng).astype(np.float64)
                 for t in progress(drive.delivered, f"sequences: ray-cast drive {k}")]
        drives.append({"seed": seed + k, "events": drive.events, **drive.extra, "delivered": drive.delivered,
                       "truth": [drive.poses[t] for t in drive.delivered]})
        for name, factory in methods.items():
            log(f"sequences: drive {k} ({len(scans)} scans) through {name}")
            results = run_stream(factory, lidar.max_range, scans, drive.delivered)
            out[name]["steps"] += step_records(f"seq{k}", results, dict(enumerate(drive.poses)))
            out[name]["sequences"].append({"seed": seed + k, **sequence_metrics(drive, results),
                                           "scans": scan_dicts(results)})
    for name in methods:
        out[name]["summary"] = summarize(out[name]["steps"])
    return {"drives": drives, "methods": out}


# ----------------------------------------------------------------------------------------------------------
# Corridor
# ----------------------------------------------------------------------------------------------------------
CORRIDOR_LIDAR = LidarModel(max_range=40.0)  # the open ends (60 m away) stay out of range
CORRIDOR_SPEED = 1.5  # m/s
CORRIDOR_MAX_SCANS = int(2 * (60.0 - CORRIDOR_LIDAR.max_range) / (CORRIDOR_SPEED * DT))  # ends (+-60 m) unseen


def corridor_drive(n: int) -> list[np.ndarray]:
    """Straight drive along the corridor axis around x = 0 with a small sway (+-0.1 m) and yaw wobble (+-1 deg)."""
    poses = []
    for i in range(n):
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_euler("z", np.radians(1.0) * np.sin(0.3 * i)).as_matrix()
        pose[:3, 3] = (i - n / 2) * CORRIDOR_SPEED * DT, 0.1 * np.sin(0.2 * i), 1.5
        poses.append(pose)
    return poses


def corridor_metrics(results: list[Scan], truth: list[np.ndarray]) -> dict:
    """Flagged fraction, along-corridor motion recovered, and the covariance's x (along) vs y (across) std."""
    processed = [s for s in results if s.pose is not None]
    steps = processed[1:]
    out = {"flagged_fraction": sum(not s.accepted for s in steps) / len(steps) if steps else None,
           "along_recovered": None, "x_std_median_m": None, "y_std_median_m": None, "x_over_y_std_median": None,
           "x_std_larger_fraction": None}
    if len(processed) >= 2:
        est = np.linalg.inv(processed[0].pose) @ processed[-1].pose
        gt = np.linalg.inv(truth[processed[0].tick]) @ truth[processed[-1].tick]
        out["along_recovered"] = float(est[0, 3] / gt[0, 3])
    covs = [s.covariance for s in steps if s.covariance is not None]
    if covs:
        x_std = np.sqrt([c[0, 0] for c in covs])
        y_std = np.sqrt([c[1, 1] for c in covs])
        out.update(x_std_median_m=float(np.median(x_std)), y_std_median_m=float(np.median(y_std)),
                   x_over_y_std_median=float(np.median(x_std / y_std)),
                   x_std_larger_fraction=float(np.mean(x_std > y_std)),
                   x_std_per_step_m=x_std.tolist(), y_std_per_step_m=y_std.tolist())
    return out


def run_corridor(n: int, seed: int, methods: dict[str, Callable]) -> dict:
    """A drive along ``corridor_scene()`` at 1.5 m/s through a fresh odometry of each method."""
    scene, rng, poses = corridor_scene(), np.random.default_rng(seed), corridor_drive(n)
    scans = [lidar_scan(scene, p, CORRIDOR_LIDAR, rng).astype(np.float64) for p in poses]
    out = {}
    for name, factory in methods.items():
        log(f"corridor: {n} scans through {name}")
        results = run_stream(factory, CORRIDOR_LIDAR.max_range, scans, list(range(n)))
        steps = step_records("corridor", results, dict(enumerate(poses)))
        out[name] = {"summary": summarize(steps), "steps": steps, **corridor_metrics(results, poses)}
    return out


# ----------------------------------------------------------------------------------------------------------
# Speed
# ----------------------------------------------------------------------------------------------------------
def ping_pong(n_items: int, length: int) -> list[int]:
    """0, 1, ..., n-1, n-2, ..., 1, 0, 1, ... cut to ``length``: consecutive items are neighbours."""
    cycle = list(range(n_items)) + list(range(n_items - 2, 0, -1)) if n_items > 1 else [0]
    return [cycle[i % len(cycle)] for i in range(length)]


def run_speed(root: Path, n: int, methods: dict[str, Callable], warmup: int = 3) -> dict:
    """Median / p90 ms per scan of the full-resolution KITTI scans played ping-pong (first ``warmup`` excluded)."""
    frames = [pts.astype(np.float64) for pts, _ in kitti_scans(root)]
    order = ping_pong(len(frames), n)
    out = {"points_mean": int(np.mean([len(f) for f in frames])), "scans": n, "warmup": warmup}
    for name in [m for m in ("cemnet", "kiss-icp") if m in methods]:
        log(f"speed: {n} KITTI scans through {name}")
        results = run_stream(methods[name], 100.0, [frames[i] for i in order], list(range(n)))
        timed = [s.ms for s in results[warmup:] if s.error is None]
        out[name] = {"ms_median": _percentile(timed, 50), "ms_p90": _percentile(timed, 90), "timed": len(timed),
                     "errors": sorted({s.error for s in results if s.error})}
    if out.get("cemnet", {}).get("ms_median") and out.get("kiss-icp", {}).get("ms_median"):
        out["ratio_cemnet_over_kiss"] = out["cemnet"]["ms_median"] / out["kiss-icp"]["ms_median"]
    return out


# ----------------------------------------------------------------------------------------------------------
# Report
# ----------------------------------------------------------------------------------------------------------
def _f(value, fmt: str = ".3f") -> str:
    return "-" if value is None else format(value, fmt)


def _pct(value, digits: int = 0) -> str:
    return "-" if value is None else f"{100 * value:.{digits}f}%"


def main_table(results: dict) -> str:
    """One row per (set, method) of the step summaries."""
    lines = ["| set | method | steps | failed | flagged | recall | precise | accepted wrong | RTE med (m) | "
             "RRE med (deg) | ms med | ms p90 |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for set_name, data in results.items():
        methods = data.get("methods", data) if isinstance(data, dict) else {}
        for name, res in methods.items():
            if not isinstance(res, dict) or "summary" not in res:
                continue
            s = res["summary"]
            lines.append(f"| {set_name} | {name} | {s['steps']} | {s['failed']} | {s['flagged']} | {_pct(s['recall'])} "
                         f"| {_pct(s['precise'])} | {s['accepted_wrong']} | {_f(s['rte_median_accepted_m'])} | "
                         f"{_f(s['rre_median_accepted_deg'], '.2f')} | {_f(s['ms_median'], '.0f')} | "
                         f"{_f(s['ms_p90'], '.0f')} |")
    return "\n".join(lines)


def wrong_list(results: dict) -> str:
    """Every accepted-while-wrong step, one line per (set, method)."""
    lines = []
    for set_name, data in results.items():
        for name, res in (data.get("methods", data) if isinstance(data, dict) else {}).items():
            if isinstance(res, dict) and res.get("summary", {}).get("accepted_wrong_steps"):
                items = ", ".join(f"{w['case']}@{w['index']} ({w['rte_m']:.2f} m, {w['rre_deg']:.1f} deg)"
                                  for w in res["summary"]["accepted_wrong_steps"])
                lines.append(f"- {set_name} / {name}: {items}")
    return "\n".join(["Accepted while wrong:"] + lines) if lines else "Accepted while wrong: none"


def failure_list(results: dict) -> str:
    """The distinct exception messages (first line) per (set, method)."""
    lines = []
    for set_name, data in results.items():
        for name, res in (data.get("methods", data) if isinstance(data, dict) else {}).items():
            errors = res.get("summary", res).get("errors") if isinstance(res, dict) else None
            for error in sorted({e.splitlines()[0] for e in errors or []}):
                lines.append(f"- {set_name} / {name}: {error}")
    return "\n".join(["Failures (exceptions):"] + lines) if lines else "Failures (exceptions): none"


def sequence_table(data: dict) -> str:
    """Per method: ATE, drift and event outcomes (recovered / resumed per event kind) over all drives."""
    kinds = ["dropout", "stop", "go", "yaw_swing", "yaw_reverse", "kidnap"]
    lines = ["| method | ATE (m) | ATE before kidnap (m) | drift % | drift before kidnap % | "
             + " | ".join(f"{k} rec/res" for k in kinds) + " | kidnap flagged |",
             "|---|---|---|---|---|" + "---|" * len(kinds) + "---|"]
    for name, res in data["methods"].items():
        seqs = res["sequences"]

        def mean(key):
            vals = [s[key] for s in seqs if s[key] is not None]
            return float(np.mean(vals)) if vals else None

        events = [e for s in seqs for e in s["events"]]
        cells = []
        for kind in kinds:
            ev = [e for e in events if e["kind"] == kind and e["recovered"] is not None]
            cells.append(f"{sum(e['recovered'] for e in ev)}/{sum(e['resumed'] for e in ev)} of {len(ev)}")
        kid = [e for e in events if e["kind"] == "kidnap" and e["flagged"] is not None]
        lines.append(f"| {name} | {_f(mean('ate_m'))} | {_f(mean('ate_before_kidnap_m'))} | "
                     f"{_f(mean('drift_pct'), '.1f')} | {_f(mean('drift_before_kidnap_pct'), '.1f')} | "
                     + " | ".join(cells) + f" | {sum(e['flagged'] for e in kid)} of {len(kid)} |")
    return "\n".join(lines)


def corridor_table(data: dict) -> str:
    """Per method: flagged fraction, along-corridor motion recovered, covariance x vs y std."""
    lines = ["| method | flagged | along-corridor motion recovered | x std med (m) | y std med (m) | "
             "x/y std med | steps with x std > y std |", "|---|---|---|---|---|---|---|"]
    for name, r in data.items():
        lines.append(f"| {name} | {_pct(r['flagged_fraction'])} | {_pct(r['along_recovered'], 1)} | "
                     f"{_f(r['x_std_median_m'], '.4f')} | {_f(r['y_std_median_m'], '.4f')} | "
                     f"{_f(r['x_over_y_std_median'], '.2f')} | {_pct(r['x_std_larger_fraction'])} |")
    return "\n".join(lines)


def speed_table(data: dict) -> str:
    """ms per scan of each method on the KITTI ping-pong stream, and the ratio."""
    lines = [f"KITTI {data['points_mean']} points/scan, {data['scans']} scans, first {data['warmup']} excluded",
             "| method | ms med | ms p90 | scans timed |", "|---|---|---|---|"]
    for name in ("cemnet", "kiss-icp"):
        if name in data:
            r = data[name]
            lines.append(f"| {name} | {_f(r['ms_median'], '.0f')} | {_f(r['ms_p90'], '.0f')} | {r['timed']} |")
    if "ratio_cemnet_over_kiss" in data:
        lines.append(f"\nms per scan, cemnet / kiss-icp: {data['ratio_cemnet_over_kiss']:.2f}x")
    return "\n".join(lines)


def report(results: dict) -> str:
    """The markdown the script prints."""
    parts = [main_table({k: v for k, v in results.items() if k != "speed"}), wrong_list(results),
             failure_list(results)]
    if "sequences" in results:
        parts.append("Sequences (recovered/resumed of events):\n" + sequence_table(results["sequences"]))
    if "corridor" in results:
        parts.append("Corridor:\n" + corridor_table(results["corridor"]))
    if "speed" in results:
        parts.append("Speed:\n" + speed_table(results["speed"]))
    return "\n\n".join(parts + [DEFINITIONS])


def write_json(path: Path, meta: dict, results: dict) -> None:
    """Atomic JSON of everything measured so far."""
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(jsonable({"meta": meta, "sets": results}), indent=1, allow_nan=False) + "\n")


# ----------------------------------------------------------------------------------------------------------
# CLI
# ----------------------------------------------------------------------------------------------------------
def parse_args(argv: Optional[list[str]]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", nargs="+", choices=SETS, default=list(SETS), help="sets to run (default: all)")
    parser.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS),
                        help="methods (peers need the optional `bench` extra; missing ones are left out)")
    parser.add_argument("--quick", action="store_true", help=f"tiny sizes for a smoke run: {QUICK}")
    parser.add_argument("--pairs", type=int, help=f"large_motion pairs (default {FULL['pairs']})")
    parser.add_argument("--sequences", type=int, help=f"synthetic drives (default {FULL['sequences']})")
    parser.add_argument("--seq-scans", type=int, help=f"ticks per drive at 10 Hz (default {FULL['seq_scans']})")
    parser.add_argument("--corridor-scans", type=int, help=f"corridor scans (default {FULL['corridor_scans']})")
    parser.add_argument("--speed-scans", type=int, help=f"KITTI ping-pong scans (default {FULL['speed_scans']})")
    parser.add_argument("--max-gap", type=int, help=f"kitti_gaps: largest g in (i, i+g) (default {FULL['max_gap']})")
    parser.add_argument("--seed", type=int, default=0, help="base seed (large_motion: seed, sequences: seed + 100 + k, "
                                                             "corridor: seed + 200)")
    parser.add_argument("--out", type=Path, default=REPO / "results" / "bench_robustness.json", help="JSON output")
    args = parser.parse_args(argv)
    sizes = QUICK if args.quick else FULL
    for key, value in sizes.items():
        if getattr(args, key) is None:
            setattr(args, key, value)
        if getattr(args, key) < 1:
            parser.error(f"--{key.replace('_', '-')} must be >= 1")
    if args.seq_scans < MIN_SEQ_TICKS:
        parser.error(f"--seq-scans must be >= {MIN_SEQ_TICKS} to hold the events")
    if args.corridor_scans > CORRIDOR_MAX_SCANS:
        parser.error(f"--corridor-scans must be <= {CORRIDOR_MAX_SCANS}: longer drives see the corridor's ends")
    return args


def main(argv: Optional[list[str]] = None) -> int:
    args = parse_args(argv)
    methods = available_methods(args.methods)
    shared = shared_dir()
    kitti = shared / "data" / "kitti_sample" if shared else None
    meta = {"argv": sys.argv[1:] if argv is None else list(argv), "sizes": {k: getattr(args, k) for k in FULL},
            "seeds": {"large_motion": args.seed, "sequences": [args.seed + 100 + k for k in range(args.sequences)],
                      "corridor": args.seed + 200},
            "methods": list(methods), "python": platform.python_version(), "machine": platform.machine(),
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    log(f"methods: {', '.join(methods) or 'none'}; seeds: {meta['seeds']}")
    results: dict = {}
    warm_up(methods)
    for set_name in args.sets:
        start = time.perf_counter()
        if set_name in ("kitti_gaps", "speed") and not (kitti and kitti.is_dir()):
            print(f"skip {set_name}: the KITTI sample (../shared/data/kitti_sample) is absent")
            continue
        if set_name == "kitti_gaps":
            results[set_name] = run_pairs(kitti_pairs(kitti, args.max_gap), methods, 100.0, set_name)
        elif set_name == "large_motion":
            log(f"large_motion: ray-casting {args.pairs} pairs (seed {args.seed})")
            results[set_name] = run_pairs(large_motion_pairs(args.pairs, args.seed), methods, 100.0, set_name)
        elif set_name == "sequences":
            results[set_name] = run_sequences(args.sequences, args.seq_scans, args.seed + 100, methods)
        elif set_name == "corridor":
            results[set_name] = run_corridor(args.corridor_scans, args.seed + 200, methods)
        else:
            results[set_name] = run_speed(kitti, args.speed_scans, methods)
        log(f"{set_name}: done in {time.perf_counter() - start:.0f} s")
        write_json(args.out, meta, results)
    print(f"seeds: {meta['seeds']}; methods: {', '.join(methods)}\n")
    print(report(results))
    write_json(args.out, meta, results)
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
