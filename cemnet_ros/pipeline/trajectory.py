"""The sequential mode's state and step 5 of its recipe (:mod:`.aligner`): what each outcome does to the pose, the
local map, the motion model, the adaptive spread and the running level.

- **accepted**: the pose, the map, the motion model, the spread and the level take the answer in;
- **failed** (failed, ambiguous, unsettled): the prediction is published; nothing else changes, and the next scan
  sends the global search to compete; too many in a row restart the map from the scan, where
  :mod:`.steps.lost_streak` says;
- **degenerate**: published as registered and the map takes it in; the accepted step that ends a run of them must
  be seen by the map as last vouched (:mod:`.degenerate_stretch`), else it is flagged and the map restarts from it;
- **near-tie**: the pose and the level move, the map does not;
- **unconfirmed** (a live scan without time for the search): joins the map unvouched, checked by the search beside
  the worker (:mod:`.unvouched`); so does every step registered on a map that holds one.

A restarted map anchors on a pose the node did not vouch for: the motion model keeps the velocity of the last
vouched step (:meth:`~.steps.motion.ConstantVelocity.restart_at`). The step's covariance is its registration's plus
the previous pose's error against the map (:func:`~.steps.covariance.carried_into_step`).
"""
from __future__ import annotations

import dataclasses
import time
from typing import Callable, Optional

import numpy as np

from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.degenerate_stretch import DegenerateStretch
from cemnet_ros.pipeline.map.gicp_cloud import GicpCloud
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.adaptive import AdaptiveSpread
from cemnet_ros.pipeline.steps.alignment_step import AlignmentStep
from cemnet_ros.pipeline.steps.answer import distinct
from cemnet_ros.pipeline.steps.covariance import carried_into_step
from cemnet_ros.pipeline.steps.decision import Outcome, Verdict
from cemnet_ros.pipeline.steps.frame import Frame, Preprocessor
from cemnet_ros.pipeline.steps.health import RunningLevel, disagreement
from cemnet_ros.pipeline.steps.lost_streak import LostStreak
from cemnet_ros.pipeline.steps.motion import ConstantVelocity
from cemnet_ros.pipeline.steps.registration import EARLY, Registered
from cemnet_ros.pipeline.steps.sweep import SweepDeskewer
from cemnet_ros.pipeline.unvouched import Check, Unvouched, UnvouchedScan

FIRST_PAIR, REQUESTED = "first pair", "requested"  # why a scan runs the global search whatever its budget


