"""Scan-to-map odometry (sequential mode) and source-to-target alignment (pair mode) with CEMNet.

Sequential mode registers each scan against a local map of the recent scans (:class:`VoxelMap`, odom frame):

0. **check** the input's plausibility (:mod:`.steps.input_checks`: stamp, frame, point count, size);
1. **preprocess** (:mod:`.steps.frame`, :mod:`.steps.sweep`): deskew, drop non-finite points, crop by range, voxel grid;
   the CEM's subset and the polish's subset;
2. **predict**: the constant-velocity pose, and how far to search around it (:class:`AdaptiveSpread`);
3. **register** (:mod:`.steps.registration`): the plan's starts (:mod:`.steps.starts`), cheapest first: the
   prediction polished point to plane against the map, the prediction polished from afar, the CEM around it
   against a sample of the map, the last pose from afar, then the global CEM search (yaw over the full circle,
   metres of translation) and turns of the last pose; each answer measured once (:mod:`.steps.answer`);
4. **decide** (:mod:`.steps.decision`) on the answers' evidence (:mod:`.steps.evidence`) after each stage: the
   plan ends once an answer stands; the global search competes where the cheaper starts do not settle it, on the
   first pair, after a failed step and on request;
5. **commit** the outcome: an accepted step moves the pose, the map, the motion model, the adaptive spread and
   the running level; a failed one is published flagged with the prediction and changes nothing else
   (too many in a row restart the map, where :mod:`.steps.lost_streak` says, and the level with it); a
   degenerate one (a direction barely constrained) is flagged and still extends the map (the accepted step that
   ends a run of them must be seen by the map as last vouched, :mod:`.degenerate_stretch`); a near-tie (equals, or
   the map and its last scan disagree) is flagged and moves the pose and the level only; an unconfirmed one (a
   live scan without time for the search, :mod:`.steps.scan_budget`) is flagged and joins the map unvouched,
   checked by the search beside the worker (:mod:`.unvouched`). The step's covariance is its
   registration's plus the previous pose's error against the map (:func:`~.steps.covariance.carried_into_step`).

Pair mode (:mod:`.pair_mode`) runs steps 0-4 against a map of the target cloud. Poses are ``T_odom_sensor``;
odom is the first scan's sensor frame. Units: see :mod:`.steps.frame`.
"""
from __future__ import annotations

import copy
import dataclasses
import time
from typing import Callable, Optional

import numpy as np

from cemnet_ros.core import Registrar
from cemnet_ros.core.config import RegistrationConfig
from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.degenerate_stretch import DegenerateStretch
from cemnet_ros.pipeline.map.gicp_cloud import GicpCloud
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.pair_mode import PairMode
from cemnet_ros.pipeline.steps import preprocess, refine
from cemnet_ros.pipeline.steps.adaptive import AdaptiveSpread
from cemnet_ros.pipeline.steps.alignment_step import AlignmentStep
from cemnet_ros.pipeline.steps.answer import distinct
from cemnet_ros.pipeline.steps.covariance import carried_into_step
from cemnet_ros.pipeline.steps.decision import Outcome, Verdict
from cemnet_ros.pipeline.steps.frame import Frame, Preprocessor
from cemnet_ros.pipeline.steps.health import RunningLevel, disagreement
from cemnet_ros.pipeline.steps.input_checks import InputChecks
from cemnet_ros.pipeline.steps.lost_streak import LostStreak
from cemnet_ros.pipeline.steps.metric_cem import MetricEngine, prior_registrar
from cemnet_ros.pipeline.steps.motion import ConstantVelocity
from cemnet_ros.pipeline.steps.registration import EARLY, Registered, Registration
from cemnet_ros.pipeline.steps.scan_budget import ScanBudget
from cemnet_ros.pipeline.steps.sweep import SweepDeskewer
from cemnet_ros.pipeline.threads import bound_threads
from cemnet_ros.pipeline.unvouched import Check, Unvouched, UnvouchedScan

FIRST_PAIR, REQUESTED = "first pair", "requested"  # why a scan runs the global search whatever its budget


