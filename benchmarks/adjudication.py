"""The judge measured as a classifier: every step accepted or flagged, its answer right or wrong.

A step's *answer* is the pose the method registered for it (the node's judged answer even where it flagged it
and published the prediction; none where it had none: off the map, an error). The answer is measured from the
step's *anchor*: the last earlier step the method vouched for (accepted) or restarted its map from (the first
scan, a lost map's restart), because that is the pose the answer claims to be right against. Peers accept every
step, so their anchor is always the step before.

An answer is **wrong** when its motion from the anchor is off the reference's by more than the sequence's
thresholds (:attr:`~.real.Sequence.off`: metres, degrees) AND off the data's own optimum near the reference by
as much: small_gicp GICP of the scan against the anchor's scan, started from the reference's relative pose (a
reference with its own error is not held against the method where the data agrees with the method). No answer
is wrong.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from benchmarks.metrics import relative_error

GICP_VOXEL_M, GICP_MAX_DISTANCE_M = 0.25, 1.0  # the data's optimum: small_gicp GICP on 25 cm voxels


@dataclass(frozen=True)
class Judged:
    """One step as a classifier sees it."""

    index: int
    anchor: Optional[int]  # the step its answer is measured from (None: no earlier anchor)
    accepted: bool
    right: bool
    error_m: float  # the answer's motion from the anchor against the reference's (inf: no answer)
    error_deg: float


class DataOptimum:
    """small_gicp GICP between two scans of a sequence started from a relative pose, each pair computed once."""

    def __init__(self, scans: Sequence[np.ndarray]) -> None:
        self._scans = scans
        self._clouds: dict[int, tuple] = {}
        self._found: dict[tuple[int, int], np.ndarray] = {}

    def relative(self, target: int, source: int, T_start: np.ndarray) -> np.ndarray:
        """T_target_source that GICP finds from ``T_start``."""
        if (target, source) not in self._found:
            import small_gicp

            target_cloud, target_tree = self._cloud(target)
            source_cloud, _ = self._cloud(source)
            result = small_gicp.align(target_cloud, source_cloud, target_tree, init_T_target_source=T_start,
                                      registration_type="GICP", max_correspondence_distance=GICP_MAX_DISTANCE_M,
                                      num_threads=1)
            self._found[(target, source)] = np.asarray(result.T_target_source)
        return self._found[(target, source)]

    def _cloud(self, index: int) -> tuple:
        if index not in self._clouds:
            import small_gicp

            self._clouds[index] = small_gicp.preprocess_points(np.asarray(self._scans[index], dtype=np.float64),
                                                               GICP_VOXEL_M, num_threads=1)
        return self._clouds[index]


def answer_is_right(T_anchor: np.ndarray, T_answer: Optional[np.ndarray], truth_anchor: np.ndarray,
                    truth_answer: np.ndarray, off: tuple[float, float], optimum: Optional[DataOptimum],
                    anchor: int, index: int) -> tuple[bool, float, float]:
    """(right, metres, degrees) of one answer (see the module)."""
    if T_answer is None:
        return False, float("inf"), float("inf")
    estimated = np.linalg.inv(T_anchor) @ T_answer
    reference = np.linalg.inv(truth_anchor) @ truth_answer
    metres, degrees = relative_error(estimated, reference)
    if metres <= off[0] and degrees <= off[1]:
        return True, metres, degrees
    if optimum is None:
        return False, metres, degrees
    data_metres, data_degrees = relative_error(estimated, optimum.relative(anchor, index, reference))
    return bool(data_metres <= off[0] and data_degrees <= off[1]), metres, degrees


def judge_steps(truth: Sequence[np.ndarray], published: Sequence[Optional[np.ndarray]],
                answers: Sequence[Optional[np.ndarray]], accepted: Sequence[bool], restarted: Sequence[bool],
                off: tuple[float, float], optimum: Optional[DataOptimum] = None) -> list[Judged]:
    """Every step after the first, judged from its anchor (see the module); ``published``: the poses the method
    published (None: the call failed), ``restarted``: its map restarted at that step."""
    out, anchor = [], None
    for k in range(len(truth)):
        if k and anchor is not None:
            right, metres, degrees = answer_is_right(published[anchor], answers[k], truth[anchor], truth[k], off,
                                                     optimum, anchor, k)
            out.append(Judged(k, anchor, bool(accepted[k]), right, metres, degrees))
        elif k:
            out.append(Judged(k, None, bool(accepted[k]), False, float("inf"), float("inf")))
        if published[k] is not None and (accepted[k] or restarted[k] or anchor is None):
            anchor = k
    return out


def confusion(steps: Sequence[Judged]) -> dict[str, float | int | None]:
    """Accepted right / wrong, flagged right / wrong, and the share of right steps accepted."""
    counts = {"accepted_right": 0, "accepted_wrong": 0, "flagged_right": 0, "flagged_wrong": 0}
    for s in steps:
        counts[f"{'accepted' if s.accepted else 'flagged'}_{'right' if s.right else 'wrong'}"] += 1
    right = counts["accepted_right"] + counts["flagged_right"]
    return {**counts, "right_accepted_share": counts["accepted_right"] / right if right else None}
