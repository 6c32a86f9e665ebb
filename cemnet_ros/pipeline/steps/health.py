"""The signals an answer reports about itself, and the running level of the vouched steps.

The level is what the decision (:mod:`.decision`) compares a new answer's fitness and coverage with: how much of a
scan lies on the map's surfaces, and how much of it where the map has any, depends on the sensor, its density and
the scene, so a right answer is one that fits and covers about as well as the recent vouched steps did. It
belongs to one map: a restarted map's steps set it again (what right answers fit depends on the scene, and until
they do the decision has no level to confirm with).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from cemnet_ros.core.geometry import rotation_angle_rad


@dataclass(frozen=True)
class Signals:
    """What one registration says about itself (published with each step)."""

    fitness: float
    disagreement_m: float  # how far the polish moved its start
    disagreement_rad: float
    conditioning: float
    spread_m: float  # the CEM's final spread, where the CEM gave the start
    coverage: float = 0.0  # fraction of the scan with a map point within health.coverage_distance

    @property
    def consistency(self) -> float:
        """The share of the scan on the map's surfaces (fitness) less the share where the map has none: a pose
        that leaves points in empty space ranks below one that fits as well and leaves none there."""
        return self.fitness - (1.0 - self.coverage)

    def as_dict(self) -> dict[str, float]:
        return {k: round(float(v), 6) for k, v in vars(self).items()}


def disagreement(T_a: np.ndarray, T_b: np.ndarray) -> tuple[float, float]:
    """(metres, radians) between two poses of the same frame."""
    delta = np.linalg.inv(T_a) @ T_b
    return float(np.linalg.norm(delta[:3, 3])), rotation_angle_rad(delta[:3, :3])


@dataclass(frozen=True)
class Level:
    """The running fitness and coverage of the vouched steps."""

    fitness: float
    coverage: float


class RunningLevel:
    """The fitness and the coverage of the vouched steps, each smoothed: level <- memory * level + (1 - memory) *
    the new step's."""

    def __init__(self, memory: float) -> None:
        self.memory = memory
        self.level: Optional[Level] = None

    def reset(self) -> None:
        self.level = None

    def accept(self, signals: Signals) -> None:
        """A vouched step's fitness and coverage move the level."""
        if self.level is None:
            self.level = Level(signals.fitness, signals.coverage)
            return
        keep, take = self.memory, 1.0 - self.memory
        self.level = Level(keep * self.level.fitness + take * signals.fitness,
                           keep * self.level.coverage + take * signals.coverage)
