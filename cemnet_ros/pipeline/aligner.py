"""Scan-to-map odometry (sequential mode) and source-to-target alignment (pair mode) with CEMNet.

Sequential mode registers each scan against a local map of the recent scans (:class:`VoxelMap`, odom frame):

0. **check** the input's plausibility (:mod:`.input_checks`: stamp, frame, point count, size);
1. **preprocess**: drop non-finite points, crop by range, voxel grid; the CEM's subset and the polish's subset;
2. **predict**: the constant-velocity pose, and how far to search around it (:class:`AdaptiveSpread`);
3. **track**: the CEM around the prediction against a sample of the map, then a point-to-plane polish
   against the map itself;
4. **judge** the step without ground truth (:class:`HealthMonitor`: fitness, agreement, conditioning, spread);
5. **recover** when tracking failed, on the first pair, after a stamp gap or on request: the global CEM search
   (:func:`~cemnet_ros.core.global_search.global_search`: yaw over the full circle, metres of translation),
   then the polish, judged the same way plus an ambiguity check between distinct hypotheses;
6. **commit**: a good step moves the pose, the map, the motion model and the adaptive spread; a failed one is
   published flagged with the prediction and changes nothing else; a degenerate one keeps the prediction along
   the unconstrained directions, is flagged, and still extends the map.

Units: the network and the CEM's epsilon live on the ModelNet unit sphere. Clouds are centred on the target
sample's centroid and divided by ``scale`` (metres per network unit, auto: the robust radius of the scan that
starts the trajectory, measured again when a lost trajectory restarts from a scan twice as large or small).
Poses are ``T_odom_sensor``; odom is the first scan's sensor frame.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from cemnet_ros.core import Registrar
from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.core.global_search import global_search
from cemnet_ros.pipeline import preprocess, refine
from cemnet_ros.pipeline.adaptive import AdaptiveSpread
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.covariance import Conditioning, covariance_from_hessian, flat_covariance, keep_prediction_along
from cemnet_ros.pipeline.deskew import deskew, se3_exp, se3_log
from cemnet_ros.pipeline.health import HealthMonitor, Signals, disagreement
from cemnet_ros.pipeline.input_checks import InputChecks, ScanRejected
from cemnet_ros.pipeline.motion import ConstantVelocity
from cemnet_ros.pipeline.preprocess import crop_range, finite_points, robust_radius, subsample, voxel_downsample
from cemnet_ros.pipeline.refine import PolishResult, point_to_plane_icp
from cemnet_ros.pipeline.voxel_map import VoxelMap

TRACKING_PAIRING = 3.0  # frame voxels: the tracking polish pairs within the adaptive spread, at most this far
LINEAR_LIMIT = 0.1  # rad: up to this rotation from the prediction a degenerate direction falls back on it
POLISH_FRACTION = 0.8  # recovery: hypotheses whose CEM fitness is this close to the best one's get polished


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
    recovery_reason: str = ""  # why it ran (first pair, stamp gap, tracking failed, requested)
    degenerate: bool = False  # a direction was unconstrained: the prediction was kept along it
    signals: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)  # (kind, message) from the input checks (decimated, restarted)


@dataclass
class Frame:
    """A preprocessed scan (sensor frame, metres): voxel cloud (map), polish subset and CEM subset.

    The CEM sees points near the sensor only: its look-up lattices span the clouds' box, and far points make
    that box (and its cache misses) large for little information.
    """

    dense: np.ndarray
    polish: np.ndarray
    sampled: np.ndarray
    near: np.ndarray  # the voxel points within the CEM's radius (the global search draws from them)
    scale: float  # metres per network unit this frame was prepared with
    voxel: float  # its voxel size (m)

    @property
    def length(self) -> float:
        """RMS range of the polish points: the lever arm that makes rotations comparable to translations."""
        return float(np.sqrt(np.mean(np.sum(self.polish ** 2, axis=1)))) or 1.0


@dataclass
class Estimate:
    """A registration and its verdict, before it is committed."""

    T_odom_sensor: np.ndarray
    covariance: np.ndarray
    signals: Signals
    failures: list[str]  # why it cannot be vouched for: the prediction is published instead
    notes: list[str]  # why it is flagged although its pose is used (degenerate, ambiguity resolved)
    recovered: bool
    free_directions: np.ndarray  # (6, k) normalised directions the scene leaves unconstrained
    length: float  # the lever arm of that normalisation

    def offset_from(self, T_reference: np.ndarray) -> tuple[float, float]:
        """(metres, radians) from ``T_reference`` along the constrained directions only."""
        return disagreement(T_reference, keep_prediction_along(self.free_directions, self.length, T_reference,
                                                               self.T_odom_sensor))

    @property
    def degenerate(self) -> bool:
        return bool(self.notes)

    def published_covariance(self, inflation: float) -> np.ndarray:
        """The covariance as published: inflated when the step failed."""
        return self.covariance * inflation if self.failures else self.covariance


class ScanAligner:
    """Stateful scan pipeline; see the module docstring for the recipe."""

    def __init__(self, config: Optional[AlignerConfig] = None, registrar: Optional[Registrar] = None) -> None:
        self.config = config or AlignerConfig()
        reg_prior = "network" if self.config.tracking.prior == "network" else "identity"
        self._registrar = registrar or Registrar(dataclasses.replace(self.config.registration, prior=reg_prior))
        self._fixed_scale = self.config.preprocess.scale if self.config.preprocess.scale > 0 else None
        self._pair_targets: dict[int, tuple[np.ndarray, VoxelMap]] = {}
        self._checks = InputChecks(self.config.checks)
        # Pair mode's targets (a latched map keeps its old stamp): their own levels and frame, no stamp order.
        self._target_checks = InputChecks(dataclasses.replace(self.config.checks, stamp_jump=0.0))
        preprocess.compile_kernels()  # the first scan must not pay the kernels' compilation
        refine.compile_kernels()
        self.reset()

    @property
    def scale(self) -> Optional[float]:
        """Metres per network unit (None until the first scan fixed it in auto mode)."""
        return self._scale

    @property
    def voxel(self) -> float:
        """Frame voxel size (m); 0 = no voxel grid, or nothing preprocessed yet."""
        return self._voxel

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
        self._scale = self._fixed_scale
        self._voxel = 0.0
        self._map: Optional[VoxelMap] = None
        self._motion = ConstantVelocity()
        self._spread = AdaptiveSpread(self.config.adaptive)
        self._health = HealthMonitor(self.config.health)
        self._pose = np.eye(4) if T_odom_sensor is None else np.asarray(T_odom_sensor, dtype=np.float64).copy()
        self._last_stamp: Optional[int] = None
        self._period_ns: Optional[int] = None
        self._pending_recovery = ""  # why the next scan runs the global search ("" = it tracks)
        self._failures_in_a_row = 0
        self._pair_targets.clear()
        self._sweep_offset_ns: Optional[int] = None  # deskewing: the reference time's offset from the stamps
        self._published: Optional[np.ndarray] = None  # the last pose published (at its stamp)
        self._odom_fix: Optional[np.ndarray] = None  # deskewing: T_odom_reference0 (odom: the first scan's stamp)
        self._skewed_input: Optional[tuple[np.ndarray, np.ndarray]] = None  # this scan, timed but not deskewed
        self._inserted: Optional[list] = None  # the map's scans while none could be deskewed (None: not tracked)
        self._last_dt_ns = 0  # the motion model's last time step
        self._T_odom_last_insert: Optional[np.ndarray] = None  # where the map last grew (a recovery's fallback)
        self._checks.forget_frame()
        self._target_checks.forget_frame()

    def request_recovery(self) -> None:
        """Run the global search on the next scan (e.g. the robot was carried: a ``~/relocalize`` service)."""
        self._pending_recovery = "requested"

    # -- sequential mode ------------------------------------------------------------------------------------
    def process(self, points: np.ndarray, stamp_ns: int, point_times: Optional[np.ndarray] = None,
                frame_id: str = "", now_ns: Optional[int] = None, n_total: Optional[int] = None) -> AlignmentStep:
        """Register this scan against the local map and accumulate the pose.

        The scan first passes the input checks (:mod:`.input_checks`; ``now_ns``: the caller's clock for the
        future-stamp check; ``n_total``: the message's points when ``points`` are its finite ones); a rejected
        one raises ScanRejected and changes nothing. ``point_times``: each
        point's time (s, relative to ``stamp_ns``, aligned with ``points``); with ``config.preprocess.deskew``
        the scan is first deskewed (see :meth:`_deskewed`). The pose is the one at ``stamp_ns`` in any case.
        """
        start, stamp_ns = time.perf_counter(), int(stamp_ns)
        admitted = self._checks.admit(points, point_times, stamp_ns, frame_id, now_ns, n_total)
        if admitted.restart:
            self.reset(self._pose)
        points, offset_ns = self._deskewed(admitted.points, admitted.times, stamp_ns)
        before = self._last_stamp
        step = self._process_at(points, stamp_ns + offset_ns, start)
        self._checks.passed(admitted)
        if before is not None and self._last_stamp != before:
            self._last_dt_ns = self._last_stamp - before  # the motion model's last time step
        step.warnings = admitted.warnings
        return self._at_stamp(step, stamp_ns, offset_ns)

    def _process_at(self, points: np.ndarray, stamp_ns: int, start: float) -> AlignmentStep:
        """The sequential step with the scan taken at ``stamp_ns`` (its reference time, see :meth:`_deskewed`)."""
        frame = self._preprocess(points)
        if self._last_stamp is not None and stamp_ns == self._last_stamp:
            return self._held(stamp_ns, start, frame, "duplicate stamp: scan skipped")
        if self._map is None or stamp_ns < self._last_stamp:
            return self._start_trajectory(frame, stamp_ns, start)
        dt_ns = stamp_ns - self._last_stamp
        T_predicted = self._pose @ self._motion.predict_relative(stamp_ns)
        why = self._recovery_reason(dt_ns)
        estimate = None if why else self._track(frame, self._map, T_predicted, self._dt_ratio(dt_ns))
        if estimate is not None and estimate.failures:
            why = "tracking failed (" + "; ".join(estimate.failures) + ")"
        if why:
            estimate = self._recover(frame, self._map, T_predicted)
        return self._commit(frame, stamp_ns, dt_ns, T_predicted, estimate, why, start)

    def _start_trajectory(self, frame: Frame, stamp_ns: int, start: float) -> AlignmentStep:
        """The first scan (or one whose stamp went back): the map restarts from it, the pose is kept."""
        restarted = self._last_stamp is not None
        reason = (f"stamp went back {(self._last_stamp - stamp_ns) * 1e-9:.3f} s: restarted from this scan, "
                  "pose kept") if restarted else ""
        self._adopt(frame)
        self._restart_map(frame, self._pose)
        self._motion.reset()
        self._motion.update(self._pose, stamp_ns)
        self._spread.reset()
        self._last_stamp, self._period_ns = stamp_ns, None
        self._pending_recovery = "first pair"  # a single pose predicts nothing
        return AlignmentStep(stamp_ns, self._pose.copy(), None, flat_covariance(0.0, 0.0), 1.0, not restarted,
                             time.perf_counter() - start, len(frame.sampled), reason)

    def _restart_map(self, frame: Frame, T_odom_sensor: np.ndarray) -> None:
        """Lost: a new map from this scan at ``T_odom_sensor``; the odometry stays continuous (flagged)."""
        self._map = self._new_map()
        self._map.update(apply_transform(T_odom_sensor, frame.dense), T_odom_sensor[:3, 3])
        self._T_odom_last_insert = T_odom_sensor.copy()
        self._inserted = []
        self._note_inserted(T_odom_sensor)
        self._health.reset()
        self._pending_recovery = ""
        self._failures_in_a_row = 0

    def _recovery_reason(self, dt_ns: int) -> str:
        if self._pending_recovery:
            return self._pending_recovery
        if dt_ns * 1e-9 > self.config.recovery.gap:
            return f"stamp gap {dt_ns * 1e-9:.3f} s"
        return ""

    def _dt_ratio(self, dt_ns: int) -> float:
        return 1.0 if not self._period_ns else dt_ns / self._period_ns

    def _commit(self, frame: Frame, stamp_ns: int, dt_ns: int, T_predicted: np.ndarray, estimate: Estimate,
                why_recovered: str, start: float) -> AlignmentStep:
        """Apply a verdict: good and degenerate steps move the state, failed ones publish the prediction."""
        self._pending_recovery = ""
        previous = self._pose
        reasons = list(estimate.failures)
        if estimate.failures:
            pose = T_predicted
            self._failures_in_a_row += 1
            self._pending_recovery = "the previous step failed"
            reasons.append("motion prediction used")
            if self._failures_in_a_row >= self.config.recovery.restart_after:
                reasons.append(f"lost for {self._failures_in_a_row} scans: the map restarts from this scan")
                self._restart_map(self._rescaled_if_lost(frame), pose)
        else:
            self._failures_in_a_row = 0
            pose = estimate.T_odom_sensor
            reasons += estimate.notes
            if not estimate.recovered:  # a recovery's guess was no prediction of the motion model
                self._spread.update(np.linalg.inv(T_predicted) @ pose)
            self._health.accept(estimate.signals.fitness)
            self._map.update(apply_transform(pose, frame.dense), pose[:3, 3])
            self._T_odom_last_insert = pose.copy()
            self._note_inserted(pose)
        self._pose = pose
        self._motion.update(pose, stamp_ns)
        self._last_stamp = stamp_ns
        self._period_ns = dt_ns if self._period_ns is None else int(0.9 * self._period_ns + 0.1 * dt_ns)
        accepted = not estimate.failures and not estimate.degenerate
        covariance = estimate.published_covariance(self.config.health.covariance_inflation)
        return AlignmentStep(stamp_ns, pose.copy(), np.linalg.inv(previous) @ pose, covariance,
                             estimate.signals.fitness, accepted, time.perf_counter() - start, len(frame.sampled),
                             "; ".join(reasons) if not accepted else "", estimate.recovered, why_recovered,
                             estimate.degenerate, estimate.signals.as_dict())

    # -- pair mode ------------------------------------------------------------------------------------------
    def align_pair(self, source: np.ndarray, target: np.ndarray, stamp_ns: int, *, source_frame: str = "",
                   target_frame: str = "", target_stamp_ns: Optional[int] = None, now_ns: Optional[int] = None,
                   n_total: Optional[int] = None) -> AlignmentStep:
        """Pair mode: the pose of ``source`` in the frame of ``target`` (a reused target is prepared once).

        Both clouds pass the input checks first, each against the levels of its own stream (a target's kinds
        are prefixed ``target_``; its stamp is checked against the clock only); ScanRejected changes nothing.
        """
        start, stamp_ns = time.perf_counter(), int(stamp_ns)
        admitted = self._checks.admit(source, None, stamp_ns, source_frame, now_ns, n_total)
        target_map, target_warnings = self._pair_target(target, target_frame,
                                                        stamp_ns if target_stamp_ns is None else target_stamp_ns,
                                                        now_ns)
        frame = self._preprocess(admitted.points)
        if self._last_stamp is not None and stamp_ns < self._last_stamp:
            self._motion.reset()
        why = "no pose yet" if self._motion.last_pose is None else ""
        if why:
            estimate = self._recover(frame, target_map, np.eye(4))
        else:
            estimate = self._track(frame, target_map, self._motion.predict(stamp_ns), 1.0)
            if estimate.failures:
                why = "tracking failed (" + "; ".join(estimate.failures) + ")"
                estimate = self._recover(frame, target_map, self._motion.predict(stamp_ns))
        accepted = not estimate.failures and not estimate.degenerate
        pose = estimate.T_odom_sensor
        previous = self._motion.last_pose
        if not estimate.failures:
            self._motion.update(pose, stamp_ns)
        self._last_stamp = stamp_ns
        relative = None if previous is None else np.linalg.inv(previous) @ pose
        reason = "; ".join(estimate.failures + estimate.notes)
        covariance = estimate.published_covariance(self.config.health.covariance_inflation)
        self._checks.passed(admitted)
        step = AlignmentStep(stamp_ns, pose.copy(), relative, covariance, estimate.signals.fitness,
                             accepted, time.perf_counter() - start, len(frame.sampled), reason, estimate.recovered,
                             why, estimate.degenerate, estimate.signals.as_dict())
        step.warnings = admitted.warnings + target_warnings
        return step

    def _pair_target(self, target: np.ndarray, frame_id: str, stamp_ns: int, now_ns: Optional[int]
                     ) -> tuple[VoxelMap, list]:
        """The target's map (and its input checks' warnings), built once per target array (a latched map is
        prepared once)."""
        cached = self._pair_targets.get(id(target))
        if cached is not None and cached[0] is target:
            return cached[1], []
        try:
            admitted = self._target_checks.admit(target, None, stamp_ns, frame_id, now_ns)
        except ScanRejected as exc:
            raise ScanRejected(f"target cloud: {exc}", f"target_{exc.kind}") from None
        self._target_checks.passed(admitted)
        frame = self._preprocess(admitted.points)
        self._adopt(frame)
        target_map = self._new_map()
        target_map.update(frame.dense, np.zeros(3))
        self._pair_targets.clear()
        self._pair_targets[id(target)] = (target, target_map)
        return target_map, admitted.warnings

    # -- the steps ------------------------------------------------------------------------------------------
    def _deskewed(self, points: np.ndarray, point_times: Optional[np.ndarray], stamp_ns: int
                  ) -> tuple[np.ndarray, int]:
        """(points, offset ns): the scan in the sensor frame at its reference time ``stamp_ns + offset``.

        With per-point times and ``preprocess.deskew`` the reference is the sweep's middle (fixed, from the first
        timed scan: a driver's stamping policy does not change) and the points are moved there at the motion
        model's velocity. Not the stamp: a registration pins the pose at the points' mean time, the pose
        elsewhere rests on the velocity; were the reference the sweep's start (Ouster's stamp), a velocity error
        would bias the pose, the next velocity would carry the opposite error and so on, undamped. At the
        middle the pose does not depend on the velocity used. :meth:`_at_stamp` publishes the pose at the stamp.
        The first scans of a trajectory have no velocity: once one is known, the map is rebuilt from them
        deskewed (the map keeps the first points of a voxel for good: skewed ones would bias every later step).
        """
        self._skewed_input = None
        if not self.config.preprocess.deskew or (point_times is None and self._sweep_offset_ns is None):
            return points, 0
        if self._sweep_offset_ns is None:
            times = np.asarray(point_times, dtype=np.float64)
            self._sweep_offset_ns = int(round(0.5 * (times.min() + times.max()) * 1e9)) if times.size else 0
        offset_ns = self._sweep_offset_ns
        if point_times is None:
            return points, offset_ns
        times = np.asarray(point_times, dtype=np.float64) - offset_ns * 1e-9
        twist = self._velocity()
        if twist is None or stamp_ns + offset_ns <= self._last_stamp:  # no velocity yet, a duplicate or a restart
            self._skewed_input = (np.asarray(points), times)
            return points, offset_ns
        if self._inserted:
            self._redeskew_map(twist)
        self._inserted = None
        return deskew(points, times, None, 0.0, twist=twist), offset_ns

    def _note_inserted(self, pose: np.ndarray) -> None:
        """Remember a scan that went into the map undeskewed (and where), for :meth:`_redeskew_map`.

        A scan without times (or deskewed already) ends the tracking: the map cannot be rebuilt without it.
        """
        if self._inserted is not None:
            if self._skewed_input is None:
                self._inserted = None
            else:
                self._inserted.append((*self._skewed_input, pose.copy()))

    def _redeskew_map(self, twist: np.ndarray) -> None:
        """The map rebuilt from its scans (all of them went in undeskewed) deskewed at the first velocity known."""
        rebuilt = self._new_map()
        for points, times, pose in self._inserted:
            try:
                dense = self._preprocess(deskew(points, times, None, 0.0, twist=twist)).dense
            except ScanRejected:
                return  # keep the map as it is
            rebuilt.update(apply_transform(pose, dense), pose[:3, 3])
        self._map = rebuilt

    def _velocity(self) -> Optional[np.ndarray]:
        """The motion model's twist (6,) per second: its last motion over its last time step (None: none yet)."""
        if not self._motion.has_velocity or self._last_dt_ns <= 0 or self._last_stamp is None:
            return None
        last_motion = self._motion.predict_relative(self._last_stamp + self._last_dt_ns)  # ratio 1: as recorded
        return se3_log(last_motion) / (self._last_dt_ns * 1e-9)

    def _at_stamp(self, step: AlignmentStep, stamp_ns: int, offset_ns: int) -> AlignmentStep:
        """The step as published: the pose at ``stamp_ns`` (the reference time is ``offset_ns`` later).

        The internal poses are the reference times'; odom stays the sensor frame at the first scan's stamp,
        placed by the first velocity known (none is known at the first scan itself).
        """
        if offset_ns:
            twist = self._velocity()
            to_stamp = np.eye(4) if twist is None else se3_exp(twist * (-offset_ns * 1e-9))
            if self._odom_fix is None and self._motion.has_velocity:
                self._odom_fix = np.linalg.inv(to_stamp)
            step.pose = (self._odom_fix if self._odom_fix is not None else np.eye(4)) @ step.pose @ to_stamp
            if step.relative is not None and self._published is not None:
                step.relative = np.linalg.inv(self._published) @ step.pose
            step.stamp_ns = stamp_ns
        self._published = step.pose
        return step

    def _preprocess(self, points: np.ndarray, scale: Optional[float] = None) -> Frame:
        """Metres, cropped and voxelised at ``scale`` (default: the aligner's; auto: this scan's robust radius).

        Raises ScanRejected. The aligner adopts a frame's scale only once the scan is used (:meth:`_adopt`): a
        rejected or implausible scan must not fix the units of the trajectory.
        """
        cfg = self.config.preprocess
        cropped = crop_range(finite_points(points), cfg.min_range, cfg.max_range)
        if len(cropped) < cfg.min_points:
            raise ScanRejected(f"too few points: {len(cropped)} after range crop, need {cfg.min_points}",
                               "too_few_points")
        scale = self._scale if scale is None else scale
        if scale is None:
            scale = robust_radius(cropped)
            if not scale > 0:
                raise ScanRejected("degenerate cloud: all points coincide, cannot measure its scale", "degenerate")
        voxel = max(cfg.voxel_size if cfg.voxel_size != 0 else scale / 100.0, 0.0)
        dense = voxel_downsample(cropped, voxel)
        if len(dense) < cfg.min_points:
            raise ScanRejected(f"too few points: {len(dense)} after preprocessing, need {cfg.min_points}",
                               "too_few_points")
        seed = max(self.config.registration.seed, 0)
        near = dense[np.einsum("ij,ij->i", dense, dense) <= (cfg.cem_radius * scale) ** 2]
        near = near if len(near) >= cfg.min_points else dense
        return Frame(dense, subsample(dense, self.config.polish.points, "random", seed),
                     subsample(near, self.config.registration.n_points, cfg.sampling, seed), near, scale, voxel)

    def _adopt(self, frame: Frame) -> None:
        """The frame's units become the aligner's (the first scan of a trajectory, a pair target)."""
        self._scale, self._voxel = frame.scale, frame.voxel

    def _rescaled_if_lost(self, frame: Frame) -> Frame:
        """Auto scale: a restart after being lost measures the scale again when this scan's differs by > 2x (the
        trajectory may have started from a scan that was not representative)."""
        if self._fixed_scale is not None or self._scale is None:
            return frame
        radius = robust_radius(frame.dense)
        if not 0.5 * self._scale <= radius <= 2.0 * self._scale:
            try:
                frame = self._preprocess(frame.dense, scale=radius)
            except ScanRejected:
                return frame
            self._adopt(frame)
        return frame

    def _new_map(self) -> VoxelMap:
        voxel = self._voxel if self._voxel > 0 else self._scale / 100.0
        max_distance = self.config.preprocess.max_range if self.config.preprocess.max_range > 0 else 10.0 * self._scale
        return VoxelMap(voxel * self.config.map.voxel_factor, self.config.map.points_per_voxel, max_distance)

    def _units(self, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(to_units, from_units) 4x4 maps between metres and network units centred on ``centre``."""
        to_units = np.eye(4)
        to_units[:3, :3] /= self._scale
        to_units[:3, 3] = -centre / self._scale
        return to_units, np.linalg.inv(to_units)

    def _map_sample(self, target_map: VoxelMap, T_guess: np.ndarray, n: int, margin: float = 0.0) -> np.ndarray:
        """``n`` map points within the CEM's radius (+ ``margin`` m) of the guessed sensor position."""
        radius = self.config.preprocess.cem_radius * self._scale + margin
        return target_map.sample(n, T_guess[:3, 3], radius, seed=max(self.config.registration.seed, 0))

    def _track(self, frame: Frame, target_map: VoxelMap, T_predicted: np.ndarray, dt_ratio: float) -> Estimate:
        """The CEM around the prediction (adaptive spread) against a map sample, then the polish.

        When the two disagree the CEM gets a second opinion around the polish's answer: a prediction that was
        far off (a stop, a swing) leaves the first search looking in the wrong place, a polish that slid away
        finds no consensus there.
        """
        cfg = self.config
        target = self._map_sample(target_map, T_predicted, cfg.registration.n_points)
        if len(target) < cfg.preprocess.min_points:
            return self._off_map(T_predicted, "prediction", 0.0)
        to_units, from_units = self._units(target.mean(axis=0))
        clouds = apply_transform(to_units, frame.sampled), apply_transform(to_units, target)
        rotation, translation = self._spread.spread(dt_ratio)
        sigma = (np.full(6, cfg.tracking.identity_sigma) if cfg.tracking.prior == "identity"
                 else np.r_[np.full(3, rotation), np.full(3, translation / self._scale)])
        centre = {"motion": T_predicted, "identity": self._motion.last_pose, "network": None}[cfg.tracking.prior]
        T_cem, spread_m = self._cem(clouds, to_units, from_units, centre, sigma)
        voxel = self._polish_voxel()
        max_distance = float(np.clip(translation, 2.0 * voxel, TRACKING_PAIRING * voxel))
        polish = point_to_plane_icp(target_map, frame.polish, T_cem, max_distance, cfg.polish.iters)
        metres, radians = disagreement(T_predicted, polish.T_target_source)
        if metres > 3.0 * translation or radians > 3.0 * rotation:  # the motion model was wrong: look wider
            polish = self._wide_polish(frame, target_map, polish.T_target_source)
        metres, radians = disagreement(T_cem, polish.T_target_source)
        if self._health.disagree(metres, radians, self._resolution()):
            T_cem, spread_m = self._cem(clouds, to_units, from_units, polish.T_target_source, sigma)
        return self._judge(frame, target_map, T_predicted, T_cem, polish, spread_m, recovered=False,
                           prediction_std=translation)

    def _cem(self, clouds: tuple[np.ndarray, np.ndarray], to_units: np.ndarray, from_units: np.ndarray,
             T_centre: Optional[np.ndarray], sigma: np.ndarray) -> tuple[np.ndarray, float]:
        """The CEM in units around ``T_centre`` (None: the network's prior); (T_odom_sensor, final spread m)."""
        if T_centre is None:
            result = self._registrar.register(*clouds)
        else:
            result = self._registrar.register(*clouds, prior_pose=to_units @ T_centre @ from_units, prior_sigma=sigma)
        T_cem = from_units @ np.asarray(result.transform, dtype=np.float64) @ to_units
        T_cem[3] = (0.0, 0.0, 0.0, 1.0)
        return T_cem, float(np.max(np.abs(result.sigma[3:]))) * self._scale

    def _recover(self, frame: Frame, target_map: VoxelMap, T_guess: np.ndarray) -> Estimate:
        """The global CEM search around ``T_guess``, each distinct hypothesis polished; the best one judged.

        The scan is placed at the guess and the engine's units are centred on the guessed sensor position, so
        that the search's yaw turns about the sensor and its translation disc is the sensor's displacement.
        """
        cfg, rec = self.config, self.config.recovery
        target = self._map_sample(target_map, T_guess, rec.points, margin=rec.radius)
        if len(target) < cfg.preprocess.min_points and target_map is self._map \
                and self._T_odom_last_insert is not None:
            T_guess = self._T_odom_last_insert  # the guess left the map (a wild prediction): search where it grew
            target = self._map_sample(target_map, T_guess, rec.points, margin=rec.radius)
        if len(target) < cfg.preprocess.min_points:
            return self._off_map(T_guess, "guess", rec.radius)
        to_units, from_units = self._units(T_guess[:3, 3])
        # The map holds at most a few points per map voxel: the scan, thinned alike, is sampled at the same density.
        uniform = voxel_downsample(frame.near, target_map.voxel_size)
        source = apply_transform(T_guess, subsample(uniform, rec.points, "random", max(cfg.registration.seed, 0)))
        hypotheses = global_search(apply_transform(to_units, source), apply_transform(to_units, target), np.zeros(6),
                                   rec.radius / self._scale, rec.search, seed=max(cfg.registration.seed, 0))
        estimates = []
        for hypothesis in hypotheses:
            if hypothesis.fitness < POLISH_FRACTION * hypotheses[0].fitness:
                break  # far behind the best: not worth a polish, nor a rival
            T_cem = from_units @ hypothesis.T_target_source @ to_units @ T_guess
            T_cem[3] = (0.0, 0.0, 0.0, 1.0)
            polish = self._wide_polish(frame, target_map, T_cem)
            estimates.append(self._judge(frame, target_map, T_guess, T_cem, polish, 0.0, recovered=True,
                                         prediction_std=rec.radius))
        estimates.sort(key=lambda e: -e.signals.fitness)
        return self._resolve_ambiguity(estimates, T_guess)

    def _resolve_ambiguity(self, estimates: list[Estimate], T_guess: np.ndarray) -> Estimate:
        """The fittest hypothesis, or among distinct near-ties the one next to the guess (a symmetric scene).

        A tie resolved by a guess within the tracking spread is flagged with a note; ties all far from the
        guess are a failure ("ambiguous").
        """
        best = estimates[0]
        ties = [best]
        for estimate in estimates[1:]:
            if estimate.signals.fitness >= self.config.recovery.ambiguity_ratio * best.signals.fitness and all(
                    _far(estimate.T_odom_sensor, kept.T_odom_sensor) for kept in ties):
                ties.append(estimate)
        if len(ties) == 1:
            return best
        rotation, translation = self._spread.spread()
        nearest = min(ties, key=lambda e: e.offset_from(T_guess)[0])
        metres, radians = nearest.offset_from(T_guess)
        summary = (f"{len(ties)} distinct hypotheses within {self.config.recovery.ambiguity_ratio:.2f} of the best "
                   "fitness")
        if metres <= 3.0 * translation and radians <= 3.0 * rotation:
            nearest.notes.append(f"symmetric scene: {summary}, the one next to the motion prediction kept")
            return nearest
        best.failures.append(f"ambiguous: {summary}, none next to the motion prediction")
        return best

    def _wide_polish(self, frame: Frame, target_map: VoxelMap, T_start: np.ndarray) -> PolishResult:
        """A polish from an answer that may be a metre or degrees off: wide pairing first, then the fine one."""
        rec, voxel = self.config.recovery, self._polish_voxel()
        coarse = point_to_plane_icp(target_map, frame.polish, T_start, rec.polish_distance * voxel, rec.polish_iters)
        return point_to_plane_icp(target_map, frame.polish, coarse.T_target_source, 2.0 * voxel,
                                  self.config.polish.iters)

    def _resolution(self) -> float:
        """Metres the CEM's max-consensus reward can tell apart: epsilon * scale."""
        return self.config.registration.cem.epsilon * self._scale

    def _polish_voxel(self) -> float:
        return self._voxel if self._voxel > 0 else self._scale / 100.0

    def _inlier_distance(self) -> float:
        return self.config.polish.inlier_distance * self._polish_voxel()

    def _judge(self, frame: Frame, target_map: VoxelMap, T_predicted: np.ndarray, T_cem: np.ndarray,
               polish: PolishResult, spread_m: float, recovered: bool, prediction_std: float) -> Estimate:
        """Signals of one registration, its failures, degeneracy and covariance."""
        cfg = self.config.health
        T_final = polish.T_target_source
        conditioning = Conditioning.of(polish.hessian, frame.length)
        fitness = target_map.inlier_fraction(frame.polish, T_final, self._inlier_distance())
        metres, radians = disagreement(T_cem, T_final)
        signals = Signals(fitness, metres, radians, conditioning.ratio, spread_m)
        failures = self._health.failures(signals, self._resolution(), recovery=recovered)
        if polish.n_pairs < 10:
            failures.append(f"only {polish.n_pairs} point-to-plane pairs")
        notes = []
        if self._health.degenerate(signals):
            notes.append(f"degenerate (conditioning {conditioning.ratio:.4f}): the motion prediction kept along "
                         "the unconstrained direction")
            # The replacement is linear in the difference: a guess degrees away (a recovery's) would be meaningless.
            if not failures and disagreement(T_predicted, T_final)[1] < LINEAR_LIMIT:
                T_final = keep_prediction_along(conditioning.degenerate_basis(cfg.min_conditioning),
                                                conditioning.length, T_predicted, T_final)
        covariance = covariance_from_hessian(conditioning, polish.residual_variance, prediction_std ** 2,
                                             cfg.min_conditioning)
        return Estimate(T_final, covariance, signals, failures, notes, recovered,
                        conditioning.degenerate_basis(cfg.min_conditioning), conditioning.length)

    def _off_map(self, T_guess: np.ndarray, what: str, margin: float) -> Estimate:
        """A failure: the map has too few points within the CEM's radius (+ ``margin`` m) of the ``what`` to
        register against (the step publishes the prediction, flagged; failures in a row restart the map)."""
        radius = self.config.preprocess.cem_radius * self._scale + margin
        return Estimate(T_guess.copy(), flat_covariance(radius, np.pi), Signals(0.0, 0.0, 0.0, 0.0, 0.0),
                        [f"no map points within {radius:.1f} m of the {what}"], [], False, np.zeros((6, 0)), 1.0)

    def _held(self, stamp_ns: int, start: float, frame: Frame, reason: str) -> AlignmentStep:
        return AlignmentStep(stamp_ns, self._pose.copy(), None, flat_covariance(0.0, 0.0), 0.0, False,
                             time.perf_counter() - start, len(frame.sampled), reason)


def _far(T_a: np.ndarray, T_b: np.ndarray) -> bool:
    """Two answers that are distinct hypotheses, not one basin: more than 1 m or 5 deg apart."""
    metres, radians = disagreement(T_a, T_b)
    return metres > 1.0 or radians > np.radians(5.0)
