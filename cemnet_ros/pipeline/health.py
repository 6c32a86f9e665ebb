"""Failure detection without ground truth: is this registration one the node can vouch for?

Four signals the pipeline already has, each compared with a limit (docs/node.md lists them):

- **fitness**: the fraction of the scan's points that have a map point nearby after the polish, against an
  absolute floor and against its running level over recent good steps (a kidnap or a wrong minimum drops it);
- **agreement**: how far the point-to-plane polish moved the CEM's answer (two methods that disagree by more
  than the CEM's resolution cannot both be right);
- **conditioning**: the smallest eigenvalue of the polish's normalised Hessian relative to the largest (a
  corridor or an open field leaves a direction unconstrained: the step is *degenerate*);
- **spread**: the CEM's final sampling spread (a search that did not converge).

A failed step is published flagged, with the motion prediction; a degenerate one is flagged too, keeping the
prediction along the unconstrained directions only.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cemnet_ros.core.geometry import rotation_angle_rad
from cemnet_ros.schema import param


@dataclass
class HealthConfig:
    """Limits of the failure signals (fractions, metres, radians)."""

    min_fitness: float = param(0.3, "inlier fraction after the polish below which a step fails", low=0.0,
                               high=0.99)
    fitness_drop: float = param(0.7, "a step fails when its fitness falls below this fraction of the running "
                                "level", low=0.01, high=1.0)
    level_memory: float = param(0.9, "running fitness level: level <- memory * level + (1 - memory) * fitness",
                                low=0.0, high=0.999)
    # Translation limits are in units of the CEM's resolution, epsilon * scale (2.6 m on a KITTI scan, 14 cm
    # on an RGB-D frame): what the max-consensus reward can tell apart.
    max_disagreement_translation: float = param(0.4, "polish vs CEM translation disagreement above which a step "
                                                "fails (units of epsilon x scale)", low=1e-4)
    max_disagreement_rotation: float = param(0.05, "polish vs CEM rotation disagreement above which a step fails "
                                             "(rad)", low=1e-4)
    min_conditioning: float = param(0.005, "smallest / largest eigenvalue of the polish's normalised Hessian "
                                    "below which a step is degenerate (flagged, prediction kept along the free "
                                    "direction)", low=0.0, high=0.99)
    max_spread_translation: float = param(0.4, "the CEM's final translation spread above which a step fails "
                                          "(units of epsilon x scale)", low=1e-4)
    covariance_inflation: float = param(100.0, "variance factor of a failed step's covariance", low=1.0)

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_fitness < 1.0 or not 0.0 < self.fitness_drop <= 1.0:
            raise ValueError("min_fitness must lie in [0, 1) and fitness_drop in (0, 1]")
        if not 0.0 <= self.level_memory < 1.0:
            raise ValueError("level_memory must lie in [0, 1)")
        if min(self.max_disagreement_translation, self.max_disagreement_rotation, self.max_spread_translation) <= 0:
            raise ValueError("disagreement and spread limits must be > 0")
        if not 0.0 <= self.min_conditioning < 1.0:
            raise ValueError("min_conditioning must lie in [0, 1)")
        if self.covariance_inflation < 1.0:
            raise ValueError("covariance_inflation must be >= 1")


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

    def disagree(self, metres: float, radians: float, resolution_m: float) -> bool:
        """Whether polish and CEM answers this far apart cannot both be right."""
        c = self.config
        return metres > c.max_disagreement_translation * resolution_m or radians > c.max_disagreement_rotation

    def failures(self, signals: Signals, resolution_m: float, recovery: bool = False) -> list[str]:
        """Why this step cannot be vouched for (empty: it can). Degeneracy is not a failure: see degenerate().

        ``resolution_m`` is the CEM's resolution epsilon * scale, the unit of the translation limits.

        A global search's answer is judged without agreement and spread (its polish starts from a coarse
        hypothesis, degrees off); its own check is the ambiguity between distinct hypotheses.
        """
        c, s, out = self.config, signals, []
        if s.fitness < c.min_fitness:
            out.append(f"low fitness {s.fitness:.3f} < {c.min_fitness:.3f}")
        elif self.level is not None and s.fitness < c.fitness_drop * self.level:
            out.append(f"fitness {s.fitness:.3f} fell below {c.fitness_drop:.2f} x its running level {self.level:.3f}")
        if not recovery and self.disagree(s.disagreement_m, s.disagreement_rad, resolution_m):
            out.append(f"polish and CEM disagree by {s.disagreement_m:.3f} m, {np.degrees(s.disagreement_rad):.2f} deg")
        if not recovery and s.spread_m > c.max_spread_translation * resolution_m:
            out.append(f"CEM spread {s.spread_m:.3f} m did not converge")
        return out

    def degenerate(self, signals: Signals) -> bool:
        return signals.conditioning < self.config.min_conditioning

    def accept(self, fitness: float) -> None:
        """A good step's fitness moves the running level."""
        m = self.config.level_memory
        self.level = fitness if self.level is None else m * self.level + (1.0 - m) * fitness
