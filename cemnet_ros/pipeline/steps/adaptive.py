"""Adaptive tracking spread: how far the CEM looks and the polish pairs, from the motion model's recent errors.

The idea of KISS-ICP's adaptive threshold: the constant-velocity prediction is wrong by about as much as it was
wrong lately, so the search around it should be a few times that error, never fixed. Before any error has been
observed the initial spreads hold; the spreads also grow with the time since the last scan (a dropped scan
doubles the motion the prediction extrapolates).
"""
from __future__ import annotations

import collections
from dataclasses import dataclass

import numpy as np

from cemnet_ros.core.geometry import rotation_angle_rad
from cemnet_ros.schema import param, validate


@dataclass
class AdaptiveConfig:
    """Spreads in radians and metres; ``factor`` times the RMS prediction error, clipped to [min, max]."""

    initial_rotation: float = param(0.05, "rotation spread (rad) until prediction errors have been observed",
                                    low=1e-4, high=3.2)
    initial_translation: float = param(0.5, "translation spread (m) until prediction errors have been observed",
                                       low=1e-4)
    min_rotation: float = param(0.01, "smallest rotation spread (rad)", low=1e-5, high=3.2)
    min_translation: float = param(0.1, "smallest translation spread (m)", low=1e-5)
    max_rotation: float = param(0.5, "largest rotation spread (rad)", low=1e-5, high=3.2)
    max_translation: float = param(5.0, "largest translation spread (m)", low=1e-5)
    factor: float = param(3.0, "spread = factor x the RMS of the recent prediction errors", low=1e-3)
    window: int = param(100, "prediction errors remembered", low=1)

    def __post_init__(self) -> None:
        validate(self)
        if self.min_rotation > self.max_rotation or self.min_translation > self.max_translation:
            raise ValueError("adaptive spreads need min <= max")


class AdaptiveSpread:
    """Running RMS of the prediction errors (rotation, translation) of accepted steps."""

    def __init__(self, config: AdaptiveConfig) -> None:
        self.config = config
        self._errors: collections.deque = collections.deque(maxlen=config.window)

    def reset(self) -> None:
        self._errors.clear()

    def update(self, T_predicted_actual: np.ndarray) -> None:
        """Record how far an accepted pose was from its prediction (``inv(T_pred) @ T_final``)."""
        self._errors.append((rotation_angle_rad(T_predicted_actual[:3, :3]),
                             float(np.linalg.norm(T_predicted_actual[:3, 3]))))

    def spread(self, dt_ratio: float = 1.0) -> tuple[float, float]:
        """(rotation rad, translation m) to search around the prediction; ``dt_ratio`` = dt / usual dt."""
        c = self.config
        if not self._errors:
            rotation, translation = c.initial_rotation, c.initial_translation
        else:
            rms = np.sqrt(np.mean(np.square(np.asarray(self._errors)), axis=0))
            rotation, translation = c.factor * rms[0], c.factor * rms[1]
        stretch = max(1.0, float(dt_ratio))
        return (float(np.clip(rotation * stretch, c.min_rotation, c.max_rotation)),
                float(np.clip(translation * stretch, c.min_translation, c.max_translation)))
