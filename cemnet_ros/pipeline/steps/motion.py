"""Constant-velocity motion model on SE(3) (as KISS-ICP): the next motion repeats the last one.

The last relative motion is rescaled to the new time step through the SE(3) logarithm, so a dropped scan
(twice the usual gap) predicts twice the motion, and a gap of a second at 10 Hz ten times it: a car keeps its
speed through a gap more often than not, and where it stopped tracking's start from the last pose finds it
(:mod:`.tracking`). A map restarted on a pose the node did not vouch for keeps the motion of the last vouched
step (:meth:`ConstantVelocity.restart_at`): no motion, or the motion into a guess, is a hypothesis, not a fact.
The model also owns the time: its last stamp, the usual time step (a running mean) that
widens the tracking's search after a longer one, and the velocity that deskews.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from cemnet_ros.core.geometry import se3_exp, se3_log


def se3_power(transform: np.ndarray, ratio: float) -> np.ndarray:
    """``transform ** ratio`` on SE(3): the screw motion scaled by ``ratio`` (exp(ratio * log T), closed form)."""
    if ratio == 1.0:
        return np.array(transform, dtype=np.float64)
    if ratio == 0.0:
        return np.eye(4)
    return se3_exp(ratio * se3_log(transform))


class ConstantVelocity:
    """Predicts the next pose from the last two (pose_{k-1} @ (T_{k-2,k-1}) ** (dt_k / dt_{k-1}))."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the poses, the stamps and the usual time step."""
        self._poses: list[np.ndarray] = []
        self._stamps: list[int] = []
        self._period_ns: Optional[int] = None
        self._vouched_motion: Optional[tuple[np.ndarray, int]] = None  # the last vouched step's motion, time step

    @property
    def has_velocity(self) -> bool:
        return len(self._poses) == 2

    @property
    def last_pose(self) -> Optional[np.ndarray]:
        return self._poses[-1] if self._poses else None

    @property
    def last_stamp(self) -> Optional[int]:
        """The stamp of the last pose recorded (None before any)."""
        return self._stamps[-1] if self._stamps else None

    @property
    def period_ns(self) -> Optional[int]:
        """The usual time step: the running mean of the recorded ones (None before two poses)."""
        return self._period_ns

    def update(self, pose: np.ndarray, stamp_ns: int, vouched: bool = True) -> None:
        """Record the pose estimated at ``stamp_ns`` (only the last two are kept); its time step joins the usual
        one. ``vouched``: the node vouched for the step to it (a restart keeps its motion, :meth:`restart_at`)."""
        if self._stamps:
            dt_ns = int(stamp_ns) - self._stamps[-1]
            self._period_ns = dt_ns if self._period_ns is None else int(0.9 * self._period_ns + 0.1 * dt_ns)
        self._poses = (self._poses + [np.array(pose, dtype=np.float64)])[-2:]
        self._stamps = (self._stamps + [int(stamp_ns)])[-2:]
        if vouched and self.has_velocity and self._stamps[1] > self._stamps[0]:
            self._vouched_motion = (np.linalg.inv(self._poses[0]) @ self._poses[1], self._stamps[1] - self._stamps[0])

    def restart_at(self, pose: np.ndarray, stamp_ns: int) -> None:
        """Record ``pose`` at ``stamp_ns`` as an anchor the node did not vouch for (a restarted map's): the motion
        into it is the last vouched step's (none vouched yet: no velocity)."""
        self.update(pose, stamp_ns, vouched=False)
        if self._vouched_motion is None:
            self._poses, self._stamps = self._poses[-1:], self._stamps[-1:]
            return
        motion, dt_ns = self._vouched_motion
        self._poses = [self._poses[-1] @ np.linalg.inv(motion), self._poses[-1]]
        self._stamps = [self._stamps[-1] - dt_ns, self._stamps[-1]]

    def moved(self, T_correction: np.ndarray) -> None:
        """The recorded poses moved by ``T_correction`` (odom frame, from the left): the motion between them kept."""
        self._poses = [T_correction @ pose for pose in self._poses]

    def dt_ratio(self, stamp_ns: int) -> float:
        """The time step to ``stamp_ns`` over the usual one (1 while none is known)."""
        last = self.last_stamp
        return 1.0 if not self._period_ns or last is None else (int(stamp_ns) - last) / self._period_ns

    def velocity(self) -> Optional[np.ndarray]:
        """The twist (6,) per second: the last motion over its time step (None: none yet)."""
        last_dt_ns = self._stamps[1] - self._stamps[0] if self.has_velocity else 0
        if last_dt_ns <= 0:
            return None
        return se3_log(np.linalg.inv(self._poses[0]) @ self._poses[1]) / (last_dt_ns * 1e-9)

    def predict_relative(self, stamp_ns: int) -> np.ndarray:
        """Predicted T_prev_curr from the last recorded pose to the pose at ``stamp_ns`` (identity at start)."""
        if not self.has_velocity:
            return np.eye(4)
        delta = np.linalg.inv(self._poses[0]) @ self._poses[1]
        last_dt = self._stamps[1] - self._stamps[0]
        ratio = 1.0 if last_dt <= 0 else (int(stamp_ns) - self._stamps[1]) / last_dt
        return se3_power(delta, max(0.0, float(ratio)))

    def predict(self, stamp_ns: int) -> np.ndarray:
        """Predicted pose at ``stamp_ns`` (identity before any update)."""
        last = self.last_pose
        return (np.eye(4) if last is None else last) @ self.predict_relative(stamp_ns)
