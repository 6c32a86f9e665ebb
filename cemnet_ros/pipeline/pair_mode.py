"""Pair mode: the pose of each source scan in the frame of a target cloud (e.g. a latched map), no local map.

The same steps as sequential mode (:mod:`.aligner`) against a map built from the target alone: check both
clouds, then register (:mod:`.steps.registration`): from the constant-velocity prediction of the source's pose,
the global search competing when there is no pose yet or the cheaper starts do not settle it. The running fitness
level is the vouched steps' against the current target: a new target starts without one, and its first answer
stands on the search's evidence (:mod:`.steps.decision`). A reused target (the same array) is prepared once.
"""
from __future__ import annotations

import dataclasses
import time
from typing import Optional

import numpy as np

from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.errors import ScanRejected
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.alignment_step import AlignmentStep
from cemnet_ros.pipeline.steps.frame import Preprocessor
from cemnet_ros.pipeline.steps.health import RunningLevel
from cemnet_ros.pipeline.steps.input_checks import InputChecks
from cemnet_ros.pipeline.steps.motion import ConstantVelocity
from cemnet_ros.pipeline.steps.registration import Registration


class PairMode:
    """Source-to-target alignment sharing the aligner's units, source checks and registration."""

    def __init__(self, config: AlignerConfig, preprocessor: Preprocessor, source_checks: InputChecks,
                 registration: Registration) -> None:
        self.config = config
        self.preprocessor = preprocessor
        self.source_checks = source_checks
        # Targets (a latched map keeps its old stamp): their own levels and frame, no stamp order.
        self.target_checks = InputChecks(dataclasses.replace(config.checks, stamp_jump=0.0))
        self.registration = registration
        self._motion = ConstantVelocity()
        self._level = RunningLevel(config.health.level_memory)
        self._targets: dict[int, tuple[np.ndarray, VoxelMap]] = {}
        self.reset()

    def reset(self) -> None:
        """Forget the source's motion, the last target and the target stream's frame."""
        self._motion.reset()
        self._level.reset()
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
        previous = self._motion.last_pose
        T_predicted, why = (np.eye(4), "no pose yet") if previous is None else (self._motion.predict(stamp_ns), "")
        registered = self.registration.register(frame, target_map, T_predicted, level=self._level.level,
                                                search_because=why, T_last=previous, moving=self._motion.has_velocity)
        failed = registered.verdict.failed
        pose = T_predicted if registered.T_odom_sensor is None else registered.T_odom_sensor
        if not failed:
            self._motion.update(pose, stamp_ns)
        if registered.verdict.vouched and registered.evidence.leader is not None:
            self._level.accept(registered.evidence.leader.signals)
        self._last_stamp = stamp_ns
        self.source_checks.passed(admitted)
        covariance = registered.covariance * (self.config.health.covariance_inflation if failed else 1.0)
        step = AlignmentStep.registered(
            registered, stamp_ns=stamp_ns, pose=pose,
            relative=None if previous is None else np.linalg.inv(previous) @ pose, covariance=covariance,
            latency_s=time.perf_counter() - start, n_points=len(frame.sampled), reason=registered.verdict.reason)
        step.warnings = admitted.warnings + target_warnings
        return step

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
        self._level.reset()  # what right answers fit against another target says nothing about this one
        frame = self.preprocessor.frame(admitted.points)
        self.preprocessor.adopt(frame)
        target_map = self.preprocessor.new_map()
        target_map.update(frame.dense, np.zeros(3))
        self._targets.clear()
        self._targets[id(target)] = (target, target_map)
        return target_map, admitted.warnings