class ScanAligner:
    """Stateful scan pipeline; see the module docstring for the recipe."""

    def __init__(self, config: Optional[AlignerConfig] = None, registrar: Optional[Registrar] = None,
                 recovery_prior: Optional[Registrar] = None) -> None:
        """``registrar``: the tracking CEM's; ``recovery_prior``: the one whose network draws part of the recovery's
        scatter with ``recovery.scatter`` 'network' (default: one loading ``recovery.weights``); built when absent."""
        self.config = config or AlignerConfig()
        prior = "network" if self.config.tracking.centre == "network" else "identity"  # a given centre: no network
        registrar = registrar or Registrar(RegistrationConfig.of(self.config.tracking_engine(), prior))
        self._preprocessor = Preprocessor(self.config)
        self._checks = InputChecks(self.config.checks)
        self._motion = ConstantVelocity()
        self._spread = AdaptiveSpread(self.config.adaptive)
        self._level = RunningLevel(self.config.health.level_memory)
        self._lost = LostStreak()
        engine = MetricEngine(self.config, registrar, prior_registrar(self.config, recovery_prior))
        self._registration = Registration(self.config, engine, self._spread)
        self._sweep = SweepDeskewer(self.config.preprocess.deskew, self._preprocessor)
        self._pairs = PairMode(self.config, self._preprocessor, self._checks, self._registration)
        self._unvouched = Unvouched()
        self._stretch = DegenerateStretch()
        preprocess.compile_kernels()  # the first scan must not pay the kernels' compilation
        refine.compile_kernels()
        self.reset()

    @property
    def scale(self) -> Optional[float]:
        """Metres per network unit (None until the first scan fixed it in auto mode)."""
        return self._preprocessor.scale

    @property
    def voxel(self) -> float:
        """Frame voxel size (m); 0 = no voxel grid, or nothing preprocessed yet."""
        return self._preprocessor.voxel

    @property
    def local_map(self) -> Optional[VoxelMap]:
        return self._map

    @property
    def pose(self) -> np.ndarray:
        """T_odom_sensor of the last scan (the identity before the first)."""
        return self._pose.copy()

    def reset(self, T_odom_sensor: Optional[np.ndarray] = None) -> None:
        """Forget the map and the motion model (the auto scale is measured again); the next scan starts a new
        trajectory at ``T_odom_sensor`` (default: the identity; pass :attr:`pose` to keep odom continuous)."""
        self._preprocessor.reset()
        self._map: Optional[VoxelMap] = None
        self._motion.reset()
        self._spread.reset()
        self._level.reset()
        self._pose = np.eye(4) if T_odom_sensor is None else np.asarray(T_odom_sensor, dtype=np.float64).copy()
        self._pending_recovery = ""  # why the next scan runs the global search ("" = it tracks)
        self._failures_in_a_row = 0
        self._lost.reset()
        self._T_odom_last_insert: Optional[np.ndarray] = None  # where the map last grew (a recovery's fallback)
        self._pose_vs_map = np.zeros((6, 6))  # covariance of the pose's error against the map (ROS order)
        self._sweep.reset()
        self._pairs.reset()
        self._checks.forget_frame()
        self._unvouched.clear()

    def request_recovery(self) -> None:
        """Run the global search on the next scan (e.g. the robot was carried: a ``~/relocalize`` service)."""
        self._pending_recovery = REQUESTED

    # -- sequential mode ------------------------------------------------------------------------------------
    def process(self, points: np.ndarray, stamp_ns: int, point_times: Optional[np.ndarray] = None,
                frame_id: str = "", now_ns: Optional[int] = None, effort: float = 1.0,
                budget_s: Optional[float] = None) -> AlignmentStep:
        """Register this scan against the local map and accumulate the pose.

        The scan first passes the input checks (:mod:`.steps.input_checks`: its non-finite points are dropped;
        ``now_ns``: the caller's clock for the future-stamp check); a rejected one raises ScanRejected and
        changes nothing. ``point_times``: each point's time (s, relative to
        ``stamp_ns``, aligned with ``points``); with ``config.preprocess.deskew`` the scan is first deskewed
        (:mod:`.steps.sweep`). The pose is the one at ``stamp_ns`` in any case. ``effort`` (0, 1] scales the
        polishes' and the global search's budgets (a live node behind its input; offline replays use 1);
        ``budget_s``: what the scan may hold the worker for (:mod:`.steps.scan_budget`; None: no bound, as
        offline).
        """
        start, stamp_ns = time.perf_counter(), int(stamp_ns)
        bound_threads(self.config.threads)
        admitted = self._checks.admit(points, point_times, stamp_ns, frame_id, now_ns)
        if admitted.restart:
            self.reset(self._pose)
        points, offset_ns, self._map = self._sweep.deskewed(admitted.points, admitted.times, stamp_ns,
                                                            self._motion.velocity, self._motion.last_stamp, self._map)
        step = self._process_at(points, stamp_ns + offset_ns, start, effort, self._budget(start, budget_s))
        step.vouched_late = [stamp - offset_ns for stamp in step.vouched_late]  # as they were published
        self._checks.passed(admitted)
        step.warnings, step.effort = admitted.warnings, effort
        return self._sweep.at_stamp(step, stamp_ns, offset_ns, self._motion.velocity, self._motion.has_velocity)

    @property
    def period_s(self) -> Optional[float]:
        """The running mean of the intervals between the stamps of the scans processed (s; None before two)."""
        period_ns = self._motion.period_ns
        return None if period_ns is None else period_ns * 1e-9

    def _budget(self, start: float, seconds: Optional[float]) -> Optional[ScanBudget]:
        """The scan's budget from ``start`` (None: no bound; a first pair or a requested search runs whatever it
        costs: nothing else can vouch for the one, and a user asked for the other)."""
        if seconds is None or self._pending_recovery in (FIRST_PAIR, REQUESTED):
            return None
        return ScanBudget(start, seconds, self._registration.stage_costs)

    def _process_at(self, points: np.ndarray, stamp_ns: int, start: float, effort: float,
                    budget: Optional[ScanBudget]) -> AlignmentStep:
        """The sequential step with the scan taken at ``stamp_ns`` (its reference time, see :mod:`.steps.sweep`)."""
        frame = self._preprocessor.frame(points)
        last_stamp = self._motion.last_stamp
        if last_stamp is not None and stamp_ns == last_stamp:
            return self._held(stamp_ns, start, frame, "duplicate stamp: scan skipped")
        if self._map is None or last_stamp is None or stamp_ns < last_stamp:
            return self._start_trajectory(frame, stamp_ns, start)
        settled, vouched_late = self._settle_check()
        T_predicted = self._pose @ self._motion.predict_relative(stamp_ns)
        level, why, T_last, T_fallback = self._level.level, self._pending_recovery, self._pose, self._T_odom_last_insert
        dt_ratio, moving = self._motion.dt_ratio(stamp_ns), self._motion.has_velocity

        def plan(registration: Registration, target_map: VoxelMap, effort: float = 1.0,
                 budget: Optional[ScanBudget] = None) -> Registered:
            """This scan's plan against ``target_map`` (the live map, or a snapshot of it beside the worker)."""
            return registration.register(frame, target_map, T_predicted, level=level, search_because=why,
                                         T_last=T_last, dt_ratio=dt_ratio, effort=effort, moving=moving,
                                         T_fallback=T_fallback, budget=budget)

        registered = plan(self._registration, self._map, effort, budget)
        check = self._check(plan) if registered.verdict.outcome == Outcome.UNCONFIRMED else None
        registered, untied = self._tied(frame, registered)
        registered = self._held_back(registered)
        step = self._commit(frame, stamp_ns, T_predicted, registered, start, settled)
        step.vouched_late = vouched_late
        if untied:  # its pose rests on the degenerate steps alone: a new anchor
            self._restart_map(frame, self._pose)
            step.map_restarted = True
        if registered.verdict.outcome == Outcome.UNCONFIRMED:
            owed = check is not None and bool(why) and not registered.searched
            self._unvouched.add(UnvouchedScan(stamp_ns, frame, self._pose.copy(), check, owed))
        if effort >= 1.0:  # a worker behind its input has no time to spare for a check beside it
            self._unvouched.start_check()
        return step

    def _check(self, plan: Callable[[Registration, VoxelMap], Registered]) -> Check:
        """The check of a scan unconfirmed on its own evidence: its ``plan`` beside the worker, against the map as
        the scan saw it (its commit is about to take the scan in) with the motion spread as it saw it."""
        assert self._map is not None
        map_before = self._map.snapshot()
        beside = Registration(self.config, self._registration.engine, copy.deepcopy(self._spread))
        return Check(map_before, self._T_odom_last_insert, lambda: plan(beside, map_before))

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

    def _settle_check(self) -> tuple[str, list[int]]:
        """Take in the check beside the worker that ended since the last scan (:mod:`.unvouched`): what it did, for
        this step's reason ("": none ended), and the stamps of the steps it vouched for."""
        finished = self._unvouched.finished()
        return ("", []) if finished is None else self._settle(*finished)

    def _settle(self, scan: UnvouchedScan, registered: Registered) -> tuple[str, list[int]]:
        """The outcome of ``scan``'s check (see :mod:`.unvouched`)."""
        at = f"the step at {scan.stamp_ns * 1e-9:.3f} s"
        T_checked, stands = registered.T_odom_sensor, registered.verdict.outcome in EARLY
        if stands and T_checked is not None and not distinct(T_checked, scan.T_inserted):
            return f"{at} confirmed by the search beside the worker", self._unvouched.vouched(scan)
        before = self._unvouched.before
        self._map, self._T_odom_last_insert = before.map_before, before.T_last_insert_before
        self._unvouched.clear()
        if not stands or T_checked is None:
            self._pending_recovery = f"the search beside the worker did not confirm {at}"
            return (f"{at} not confirmed by the search beside the worker ({registered.verdict.outcome.value}): "
                    "the map goes back to the one last vouched for"), []
        T_correction = T_checked @ np.linalg.inv(scan.T_inserted)
        self._pose = T_correction @ self._pose
        self._motion.moved(T_correction)
        self._sweep.moved(T_correction)
        self._insert(scan.frame, T_checked)
        metres, radians = disagreement(scan.T_inserted, T_checked)
        return (f"the search beside the worker placed {at} {metres:.2f} m, {np.degrees(radians):.1f} deg from its "
                "answer: the map goes back to the one last vouched for and takes it in there, the pose moves with "
                "it"), []

    def _start_trajectory(self, frame: Frame, stamp_ns: int, start: float) -> AlignmentStep:
        """The first scan (or one whose stamp went back): the map restarts from it, the pose is kept."""
        last_stamp = self._motion.last_stamp
        restarted = last_stamp is not None
        reason = (f"stamp went back {(last_stamp - stamp_ns) * 1e-9:.3f} s: restarted from this scan, "
                  "pose kept") if last_stamp is not None else ""
        self._preprocessor.adopt(frame)
        self._restart_map(frame, self._pose)
        self._motion.reset()
        self._motion.update(self._pose, stamp_ns)
        self._spread.reset()
        self._pending_recovery = FIRST_PAIR  # a single pose predicts nothing
        return AlignmentStep.unregistered(stamp_ns, self._pose, accepted=not restarted, fitness=1.0,
                                          latency_s=time.perf_counter() - start, n_points=len(frame.sampled),
                                          reason=reason, map_restarted=True)

    def _restart_map(self, frame: Frame, T_odom_sensor: np.ndarray) -> None:
        """Lost: a new map from this scan at ``T_odom_sensor``; the odometry stays continuous (flagged)."""
        self._map = self._preprocessor.new_map()
        self._map.update(apply_transform(T_odom_sensor, frame.dense), T_odom_sensor[:3, 3],
                         self._scan_cloud(frame, self._map.gicp_voxel, T_odom_sensor))
        self._T_odom_last_insert = T_odom_sensor.copy()
        self._pose_vs_map = np.zeros((6, 6))  # the map is this scan where it is: no error against it
        self._sweep.map_restarted(T_odom_sensor)
        self._level.reset()  # what right answers fit depends on the scene: the new map's steps set it again
        self._unvouched.clear()
        self._stretch.clear()
        self._pending_recovery = ""
        self._failures_in_a_row = 0
        self._lost.reset()

    def _commit(self, frame: Frame, stamp_ns: int, T_predicted: np.ndarray, registered: Registered,
                start: float, settled: str = "") -> AlignmentStep:
        """Apply the outcome (see the module): a failed step publishes the prediction, the others their answer;
        ``settled``: what the check beside the worker did before it (its reason's last part)."""
        verdict, previous, answered = registered.verdict, self._pose, registered.T_odom_sensor
        if verdict.failed or answered is None:
            covariance = self._covariance(registered, T_predicted)
            pose, reasons, restarted = self._failed(frame, stamp_ns, T_predicted, registered)
        else:
            covariance = self._covariance(registered, answered)
            pose, reasons, restarted = answered, [verdict.reason] if verdict.reason else [], False
            self._extend(frame, pose, T_predicted, registered)
        reasons += [settled] if settled else []
        self._pose = pose
        self._motion.update(pose, stamp_ns)
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
        carried = carried_into_step(self._pose_vs_map, self._pose, pose)
        self._pose_vs_map = covariance
        return covariance + carried

    def _failed(self, frame: Frame, stamp_ns: int, T_predicted: np.ndarray, registered: Registered
                ) -> tuple[np.ndarray, list[str], bool]:
        """A step that cannot be vouched for, flagged (the pose published, the reasons, whether the map
        restarted): the prediction, and the next scan sends the global search to compete; too many in a row
        restart the map from this scan, where :class:`.LostStreak` says."""
        self._failures_in_a_row += 1
        self._pending_recovery = "the previous step failed"
        leader = registered.evidence.leader
        overlaps = leader is not None and leader.fitness >= self.config.health.min_fitness
        self._lost.failed(registered.answer if overlaps else None, stamp_ns)
        reason = registered.verdict.reason
        if self._failures_in_a_row < self.config.recovery.restart_after:
            return T_predicted, [reason, "motion prediction used"], False
        pose, where = self._lost.restart_pose(T_predicted)
        self._restart_map(self._preprocessor.rescaled_if_lost(frame), pose)
        return pose, [reason, where,
                      f"lost for {self.config.recovery.restart_after} scans: the map restarts from this scan"], True

    def _extend(self, frame: Frame, pose: np.ndarray, T_predicted: np.ndarray, registered: Registered) -> None:
        """A step that is not failed: the fitness level takes it in; the map and the prediction errors every one
        but a near-tie, which moves the pose and the level only (a map grown at a guess among equals would mislead
        every later scan; an unconfirmed answer goes in unvouched, :mod:`.unvouched`)."""
        assert self._map is not None  # a step is only committed against the map it was registered on
        self._pending_recovery = ""
        self._failures_in_a_row = 0
        self._lost.reset()
        leader = registered.evidence.leader
        assert leader is not None  # a step that is not failed has an answer
        self._level.accept(leader.signals)  # near-ties too: equals fit alike, and that is what this scene gives
        if registered.verdict.outcome == Outcome.NEAR_TIE:
            return
        if not registered.searched:  # a search's guess was no prediction of the motion model
            self._spread.update(np.linalg.inv(T_predicted) @ pose)
        if registered.verdict.outcome == Outcome.DEGENERATE:
            self._stretch.entering(self._map)
        elif registered.verdict.vouched:
            self._stretch.clear()
        self._insert(frame, pose)
        self._sweep.inserted(pose)

    def _insert(self, frame: Frame, pose: np.ndarray) -> None:
        """The frame into the map at ``pose``."""
        assert self._map is not None
        self._map.update(apply_transform(pose, frame.dense), pose[:3, 3],
                         self._scan_cloud(frame, self._map.gicp_voxel, pose))
        self._T_odom_last_insert = pose.copy()

    @staticmethod
    def _scan_cloud(frame: Frame, voxel: float, T_odom_sensor: np.ndarray) -> Callable[[], GicpCloud]:
        """What makes the frame's GICP cloud placed at its pose, for the map to keep as its last scan."""
        pose = T_odom_sensor.copy()
        return lambda: frame.gicp_cloud(voxel).placed(pose)

    def _held(self, stamp_ns: int, start: float, frame: Frame, reason: str) -> AlignmentStep:
        """A scan not registered (e.g. a duplicate stamp): the pose held, flagged."""
        return AlignmentStep.unregistered(stamp_ns, self._pose, accepted=False, fitness=0.0,
                                          latency_s=time.perf_counter() - start, n_points=len(frame.sampled),
                                          reason=reason)

    # -- pair mode ------------------------------------------------------------------------------------------
    def align_pair(self, source: np.ndarray, target: np.ndarray, stamp_ns: int, *, source_frame: str = "",
                   target_frame: str = "", target_stamp_ns: Optional[int] = None, now_ns: Optional[int] = None
                   ) -> AlignmentStep:
        """Pair mode (:class:`~.pair_mode.PairMode`): the pose of ``source`` in the frame of ``target``."""
        bound_threads(self.config.threads)
        return self._pairs.align(source, target, stamp_ns, source_frame=source_frame, target_frame=target_frame,
                                 target_stamp_ns=target_stamp_ns, now_ns=now_ns)
