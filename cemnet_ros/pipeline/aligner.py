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
5. **commit** the outcome (:mod:`.trajectory`): an accepted step moves the pose, the map, the motion model, the
   adaptive spread and the running level; a failed one is published flagged with the prediction and changes
   nothing else (too many in a row restart the map, where :mod:`.steps.lost_streak` says); a degenerate one (a
   direction barely constrained) is flagged and still extends the map (the accepted step that ends a run of them
   must be seen by the map as last vouched, :mod:`.degenerate_stretch`); a near-tie (equals, or the map and its
   last scan disagree) is flagged and moves the pose and the level only; an unconfirmed one (a live scan without
   time for the search, :mod:`.steps.scan_budget`) is flagged and joins the map unvouched, checked by the search
   beside the worker (:mod:`.unvouched`).

Pair mode (:mod:`.pair_mode`) runs steps 0-4 against a map of the target cloud. Poses are ``T_odom_sensor``;
odom is the first scan's sensor frame. Units: see :mod:`.steps.frame`.
"""
from __future__ import annotations

import copy
import time
from typing import Callable, Optional

import numpy as np

from cemnet_ros.core import Registrar
from cemnet_ros.core.config import RegistrationConfig
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.pair_mode import PairMode
from cemnet_ros.pipeline.steps import preprocess, refine
from cemnet_ros.pipeline.steps.adaptive import AdaptiveSpread
from cemnet_ros.pipeline.steps.alignment_step import AlignmentStep
from cemnet_ros.pipeline.steps.decision import Outcome
from cemnet_ros.pipeline.steps.frame import Frame, Preprocessor
from cemnet_ros.pipeline.steps.input_checks import InputChecks
from cemnet_ros.pipeline.steps.metric_cem import MetricEngine, prior_registrar
from cemnet_ros.pipeline.steps.registration import Registered, Registration
from cemnet_ros.pipeline.steps.scan_budget import ScanBudget
from cemnet_ros.pipeline.steps.sweep import SweepDeskewer
from cemnet_ros.pipeline.threads import bound_threads
from cemnet_ros.pipeline.trajectory import FIRST_PAIR, REQUESTED, Trajectory
from cemnet_ros.pipeline.unvouched import Check


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
        self._spread = AdaptiveSpread(self.config.adaptive)
        engine = MetricEngine(self.config, registrar, prior_registrar(self.config, recovery_prior))
        self._registration = Registration(self.config, engine, self._spread)
        self._sweep = SweepDeskewer(self.config.preprocess.deskew, self._preprocessor)
        self._pairs = PairMode(self.config, self._preprocessor, self._checks, self._registration)
        self._trajectory = Trajectory(self.config, self._preprocessor, self._sweep, self._spread)
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
        return self._trajectory.map

    @property
    def pose(self) -> np.ndarray:
        """T_odom_sensor of the last scan (the identity before the first)."""
        return self._trajectory.pose.copy()

    def reset(self, T_odom_sensor: Optional[np.ndarray] = None) -> None:
        """Forget the map and the motion model (the auto scale is measured again); the next scan starts a new
        trajectory at ``T_odom_sensor`` (default: the identity; pass :attr:`pose` to keep odom continuous)."""
        self._preprocessor.reset()
        self._trajectory.reset(T_odom_sensor)
        self._sweep.reset()
        self._pairs.reset()
        self._checks.forget_frame()

    def request_recovery(self) -> None:
        """Run the global search on the next scan (e.g. the robot was carried: a ``~/relocalize`` service)."""
        self._trajectory.pending_recovery = REQUESTED

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
            self.reset(self._trajectory.pose)
        trajectory = self._trajectory
        points, offset_ns, trajectory.map = self._sweep.deskewed(admitted.points, admitted.times, stamp_ns,
                                                                 trajectory.motion.velocity,
                                                                 trajectory.motion.last_stamp, trajectory.map)
        step = self._process_at(points, stamp_ns + offset_ns, start, effort, self._budget(start, budget_s))
        step.vouched_late = [stamp - offset_ns for stamp in step.vouched_late]  # as they were published
        self._checks.passed(admitted)
        step.warnings, step.effort = admitted.warnings, effort
        return self._sweep.at_stamp(step, stamp_ns, offset_ns, trajectory.motion.velocity,
                                    trajectory.motion.has_velocity)

    @property
    def period_s(self) -> Optional[float]:
        """The running mean of the intervals between the stamps of the scans processed (s; None before two)."""
        period_ns = self._trajectory.motion.period_ns
        return None if period_ns is None else period_ns * 1e-9

    def _budget(self, start: float, seconds: Optional[float]) -> Optional[ScanBudget]:
        """The scan's budget from ``start`` (None: no bound; a first pair or a requested search runs whatever it
        costs: nothing else can vouch for the one, and a user asked for the other)."""
        if seconds is None or self._trajectory.pending_recovery in (FIRST_PAIR, REQUESTED):
            return None
        return ScanBudget(start, seconds, self._registration.stage_costs)

    def _process_at(self, points: np.ndarray, stamp_ns: int, start: float, effort: float,
                    budget: Optional[ScanBudget]) -> AlignmentStep:
        """The sequential step with the scan taken at ``stamp_ns`` (its reference time, see :mod:`.steps.sweep`)."""
        frame, trajectory = self._preprocessor.frame(points), self._trajectory
        last_stamp = trajectory.motion.last_stamp
        if last_stamp is not None and stamp_ns == last_stamp:
            return self._held(stamp_ns, start, frame, "duplicate stamp: scan skipped")
        if trajectory.map is None or last_stamp is None or stamp_ns < last_stamp:
            return self._start_trajectory(frame, stamp_ns, start)
        settled, vouched_late = trajectory.settle_check()
        T_predicted = trajectory.pose @ trajectory.motion.predict_relative(stamp_ns)
        level, why, T_last, T_fallback = (trajectory.level.level, trajectory.pending_recovery, trajectory.pose,
                                          trajectory.T_last_insert)
        dt_ratio, moving = trajectory.motion.dt_ratio(stamp_ns), trajectory.motion.has_velocity

        def plan(registration: Registration, target_map: VoxelMap, effort: float = 1.0,
                 budget: Optional[ScanBudget] = None) -> Registered:
            """This scan's plan against ``target_map`` (the live map, or a snapshot of it beside the worker)."""
            return registration.register(frame, target_map, T_predicted, level=level, search_because=why,
                                         T_last=T_last, dt_ratio=dt_ratio, effort=effort, moving=moving,
                                         T_fallback=T_fallback, budget=budget)

        registered = plan(self._registration, trajectory.map, effort, budget)
        check = self._check(plan) if registered.verdict.outcome == Outcome.UNCONFIRMED else None
        owed = check is not None and bool(why) and not registered.searched
        step = trajectory.commit(frame, stamp_ns, T_predicted, registered, start, settled, check, owed)
        step.vouched_late = vouched_late
        if effort >= 1.0:  # a worker behind its input has no time to spare for a check beside it
            trajectory.start_check()
        return step

    def _check(self, plan: Callable[[Registration, VoxelMap], Registered]) -> Check:
        """The check of a scan unconfirmed on its own evidence: its ``plan`` beside the worker, against the map as
        the scan saw it (its commit is about to take the scan in) with the motion spread as it saw it."""
        assert self._trajectory.map is not None
        map_before = self._trajectory.map.snapshot()
        beside = Registration(self.config, self._registration.engine, copy.deepcopy(self._spread))
        return Check(map_before, self._trajectory.T_last_insert, lambda: plan(beside, map_before))

    def _start_trajectory(self, frame: Frame, stamp_ns: int, start: float) -> AlignmentStep:
        """The first scan (or one whose stamp went back): the map restarts from it, the pose is kept."""
        last_stamp = self._trajectory.motion.last_stamp
        reason = (f"stamp went back {(last_stamp - stamp_ns) * 1e-9:.3f} s: restarted from this scan, "
                  "pose kept") if last_stamp is not None else ""
        self._trajectory.start(frame, stamp_ns)
        return AlignmentStep.unregistered(stamp_ns, self._trajectory.pose, accepted=last_stamp is None, fitness=1.0,
                                          latency_s=time.perf_counter() - start, n_points=len(frame.sampled),
                                          reason=reason, map_restarted=True)

    def _held(self, stamp_ns: int, start: float, frame: Frame, reason: str) -> AlignmentStep:
        """A scan not registered (e.g. a duplicate stamp): the pose held, flagged."""
        return AlignmentStep.unregistered(stamp_ns, self._trajectory.pose, accepted=False, fitness=0.0,
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
