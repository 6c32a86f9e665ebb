"""Failure detection without ground truth: is this registration one the node can vouch for?

Signals of the polished answer, each compared with a limit (docs/node.md lists them):

- **fitness**: the fraction of the scan's points that have a map point nearby after the polish, against an
  absolute floor and against its running level over recent good steps (a kidnap or a wrong minimum drops it);
- **coverage**: the fraction that has a map point within a few voxels at all. A wrong basin in a regular
  building (a turn of 90 deg, a shift by a room) often fits the walls as well as the truth but leaves part of
  the scan in empty space: an answer that covers nearly all of the scan is evidence of its own, one that leaves
  a part uncovered needs a rival's support;
- **conditioning**: the smallest eigenvalue of the polish's normalised Hessian relative to the largest (a
  corridor or an open field leaves a direction unconstrained: the step is *degenerate*).

The third judge is the competition between answers (:mod:`.contest`): distinct answers of similar consistency
are a scene that cannot vouch for either. The CEM's agreement with the polish and its final spread are recorded
as signals, not judged. A failed step is published flagged, with the motion prediction; a degenerate one is
flagged too, keeping the prediction along the unconstrained directions only.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cemnet_ros.core.geometry import rotation_angle_rad
from cemnet_ros.pipeline.config import HealthConfig


@dataclass
class Signals:
    """What one registration says about itself."""

    fitness: float
    disagreement_m: float
    disagreement_rad: float
    conditioning: float
    spread_m: float
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


class HealthMonitor:
    """Judges steps and keeps the running fitness level of the good ones."""

    def __init__(self, config: HealthConfig) -> None:
        self.config = config
        self.level: float | None = None

    def reset(self) -> None:
        self.level = None

    def failures(self, signals: Signals) -> list[str]:
        """Why this step cannot be vouched for (empty: it can). Degeneracy is not a failure: see degenerate().

        The CEM's agreement and spread are not judged: the CEM is one of the starts whose polished answers
        compete (:mod:`.contest`); a wrong answer shows in its fitness or loses to a more consistent one.
        """
        c, s, out = self.config, signals, []
        if not self.overlaps(s.fitness):
            out.append(f"low fitness {s.fitness:.3f} < {c.min_fitness:.3f}")
        elif self.level is not None and s.fitness < c.fitness_drop * self.level:
            out.append(f"fitness {s.fitness:.3f} fell below {c.fitness_drop:.2f} x its running level {self.level:.3f}")
        return out

    def unconfirmed(self, fitness: float, support: int, after_gap: bool = False, coverage: float = 0.0) -> str:
        """Why an answer cannot be vouched for although it passed :meth:`failures` ("" = it can): it fits clearly
        worse than the recent good steps, one start alone reached it (a wrong local minimum does) and it does not
        cover the scan (:meth:`covers`), or, after a stamp gap, whatever its support unless it covers the scan (a
        prediction over a gap is no evidence)."""
        floor = self.config.confirm_ratio * (self.level or 0.0)
        if fitness >= floor or (support >= 2 and not after_gap) or self.covers(coverage):
            return ""
        alone = "after a stamp gap" if after_gap else "reached from one start only"
        return f"unconfirmed: fitness {fitness:.3f} < {floor:.3f}, {alone}"

    def overlaps(self, fitness: float) -> bool:
        """Enough of the scan lies on the map's surfaces to be evidence at all (``health.min_fitness``)."""
        return fitness >= self.config.min_fitness

    def covers(self, coverage: float) -> bool:
        """Nearly all of the scan lands next to the map's surfaces (``health.confirm_coverage``)."""
        return coverage >= self.config.confirm_coverage

    def degenerate(self, signals: Signals) -> bool:
        return signals.conditioning < self.config.min_conditioning

    def accept(self, fitness: float) -> None:
        """A good step's fitness moves the running level."""
        m = self.config.level_memory
        self.level = fitness if self.level is None else m * self.level + (1.0 - m) * fitness
