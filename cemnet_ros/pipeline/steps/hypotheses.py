"""Competing answers of one step (tracking's and the recovery's): the fittest wins, near-ties go to the nearest.

Every answer is a polished, judged :class:`~.verdict.Estimate`. Answers closer than the precision the node
vouches for (``DISTINCT_M``, ``DISTINCT_RAD``: metres and radians, whatever the scene's size or the auto scale)
are one answer. Distinct answers whose fitness is within ``tie_ratio`` of the best are a near-tie the scene
cannot settle: the one next to the motion prediction is kept and flagged (a symmetric scene; the map does not
take it in), and when none is next to it the step fails as ambiguous. A distant answer never replaces a near one
of similar fitness. The chosen answer's ``support`` counts the kinds of start that reached it (the CEM's answer,
the prediction, the last pose, the global search): two kinds that agree confirm it; the global search's
hypotheses count once, since several of them converging to one basin is no independent evidence.
"""
from __future__ import annotations

import numpy as np

from cemnet_ros.pipeline.steps.health import disagreement
from cemnet_ros.pipeline.steps.verdict import Estimate

DISTINCT_M, DISTINCT_RAD = 0.1, np.radians(1.0)  # answers farther apart than what the node vouches for differ


def distinct(T_a: np.ndarray, T_b: np.ndarray) -> bool:
    """Two answers that differ by more than the precision the node vouches for."""
    metres, radians = disagreement(T_a, T_b)
    return metres > DISTINCT_M or radians > DISTINCT_RAD


def choose(estimates: list[Estimate], T_predicted: np.ndarray, tie_ratio: float,
           near: tuple[float, float]) -> Estimate:
    """The fittest answer, or among distinct near-ties the one nearest ``T_predicted``.

    ``near`` (metres, radians): how far from the prediction an answer may lie and still be the prediction's
    (the tracking spread). A near-tie resolved by an answer that near is flagged with a note; near-ties all
    farther are a failure ("ambiguous").
    """
    ranked = sorted(estimates, key=lambda e: -e.signals.fitness)
    for estimate in ranked:
        estimate.support = len({e.origin for e in ranked if not distinct(estimate.T_odom_sensor, e.T_odom_sensor)})
    best = ranked[0]
    ties = [best]
    for estimate in ranked[1:]:
        if estimate.signals.fitness >= tie_ratio * best.signals.fitness and all(
                distinct(estimate.T_odom_sensor, kept.T_odom_sensor) for kept in ties):
            ties.append(estimate)
    if len(ties) == 1:
        return best
    nearest = min(ties, key=lambda e: e.offset_from(T_predicted)[0])
    metres, radians = nearest.offset_from(T_predicted)
    summary = f"{len(ties)} distinct answers within {tie_ratio:.2f} of the best fitness"
    if metres <= near[0] and radians <= near[1]:
        nearest.notes.append(f"symmetric scene: {summary}, the one next to the motion prediction kept")
        nearest.tied = True
        return nearest
    best.failures.append(f"ambiguous: {summary}, none next to the motion prediction")
    return best