class Trajectory:
    """The pose (T_odom_sensor), the local map and the motion model, moved by each step's outcome."""

    def __init__(self, config: AlignerConfig, preprocessor: Preprocessor, sweep: SweepDeskewer,
                 spread: AdaptiveSpread) -> None:
        self.config = config
        self._preprocessor, self._sweep, self._spread = preprocessor, sweep, spread
        self.motion = ConstantVelocity()
        self.level = RunningLevel(config.health.level_memory)
        self._lost = LostStreak()
        self._unvouched = Unvouched()
        self._stretch = DegenerateStretch()
        self.reset()

    def reset(self, T_odom_sensor: Optional[np.ndarray] = None) -> None:
        """No map, no motion; the next scan starts at ``T_odom_sensor`` (default: the identity)."""
        self.map: Optional[VoxelMap] = None
        self.motion.reset()
        self._spread.reset()
        self.level.reset()
        self.pose = np.eye(4) if T_odom_sensor is None else np.asarray(T_odom_sensor, dtype=np.float64).copy()
        self.pending_recovery = ""  # why the next scan runs the global search ("" = it tracks)
        self._lost.reset()
        self.T_last_insert: Optional[np.ndarray] = None  # where the map last grew (a recovery's fallback)
        self._pose_vs_map = np.zeros((6, 6))  # covariance of the pose's error against the map (ROS order)
        self._unvouched.clear()

    def start(self, frame: Frame, stamp_ns: int) -> None:
        """The first scan (or one whose stamp went back): the map restarts from it at the pose kept."""
        self._preprocessor.adopt(frame)
        self.restart_map(frame, self.pose)
        self.motion.reset()
        self.motion.update(self.pose, stamp_ns)
        self._spread.reset()
        self.pending_recovery = FIRST_PAIR  # a single pose predicts nothing

    def restart_map(self, frame: Frame, T_odom_sensor: np.ndarray) -> None:
        """A new map from this scan at ``T_odom_sensor``; the odometry stays continuous."""
        self.map = self._preprocessor.new_map()
        self.map.update(apply_transform(T_odom_sensor, frame.dense), T_odom_sensor[:3, 3],
                        self._scan_cloud(frame, self.map.gicp_voxel, T_odom_sensor))
        self.T_last_insert = T_odom_sensor.copy()
        self._pose_vs_map = np.zeros((6, 6))  # the map is this scan where it is: no error against it
        self._sweep.map_restarted(T_odom_sensor)
        self.level.reset()  # what right answers fit depends on the scene: the new map's steps set it again
        self._unvouched.clear()
        self._stretch.clear()
        self.pending_recovery = ""
        self._lost.reset()

    def commit(self, frame: Frame, stamp_ns: int, T_predicted: np.ndarray, registered: Registered, start: float,
               settled: str = "", check: Optional[Check] = None, owed_search: bool = False) -> AlignmentStep:
        """Apply the outcome of ``frame``'s registration (see the module); ``settled``: what the check beside the
        worker did before it (its reason's last part); ``check``: an unconfirmed scan's check beside the worker;
        ``owed_search``: the scan owed the global search and had no time for it."""
        registered, untied = self._tied(frame, registered)
        registered = self._held_back(registered)
        verdict, previous, answered = registered.verdict, self.pose, registered.T_odom_sensor
        if verdict.failed or answered is None:
            covariance = self._covariance(registered, T_predicted)
            pose, reasons, restarted = self._failed(frame, stamp_ns, T_predicted, registered)
        else:
            covariance = self._covariance(registered, answered)
            pose, reasons, restarted = answered, [verdict.reason] if verdict.reason else [], untied
            self._extend(frame, pose, T_predicted, registered)
            if untied:  # its pose rests on the degenerate steps alone: a new anchor
                self.restart_map(frame, pose)
        reasons += [settled] if settled else []
        self.pose = pose
        if restarted:
            self.motion.restart_at(pose, stamp_ns)
        else:
            self.motion.update(pose, stamp_ns, vouched=verdict.vouched)
        if verdict.outcome == Outcome.UNCONFIRMED:
            self._unvouched.add(UnvouchedScan(stamp_ns, frame, pose.copy(), check, owed_search))
        return AlignmentStep.registered(
            registered, stamp_ns=stamp_ns, pose=pose, relative=np.linalg.inv(previous) @ pose, covariance=covariance,
            latency_s=time.perf_counter() - start, n_points=len(frame.sampled), reason="; ".join(reasons),
            map_restarted=restarted)

    def _covariance(self, registered: Registered, pose: np.ndarray) -> np.ndarray:
        """The covariance of the step to ``pose``: its registration's (inflated when it failed) plus what the
        previous pose's error against the map carries into it; the pose published now errs against the map by
        this registration's own error from here on (a restarted map resets that)."""
        covariance = registered.covariance
        if registered.verdict.failed:
            covariance = covariance * self.config.health.covariance_inflation
        carried = carried_into_step(self._pose_vs_map, self.pose, pose)
        self._pose_vs_map = covariance
        return covariance + carried

    def _failed(self, frame: Frame, stamp_ns: int, T_predicted: np.ndarray, registered: Registered
                ) -> tuple[np.ndarray, list[str], bool]:
        """A step that cannot be vouched for (the pose published, the reasons, whether the map restarted): the
        prediction, and the next scan sends the global search to compete; too many in a row restart the map from
        this scan, where :class:`.LostStreak` says."""
        self.pending_recovery = "the previous step failed"
        leader = registered.evidence.leader
        overlaps = leader is not None and leader.fitness >= self.config.health.min_fitness
        self._lost.failed(registered.answer if overlaps else None, stamp_ns)
        reason = registered.verdict.reason
        if self._lost.failures < self.config.recovery.restart_after:
            return T_predicted, [reason, "motion prediction used"], False
        pose, where = self._lost.restart_pose(T_predicted)
        self.restart_map(self._preprocessor.rescaled_if_lost(frame), pose)
        return pose, [reason, where,
                      f"lost for {self.config.recovery.restart_after} scans: the map restarts from this scan"], True

    def _extend(self, frame: Frame, pose: np.ndarray, T_predicted: np.ndarray, registered: Registered) -> None:
        """A step that is not failed: the fitness level takes it in; the map and the prediction errors every one
        but a near-tie, which moves the pose and the level only (a map grown at a guess among equals would mislead
        every later scan)."""
        self.pending_recovery = ""
        self._lost.reset()
        leader = registered.evidence.leader
        assert leader is not None  # a step that is not failed has an answer
        self.level.accept(leader.signals)  # near-ties too: equals fit alike, and that is what this scene gives
        if registered.verdict.outcome == Outcome.NEAR_TIE:
            return
        if not registered.searched:  # a search's guess was no prediction of the motion model
            self._spread.update(np.linalg.inv(T_predicted) @ pose)
        if registered.verdict.outcome == Outcome.DEGENERATE:
            assert self.map is not None
            self._stretch.entering(self.map)
        elif registered.verdict.vouched:
            self._stretch.clear()
        self._insert(frame, pose)
        self._sweep.inserted(pose)

    def _tied(self, frame: Frame, registered: Registered) -> tuple[Registered, bool]:
        """An accepted step that ends a degenerate stretch where the map as last vouched does not see it: flagged
        degenerate, and whether it is (:mod:`.degenerate_stretch`)."""
        leader = registered.evidence.leader
        if registered.verdict.outcome != Outcome.ACCEPTED or leader is None:
            return registered, False
        why = self._stretch.untied(self.config, frame, leader.T_odom_sensor, leader.fitness)
        if not why:
            return registered, False
        return dataclasses.replace(registered, verdict=Verdict(Outcome.DEGENERATE, why)), True

    def _held_back(self, registered: Registered) -> Registered:
        """An accepted step registered against a map that holds unvouched scans: unconfirmed until they are
        vouched for (:mod:`.unvouched`)."""
        if registered.verdict.outcome != Outcome.ACCEPTED or not self._unvouched:
            return registered
        oldest = self._unvouched.oldest.stamp_ns * 1e-9
        return dataclasses.replace(registered, verdict=Verdict(Outcome.UNCONFIRMED, (
            f"unconfirmed: the map holds {len(self._unvouched)} scans the search has yet to vouch for (the first at "
            f"{oldest:.3f} s)")))

    def start_check(self) -> None:
        """Check the oldest unvouched scan beside the worker, unless a check runs."""
        self._unvouched.start_check()

    def settle_check(self) -> tuple[str, list[int]]:
        """Take in the check beside the worker that ended since the last scan (:mod:`.unvouched`): what it did, for
        this step's reason ("": none ended), and the stamps of the steps it vouched for."""
        finished = self._unvouched.finished()
        return ("", []) if finished is None else self._settle(*finished)

    def _settle(self, scan: UnvouchedScan, registered: Registered) -> tuple[str, list[int]]:
        """The outcome of ``scan``'s check: confirmed, or the map goes back to the one last vouched for (taking the
        scan in where the check placed it, if it did) and the next scan runs the search: the steps since stood on
        a map the node no longer holds."""
        at = f"the step at {scan.stamp_ns * 1e-9:.3f} s"
        T_checked, stands = registered.T_odom_sensor, registered.verdict.outcome in EARLY
        if stands and T_checked is not None and not distinct(T_checked, scan.T_inserted):
            return f"{at} confirmed by the search beside the worker", self._unvouched.vouched(scan)
        before = self._unvouched.before
        self.map, self.T_last_insert = before.map_before, before.T_last_insert_before
        self._unvouched.clear()
        if not stands or T_checked is None:
            self.pending_recovery = f"the search beside the worker did not confirm {at}"
            return (f"{at} not confirmed by the search beside the worker ({registered.verdict.outcome.value}): "
                    "the map goes back to the one last vouched for"), []
        self.pending_recovery = f"the search beside the worker placed {at} elsewhere"
        T_correction = T_checked @ np.linalg.inv(scan.T_inserted)
        self.pose = T_correction @ self.pose
        self.motion.moved(T_correction)
        self._sweep.moved(T_correction)
        self._insert(scan.frame, T_checked)
        metres, radians = disagreement(scan.T_inserted, T_checked)
        return (f"the search beside the worker placed {at} {metres:.2f} m, {np.degrees(radians):.1f} deg from its "
                "answer: the map goes back to the one last vouched for and takes it in there, the pose moves with "
                "it"), []

    def _insert(self, frame: Frame, pose: np.ndarray) -> None:
        """The frame into the map at ``pose``."""
        assert self.map is not None
        self.map.update(apply_transform(pose, frame.dense), pose[:3, 3],
                        self._scan_cloud(frame, self.map.gicp_voxel, pose))
        self.T_last_insert = pose.copy()

    @staticmethod
    def _scan_cloud(frame: Frame, voxel: float, T_odom_sensor: np.ndarray) -> Callable[[], GicpCloud]:
        """What makes the frame's GICP cloud placed at its pose, for the map to keep as its last scan."""
        pose = T_odom_sensor.copy()
        return lambda: frame.gicp_cloud(voxel).placed(pose)
