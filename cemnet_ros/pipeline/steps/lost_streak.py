"""Where a lost trajectory's map restarts (step 5 of the recipe in :mod:`..aligner`): the failed steps' own answers
when they move steadily, else the motion prediction.

A step into new ground (a car through a gap of a second) registers right but fits below the running level: the
map has not seen a quarter of the scan. Each failed step is flagged; after ``recovery.restart_after`` of them the
map restarts from the scan. The prediction extrapolates the motion from before the failures (a car's weave
over a second turns it degrees off); the failed steps' answers are evidence of their own when they agree with
one another: the last one lies where the constant-velocity motion of the ones before it puts it, within the
precision the node vouches for (:data:`~.answer.DISTINCT_M`, :data:`~.answer.DISTINCT_RAD`). A hand-held
sensor's answers, right or wrong, did not move so steadily on any lost stretch measured (docs/odometry.md, "Fast
gaps"): there the prediction is kept, as before.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from cemnet_ros.pipeline.steps.contest import distinct
from cemnet_ros.pipeline.steps.motion import ConstantVelocity


class LostStreak:
    """The failed steps in a row, and their registered answers."""

    def __init__(self) -> None:
        self._motion = ConstantVelocity()
        self.reset()

    def reset(self) -> None:
        """A good step, or a restarted map: no streak."""
        self.failures = 0
        self._forget_answers()

    def _forget_answers(self) -> None:
        self._motion.reset()
        self._steady: Optional[np.ndarray] = None  # the last answer, when the ones before it predicted it

    def failed(self, T_answer: Optional[np.ndarray], stamp_ns: int) -> None:
        """Count a failed step and record its registered answer (None: it has none worth keeping, e.g. no
        overlap)."""
        self.failures += 1
        if T_answer is None:
            self._forget_answers()
            return
        predicted = self._motion.predict(stamp_ns) if self._motion.has_velocity else None
        self._steady = T_answer if predicted is not None and not distinct(predicted, T_answer) else None
        self._motion.update(T_answer, stamp_ns)

    def restart_pose(self, T_predicted: np.ndarray) -> tuple[np.ndarray, str]:
        """Where the map restarts, and why: the last answer when it moved steadily, else ``T_predicted``."""
        if self._steady is not None:
            return self._steady, "the failed steps' answers moved steadily: the last one used"
        return T_predicted, "motion prediction used"
