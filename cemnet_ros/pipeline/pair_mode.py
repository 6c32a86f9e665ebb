"""Pair mode: the pose of each source scan in the frame of a target cloud (e.g. a latched map), no local map.

The same steps as sequential mode (:mod:`.aligner`) against a map built from the target alone: check both
clouds, track from the constant-velocity prediction of the source's pose, recover with the global search
when there is no pose yet or tracking failed. A reused target (the same array) is prepared once.
"""
from __future__ import annotations

import dataclasses
import time
from typing import Optional

import numpy as np

from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.errors import ScanRejected
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.frame import Frame, Preprocessor
from cemnet_ros.pipeline.steps.input_checks import InputChecks
from cemnet_ros.pipeline.steps.motion import ConstantVelocity
from cemnet_ros.pipeline.steps.recovery import Recovery
from cemnet_ros.pipeline.steps.tracking import Tracker
from cemnet_ros.pipeline.steps.verdict import AlignmentStep, Estimate


class PairMode:
    """Source-to-target alignment sharing the aligner's units, source checks, tracker and recovery."""

    def __init__(self, config: AlignerConfig, preprocessor: Preprocessor, source_checks: InputChecks,
                 tracker: Tracker, recovery: Recovery) -> None:
        self.config = config
        self.preprocessor = preprocessor
        self.source_checks = source_checks
        # Targets (a latched map keeps its old stamp): their own levels and frame, no stamp order.
        self.target_checks = InputChecks(dataclasses.replace(config.checks, stamp_jump=0.0))
        self.tracker = tracker
        self.recovery = recovery
        self._motion = ConstantVelocity()
        self._targets: dict[int, tuple[np.ndarray, VoxelMap]] = {}
        self.reset()

    def reset(self) -> None:
        """Forget the source's motion, the last target and the target stream's frame."""
        self._motion.reset()
        self._last_stamp: Optional[int] = None
        self._targets.clear()
        self.target_checks.forget_frame()

    def align(self, source: np.ndarray, target: np.ndarray, stamp_ns: int, *, source_frame: str = "",
              target_frame: str = "", target_stamp_ns: Optional[int] = None, now_ns: Optional[int] = None
              ) -> AlignmentStep:
        """The pose of ``source`` in the frame of ``target``.

        Both clouds pass the input checks first, each against the levels of its own stream (a target's kinds
        are prefixed ``target_``; its stamp is checked against the clock only); ScanRejected changes nothing.
        """
        start, stamp_ns = time.perf_counter(), int(stamp_ns)
        admitted = self.source_checks.admit(source, None, stamp_ns, source_frame, now_ns)
        target_map, target_warnings = self._target_map(
            target, target_frame, stamp_ns if target_stamp_ns is None else target_stamp_ns, now_ns)
        frame = self.preprocessor.frame(admitted.points)
        if self._last_stamp is not None and stamp_ns < self._last_stamp:
            self._motion.reset()
        why, estimate = self._register(frame, target_map, stamp_ns)
        previous = self._motion.last_pose
        pose = estimate.T_odom_sensor
        if not estimate.failures:
            self._motion.update(pose, stamp_ns)
        self._last_stamp = stamp_ns
        self.source_checks.passed(admitted)
        step = AlignmentStep(stamp_ns, pose.copy(), None if previous is None else np.linalg.inv(previous) @ pose,
                             estimate.published_covariance(self.config.health.covariance_inflation),
                             estimate.signals.fitness, estimate.accepted, time.perf_counter() - start,
                             len(frame.sampled), "; ".join(estimate.failures + estimate.notes), estimate.recovered,
                             why, estimate.degenerate, estimate.signals.as_dict(),
                             origin=estimate.published_origin)
        step.warnings = admitted.warnings + target_warnings
        return step

    def _register(self, frame: Frame, target_map: VoxelMap, stamp_ns: int) -> tuple[str, Estimate]:
        """(why the global search ran, or "", the estimate): tracking from the prediction, else the search."""
        if self._motion.last_pose is None:
            return "no pose yet", self.recovery.recover(frame, target_map, self.tracker.contest(frame, target_map,
                                                                                                 np.eye(4)))
        T_predicted = self._motion.predict(stamp_ns)
        estimate, contest = self.tracker.track(frame, target_map, T_predicted, 1.0, self._motion.last_pose)
        doubts = self.tracker.doubts(estimate)
        if not doubts:
            return "", estimate
        why = "tracking failed (" + "; ".join(doubts) + ")"
        return why, self.recovery.recover(frame, target_map, contest)

    def _target_map(self, target: np.ndarray, frame_id: str, stamp_ns: int, now_ns: Optional[int]
                    ) -> tuple[VoxelMap, list]:
        """The target's map (and its input checks' warnings), built once per target array; its units become
        the trajectory's."""
        cached = self._targets.get(id(target))
        if cached is not None and cached[0] is target:
            return cached[1], []
        try:
            admitted = self.target_checks.admit(target, None, stamp_ns, frame_id, now_ns)
        except ScanRejected as exc:
            raise ScanRejected(f"target cloud: {exc}", f"target_{exc.kind}") from None
        self.target_checks.passed(admitted)
        frame = self.preprocessor.frame(admitted.points)
        self.preprocessor.adopt(frame)
        target_map = self.preprocessor.new_map()
        target_map.update(frame.dense, np.zeros(3))
        self._targets.clear()
        self._targets[id(target)] = (target, target_map)
        return target_map, admitted.warnings
