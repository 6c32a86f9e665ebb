"""The methods under test, each a fresh odometry per pair / sequence: ``process(points, stamp_ns) -> Output``.

``ScanAligner`` with default parameters (or overrides of them); KISS-ICP and GenZ-ICP with their default configs
(max_range of the sensor; KISS-ICP's voxel = max_range / 100); small_gicp GICP scan-to-scan from the identity. The
peers have no failure flag: all their steps count as accepted.
"""
from __future__ import annotations

import functools
import importlib
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Optional

import numpy as np

from cemnet_ros.io.console import log
from cemnet_ros.pipeline.steps.scan_budget import budget_seconds

METHODS = ("cemnet", "kiss-icp", "genz-icp", "gicp")


@dataclass
class Output:
    """One scan's result: pose T_odom_sensor (odom = first scan), flag, reason, covariance (None: not given)."""

    pose: np.ndarray
    accepted: bool = True
    reason: str = ""
    covariance: Optional[np.ndarray] = None
    recovered: bool = False  # the step ran a global search (the peers have none)
    answer: Optional[np.ndarray] = None  # the registered answer judged, flagged or not (None: the pose)
    restarted: bool = False  # the map restarted at this scan (lost)


class CemnetOdometry:
    """The pipeline under test, through its public interface only: the node's defaults, or those with the dotted
    parameter ``overrides`` (e.g. ``{"recovery.search.n_scatter": 125}``); ``scan_budget`` (periods, 0: none, as
    offline) bounds each scan as a live node's ``scan_budget`` does, every scan still processed."""

    def __init__(self, max_range: float, overrides: Optional[Mapping[str, Any]] = None,
                 scan_budget: float = 0.0) -> None:
        from cemnet_ros.pipeline.aligner import AlignerConfig, ScanAligner
        from cemnet_ros.schema import build

        self._aligner = ScanAligner(build(AlignerConfig(), overrides or {}))
        self._scan_budget = scan_budget

    def process(self, points: np.ndarray, stamp_ns: int) -> Output:
        step = self._aligner.process(points, stamp_ns,
                                     budget_s=budget_seconds(self._scan_budget, self._aligner.period_s))
        return Output(np.asarray(step.pose), bool(step.accepted), str(step.reason), np.asarray(step.covariance),
                      bool(step.recovered), step.answer, bool(step.map_restarted))

    def pair(self, source: np.ndarray, target: np.ndarray) -> Output:
        """``source`` registered onto ``target`` from no history: pair mode, as ``align_clouds`` runs it."""
        step = self._aligner.align_pair(source, target, 0)
        return Output(np.asarray(step.pose), bool(step.accepted), str(step.reason), np.asarray(step.covariance),
                      bool(step.recovered))


class KissOdometry:
    """KISS-ICP with its default config; ``max_range`` set for the sensor (voxel = max_range / 100)."""

    def __init__(self, max_range: float) -> None:
        from kiss_icp.config import KISSConfig
        from kiss_icp.kiss_icp import KissICP

        config = KISSConfig()
        config.data.max_range = max_range
        config.mapping.voxel_size = max_range / 100.0
        self._kiss = KissICP(config)

    def process(self, points: np.ndarray, stamp_ns: int) -> Output:
        self._kiss.register_frame(points, np.empty(0))  # no per-point timestamps: no deskewing
        return Output(self._kiss.last_pose.copy())


class GenzOdometry:
    """GenZ-ICP with its default config; ``max_range`` set for the sensor."""

    def __init__(self, max_range: float) -> None:
        from genz_icp.config import GenZConfig
        from genz_icp.genz_icp import GenZICP

        config = GenZConfig()
        config.data.max_range = max_range
        self._genz = GenZICP(config)

    def process(self, points: np.ndarray, stamp_ns: int) -> Output:
        self._genz.register_frame(points, np.empty(0))  # no per-point timestamps: no deskewing
        return Output(self._genz.last_pose.copy())


class GicpOdometry:
    """small_gicp GICP scan-to-scan from the identity (0.25 m voxels, 1 m correspondences, 2 threads)."""

    voxel, max_distance, threads = 0.25, 1.0, 2

    def __init__(self, max_range: float) -> None:
        import small_gicp

        self._gicp = small_gicp
        self._pose = np.eye(4)
        self._previous = None

    def process(self, points: np.ndarray, stamp_ns: int) -> Output:
        cloud, tree = self._gicp.preprocess_points(points, self.voxel, num_threads=self.threads)
        if self._previous is not None:
            target, target_tree = self._previous
            result = self._gicp.align(target, cloud, target_tree, registration_type="GICP",
                                      max_correspondence_distance=self.max_distance, num_threads=self.threads)
            self._pose = self._pose @ np.asarray(result.T_target_source)
        self._previous = (cloud, tree)
        return Output(self._pose.copy())


FACTORIES: dict[str, Callable] = {"cemnet": CemnetOdometry, "kiss-icp": KissOdometry, "genz-icp": GenzOdometry,
                                  "gicp": GicpOdometry}
PEER_MODULES = {"kiss-icp": "kiss_icp.kiss_icp", "genz-icp": "genz_icp.genz_icp", "gicp": "small_gicp"}


def available_methods(wanted: list[str], overrides: Optional[Mapping[str, Any]] = None, scan_budget: float = 0.0
                      ) -> dict[str, Callable]:
    """The wanted methods, less the peers that do not import (reported on stderr); the pipeline under test with
    the parameter ``overrides`` and a live node's ``scan_budget`` (0: none).

    The pipeline under test is always kept: if it cannot even be built, every step counts as failed.
    """
    out = {}
    for name in wanted:
        if name in PEER_MODULES:
            try:
                importlib.import_module(PEER_MODULES[name])
            except ImportError as exc:
                log(f"{name}: not importable ({exc}); left out (pip install -e .[bench])")
                continue
        out[name] = functools.partial(CemnetOdometry, overrides=overrides, scan_budget=scan_budget) \
            if name == "cemnet" else FACTORIES[name]
    return out
