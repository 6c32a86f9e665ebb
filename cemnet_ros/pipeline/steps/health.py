"""Failure detection without ground truth: is this registration one the node can vouch for?

Signals of the polished answer, each compared with a limit (docs/node.md lists them):

- **fitness**: the fraction of the scan's points that have a map point nearby after the polish, against an
  absolute floor and against its running level over recent good steps (a kidnap or a wrong minimum drops it);
- **conditioning**: the smallest eigenvalue of the polish's normalised Hessian relative to the largest (a
  corridor or an open field leaves a direction unconstrained: the step is *degenerate*).

The third judge is the competition between answers (:mod:`.hypotheses`): distinct answers of similar fitness
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
        compete (:mod:`.hypotheses`); a wrong answer shows in its fitness or loses to a fitter one.
        """
        c, s, out = self.config, signals, []
        if s.fitness < c.min_fitness:
            out.append(f"low fitness {s.fitness:.3f} < {c.min_fitness:.3f}")
        elif self.level is not None and s.fitness < c.fitness_drop * self.level:
            out.append(f"fitness {s.fitness:.3f} fell below {c.fitness_drop:.2f} x its running level {self.level:.3f}")
        return out

    def unconfirmed(self, fitness: float, support: int, after_gap: bool = False) -> str:
        """Why an answer cannot be vouched for although it passed :meth:`failures` ("" = it can): it fits clearly
        worse than the recent good steps and one start alone reached it (a wrong local minimum does), or, after a
        stamp gap, whatever its support (a prediction over a gap is no evidence)."""
        floor = self.config.confirm_ratio * (self.level or 0.0)
        if fitness >= floor or (support >= 2 and not after_gap):
            return ""
        alone = "after a stamp gap" if after_gap else "reached from one start only"
        return f"unconfirmed: fitness {fitness:.3f} < {floor:.3f}, {alone}"

    def degenerate(self, signals: Signals) -> bool:
        return signals.conditioning < self.config.min_conditioning

    def accept(self, fitness: float) -> None:
        """A good step's fitness moves the running level."""
        m = self.config.level_memory
        self.level = fitness if self.level is None else m * self.level + (1.0 - m) * fitness
