"""Adaptive tracking spread: how far the CEM looks and the polish pairs, from the motion model's recent errors.

The idea of KISS-ICP's adaptive threshold: the constant-velocity prediction is wrong by about as much as it was
wrong lately, so the search around it should be a few times that error, never fixed. Before any error has been
observed the initial spreads hold; the spreads also grow with the time since the last scan (a dropped scan
doubles the motion the prediction extrapolates).
"""
from __future__ import annotations

import collections

import numpy as np

from cemnet_ros.core.geometry import rotation_angle_rad
from cemnet_ros.pipeline.config import AdaptiveConfig


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

    def recent_errors(self, n: int) -> np.ndarray:
        """The last ``n`` recorded prediction errors, (k, 2) rows of (rotation rad, translation m), k <= n."""
        return np.asarray(list(self._errors)[-n:], dtype=np.float64).reshape(-1, 2)

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
