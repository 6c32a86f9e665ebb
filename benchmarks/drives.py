"""Simulated courtyard drives with events: ``--seq-scans`` ticks at 10 Hz, 1-10 m/s, two dropouts, a
stop-and-go, a 40 deg/s yaw swing and a kidnap (5-8 m, 30-90 deg), every tick in free space."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np
from scipy.spatial.transform import Rotation

from benchmarks.streams import DT
from cemnet_ros.data.scenes import COURTYARD_BOUNDS, courtyard_scene, in_free_space, random_sensor_pose

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
        if in_free_space(scene, positions, COURTYARD_BOUNDS):
            delivered = [i for i in range(n_ticks) if i not in dropped]
            return Drive(_poses(positions, headings, swing, rng), delivered, events, odometer, kidnap,
                         {"teleport": teleport, "speed_max_mps": float(speed.max()), "path_m": float(odometer[-1])})
    raise RuntimeError(f"no free drive of {n_ticks} ticks found in {max_tries} tries")
