"""The node's aligner between its ROS callbacks, as plain code: loading, requests, the map lock, step outputs.

The aligner loads in a background thread (:meth:`AlignerSession.load`: torch, the weights and the kernels take
seconds) while scans queue; the worker waits for it (:meth:`~AlignerSession.begin_scan`). Requests from the
services (reset, relocalize, a pose set before the aligner exists) are carried out before the next scan; a pose
set later, and readers of the map (timers, services), take the map lock, so that they act between two scans.
Each step becomes the numbers the node publishes (:func:`~.odometry_output.odometry_output`), and its pose joins
the session's trajectory (:class:`~.trajectory_log.TrajectoryLog`, for ``~/save_trajectory`` and ``~/path``).
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Optional

import numpy as np

from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.steps.scan_budget import budget_seconds
from cemnet_ros.runtime.extrinsic import BaseFrame
from cemnet_ros.runtime.odometry_output import OdometryOutput, odometry_output
from cemnet_ros.runtime.trajectory_log import TrajectoryLog


@dataclass
class StepResult:
    """One registered scan and what it publishes."""

    step: Any  # the aligner's AlignmentStep
    out: OdometryOutput
    T_odom_sensor: np.ndarray  # where the scan's points go in odom (the aligned cloud)


def _scan_aligner(config: AlignerConfig) -> Any:
    from cemnet_ros.pipeline.aligner import ScanAligner  # torch and the kernels: loaded in the background

    return ScanAligner(config)


class AlignerSession:
    """A ScanAligner as the node drives it from several threads.

    ``output_config``: the node's covariance, effort and trajectory settings (a NodeConfig); ``make_aligner``:
    builds the aligner from ``config`` (default: a ScanAligner). :attr:`trajectory` keeps every published pose.
    """

    def __init__(self, config: AlignerConfig, output_config: Any, base: BaseFrame,
                 make_aligner: Callable[[AlignerConfig], Any] = _scan_aligner) -> None:
        self.config, self.base = config, base
        self.fatal_error: Optional[str] = None
        self._output_config, self._make_aligner = output_config, make_aligner
        self._aligner: Any = None
        self._loaded = threading.Event()  # set when loaded, when loading failed, or when the node closes
        self._map_lock = threading.Lock()  # held while a scan registers
        self._requests: dict[str, Any] = {}
        self._requests_lock = threading.Lock()
        self._last_stamp_ns: Optional[int] = None
        self.trajectory = TrajectoryLog(output_config.trajectory_max_poses)

    def load(self) -> Optional[float]:
        """Build the aligner; the seconds it took, or None when it failed (:attr:`fatal_error` says why)."""
        start = time.monotonic()
        try:
            self._aligner = self._make_aligner(self.config)
        except Exception as exc:  # noqa: BLE001 - e.g. a corrupt weights file: fatal for the node
            self.fatal_error = f"the engine did not load: {type(exc).__name__}: {str(exc).splitlines()[0]}"
            return None
        finally:
            self._loaded.set()
        return time.monotonic() - start

    def close(self) -> None:
        """A worker waiting for the aligner gives up."""
        self._loaded.set()

    @property
    def scale(self) -> Optional[float]:
        return None if self._aligner is None else self._aligner.scale

    # -- requests (service threads) -------------------------------------------------------------------------
    def request(self, name: str, value: Any = True) -> None:
        """"reset" (a new map, the pose kept), "relocalize" (a global search) or "set_pose" (T_odom_base): carried
        out before the next scan."""
        with self._requests_lock:
            self._requests[name] = value

    def set_pose(self, T_odom_base: np.ndarray) -> None:
        """A new map starting at this base pose: now (between two scans) once loaded, else before the first."""
        if self._aligner is None:
            self.request("set_pose", T_odom_base)
            return
        with self._map_lock:
            self._aligner.reset(self.base.sensor_pose(T_odom_base))

    # -- worker thread --------------------------------------------------------------------------------------
    def begin_scan(self) -> None:
        """Wait for the aligner (RuntimeError when it did not load), then carry out the requests."""
        self._loaded.wait()
        if self._aligner is None:
            raise RuntimeError(f"the engine did not load: {self.fatal_error}")
        with self._requests_lock:
            requests, self._requests = self._requests, {}
        if "reset" in requests:
            self._aligner.reset(self._aligner.pose)
        if "set_pose" in requests:
            self._aligner.reset(self.base.sensor_pose(requests["set_pose"]))
        if "relocalize" in requests:
            self._aligner.request_recovery()

    def process(self, scan: Any, frame_id: str, now_ns: Optional[int], backlog: Optional[int] = None,
                period_s: Optional[float] = None) -> StepResult:
        """Sequential mode: register a decoded scan (points, stamp_ns, times) against the map. ``backlog``: newer
        scans waiting in a live node's queue (while behind, a scan gets ``behind_effort`` of the budgets), and every
        live scan ``scan_budget`` x ``period_s`` of the worker's time (the usual time between arrivals; None: between
        the stamps); ``backlog`` None: offline, the whole plan at full effort."""
        effort = self._output_config.behind_effort if backlog is not None and backlog > 0 else 1.0
        with self._map_lock:
            budget_s = None if backlog is None else budget_seconds(
                self._output_config.scan_budget, period_s if period_s is not None else self._aligner.period_s)
            step = self._aligner.process(scan.points, scan.stamp_ns, scan.times, frame_id=frame_id, now_ns=now_ns,
                                         effort=effort, budget_s=budget_s)
        return self._result(step)

    def align_pair(self, source: Any, target: Any, source_frame: str, target_frame: str,
                   now_ns: Optional[int]) -> StepResult:
        """Pair mode: the pose of a decoded source scan in the frame of a decoded target."""
        step = self._aligner.align_pair(source.points, target.points, source.stamp_ns, source_frame=source_frame,
                                        target_frame=target_frame, target_stamp_ns=target.stamp_ns, now_ns=now_ns)
        return self._result(step)

    def _result(self, step: Any) -> StepResult:
        """The step's outputs; its twist over the time since the previous step."""
        dt_s = None if self._last_stamp_ns is None else (step.stamp_ns - self._last_stamp_ns) * 1e-9
        self._last_stamp_ns = step.stamp_ns
        out = odometry_output(step, self.base, dt_s, self._output_config, self.config.health.covariance_inflation)
        self.trajectory.append(step.stamp_ns, out.T_odom_base, step)
        return StepResult(step, out, out.T_odom_base @ self.base.T_base_sensor)

    # -- readers (timer and service threads) ----------------------------------------------------------------
    def map_in_odom(self) -> Optional[np.ndarray]:
        """The local map's points in odom (None: no map yet); the map is kept in the first sensor frame."""
        local_map = None if self._aligner is None else self._aligner.local_map
        if local_map is None or local_map.empty():
            return None
        with self._map_lock:
            points = local_map.points
        return apply_transform(self.base.T_base_sensor, points)
