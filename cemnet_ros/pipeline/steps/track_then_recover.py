"""Registering one frame (steps 3 and 5 of the recipe in :mod:`..aligner`): track from the prediction, then
recover with the global search when tracking's answer cannot stand alone, or at once when the caller says why;
the answer on a weakly constrained view is checked against its neighbours (:mod:`.contest`).

Sequential mode (:mod:`..aligner`) and pair mode (:mod:`..pair_mode`) register through it alike; what they
commit differs.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.contest import Contest
from cemnet_ros.pipeline.steps.frame import Frame
from cemnet_ros.pipeline.steps.recovery import Recovery
from cemnet_ros.pipeline.steps.tracking import Tracker
from cemnet_ros.pipeline.steps.verdict import Estimate


@dataclass
class Registered:
    """A frame's registration, before it is committed."""

    estimate: Estimate
    contest: Contest  # the answers polished and judged for it
    why_recovered: str = ""  # why the global search ran ("" = tracking's answer stood)


@dataclass(frozen=True)
class RecoveryFallbacks:
    """The recovery's other starts (:meth:`~.recovery.Recovery.recover`; None: not used): ``T_fallback``, where
    to search when the map has no points near the guess; ``T_last``, the last pose, a rival when tracking
    entered no answer."""

    T_fallback: Optional[np.ndarray] = None
    T_last: Optional[np.ndarray] = None


class TrackThenRecover:
    """Tracking first; the global search when tracking doubts its answer (:meth:`~.tracking.Tracker.doubts`)."""

    def __init__(self, tracker: Tracker, recovery: Recovery) -> None:
        self.tracker = tracker
        self.recovery = recovery

    def register(self, frame: Frame, target_map: VoxelMap, T_predicted: np.ndarray, *, recover_because: str = "",
                 T_last: Optional[np.ndarray] = None, dt_ratio: float = 1.0, effort: float = 1.0,
                 after_gap: bool = False, fallbacks: RecoveryFallbacks = RecoveryFallbacks()) -> Registered:
        """``frame`` registered against ``target_map`` near ``T_predicted``.

        ``recover_because``: why the global search runs without tracking first ("" = track first); ``T_last``:
        the last pose, tracking's last start; ``dt_ratio`` and ``effort``: see
        :meth:`~.tracking.Tracker.contest`; ``after_gap``: the time step was longer than ``recovery.gap``
        (tracking's answer must then fit at the running level).
        """
        why = recover_because
        if why:
            contest = self.tracker.contest(frame, target_map, T_predicted, dt_ratio, effort)
        else:
            estimate, contest = self.tracker.track(frame, target_map, T_predicted, dt_ratio, T_last, effort)
            doubts = self.tracker.doubts(estimate, after_gap=after_gap)
            if not doubts:
                return Registered(self._checked(estimate, contest), contest)
            why = "tracking failed (" + "; ".join(doubts) + ")"
        estimate = self.recovery.recover(frame, target_map, contest, fallbacks.T_fallback, fallbacks.T_last)
        return Registered(self._checked(estimate, contest), contest, why)

    def _checked(self, estimate: Estimate, contest: Contest) -> Estimate:
        """The answer after the neighbour check (:meth:`~.contest.Contest.checked_against_neighbours`)."""
        return contest.checked_against_neighbours(estimate, self.tracker.config.tracking.tie_ratio)
