"""What the aligner returns for a scan (:class:`AlignmentStep`): the pose T_odom_sensor, whether the node vouches
for it and why not, its covariance, and what the decision read (:mod:`.decision`)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from cemnet_ros.pipeline.steps.covariance import flat_covariance
from cemnet_ros.pipeline.steps.decision import Outcome
from cemnet_ros.pipeline.steps.registration import Registered


@dataclass
class AlignmentStep:
    """One processed scan: the pose T_odom_sensor and whether the node can vouch for it."""

    stamp_ns: int
    pose: np.ndarray  # (4, 4)
    relative: Optional[np.ndarray]  # (4, 4) T_prev_curr, None for the first scan / after a restart
    covariance: np.ndarray  # (6, 6) ROS order x, y, z, roll, pitch, yaw (docs/node.md: frame and meaning)
    fitness: float
    accepted: bool
    latency_s: float
    n_points: int
    reason: str = ""
    recovered: bool = False  # this step ran the global search
    recovery_reason: str = ""  # why it ran (first pair, the previous step failed, tracking failed, requested)
    outcome: str = Outcome.ACCEPTED.value  # the decision's outcome (:class:`~.decision.Outcome`)
    signals: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)  # (kind, message) from the input checks (decimated, restarted)
    origin: str = ""  # the start the published answer was polished from: prediction, cem, last pose, search
    effort: float = 1.0  # the share of the polishes' and the search's budgets this scan had (a live node behind)
    polishes: int = 0  # answers polished and judged for this scan (the cost of its decision)
    answer: Optional[np.ndarray] = None  # (4, 4) the registered answer judged, also when flagged (None: none)
    map_restarted: bool = False  # the map restarted from this scan (the first scan, or lost)
    vouched_late: list[int] = field(default_factory=list)  # stamps (ns) of earlier steps, published flagged, that the
    # search beside the worker has since confirmed (:mod:`..unvouched`): the node vouches for them now

    @property
    def degenerate(self) -> bool:
        """A direction was weakly constrained: the covariance carries the prediction's uncertainty along it."""
        return self.outcome == Outcome.DEGENERATE.value

    @classmethod
    def registered(cls, registered: Registered, *, stamp_ns: int, pose: np.ndarray, relative: Optional[np.ndarray],
                   covariance: np.ndarray, latency_s: float, n_points: int, reason: str,
                   map_restarted: bool = False) -> AlignmentStep:
        """A registered scan: its verdict, signals and origin from ``registered``; ``pose`` is the one published
        (the prediction when the step failed) with its ``covariance``."""
        verdict, leader = registered.verdict, registered.evidence.leader
        return cls(stamp_ns=stamp_ns, pose=pose.copy(), relative=relative, covariance=covariance,
                   fitness=0.0 if leader is None else leader.fitness, accepted=verdict.vouched, latency_s=latency_s,
                   n_points=n_points, reason=reason, recovered=registered.searched,
                   recovery_reason=registered.why_searched, outcome=verdict.outcome.value,
                   signals={} if leader is None else leader.signals.as_dict(),
                   origin="" if leader is None or verdict.failed else leader.origin.value,
                   polishes=registered.polishes, answer=registered.answer, map_restarted=map_restarted)

    @classmethod
    def unregistered(cls, stamp_ns: int, pose: np.ndarray, *, accepted: bool, fitness: float, latency_s: float,
                     n_points: int, reason: str = "", map_restarted: bool = False) -> AlignmentStep:
        """A scan that was not registered (the first of a trajectory, a duplicate stamp): ``pose`` kept, no
        relative motion, a zero covariance."""
        return cls(stamp_ns=stamp_ns, pose=pose.copy(), relative=None, covariance=flat_covariance(0.0, 0.0),
                   fitness=fitness, accepted=accepted, latency_s=latency_s, n_points=n_points, reason=reason,
                   outcome=(Outcome.ACCEPTED if accepted else Outcome.FAILED).value, map_restarted=map_restarted)
