"""Each method's side of a piece: voxel grid calls, local maps (insert a scan, polish a step) and nearest-point
calls, all on the node's parameters and :data:`~.peers.THREADS` threads."""
from __future__ import annotations

from functools import partial
from types import ModuleType
from typing import Any, Callable, Optional

import numpy as np
from scipy.spatial import cKDTree

from benchmarks.libraries.inputs import Stage, Step
from benchmarks.libraries.peers import CONVERGENCE, NEIGHBOURS, OURS, THREADS
from benchmarks.libraries.timing import interleaved
from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.preprocess import voxel_downsample
from cemnet_ros.pipeline.steps.refine import point_to_plane_icp


def downsample_calls(points: np.ndarray, voxel: float, peers: dict[str, ModuleType]) -> dict[str, Callable]:
    """One voxel grid of ``points`` per method, as a numpy (n, 3) array. Ours and small_gicp keep each voxel's
    centroid, KISS-ICP one of its input points."""
    calls: dict[str, Callable] = {OURS: partial(voxel_downsample, points, voxel)}
    if "small_gicp" in peers:
        sg = peers["small_gicp"]
        calls["small_gicp"] = lambda: sg.voxelgrid_sampling(points, voxel, THREADS).points()[:, :3]
    if "kiss_icp" in peers:
        calls["kiss_icp"] = partial(peers["kiss_icp"].voxelization.voxel_down_sample, points, voxel)
    return calls


def staged(stages: list[Stage], initial: np.ndarray, align: Callable[[Stage, np.ndarray], Any]
           ) -> tuple[np.ndarray, int]:
    """(T_target_source, steps taken) of ``align(stage, T_target_source)`` run stage after stage from ``initial``;
    ``align`` returns a result with ``T_target_source`` and ``iterations`` (ours and small_gicp's alike)."""
    T_target_source, steps = initial, 0
    for stage in stages:
        result = align(stage, T_target_source)
        T_target_source, steps = result.T_target_source, steps + result.iterations
    return T_target_source, steps


class OursMap:
    """The node's local map (:class:`VoxelMap`: points with normals) and polish (:func:`point_to_plane_icp`)."""

    def __init__(self, map_voxel: float, points_per_voxel: int, max_range: float) -> None:
        self.map = VoxelMap(map_voxel, points_per_voxel, max_range)

    def insert(self, points_sensor: np.ndarray, T_target_sensor: np.ndarray) -> None:
        """As the node does each step: the scan moved into the map frame, then ``VoxelMap.update``."""
        self.map.update(apply_transform(T_target_sensor, points_sensor), T_target_sensor[:3, 3])

    def polish(self, step: Step, initial: np.ndarray, stages: list[Stage]) -> tuple[np.ndarray, Optional[int]]:
        """(T_target_source, Gauss-Newton steps taken) of the stages in turn."""
        return staged(stages, initial, lambda stage, T: point_to_plane_icp(
            self.map, stage.subset(step.polish), T, stage.max_distance, stage.iters, convergence=CONVERGENCE))


def covariance_cloud(sg: ModuleType, points: np.ndarray) -> Any:
    """A small_gicp cloud of ``points`` with the covariances of each point's k nearest (GICP's, VGICP's input)."""
    cloud = sg.PointCloud(points)
    sg.estimate_covariances(cloud, num_neighbors=NEIGHBOURS, num_threads=THREADS)
    return cloud


class SmallGicpCloudMap:
    """small_gicp against a point cloud: an ``IncrementalVoxelMap`` of the scans (same voxel; 10 points per voxel,
    its default) whose points get normals (PLANE_ICP) or covariances (GICP) of their k nearest and a ``KdTree``,
    rebuilt at each insertion: its Python ``align`` takes a cloud and a tree, not the incremental map.

    GICP needs the source's covariances too: it aligns the source's whole voxel cloud (covariances estimated in
    the polish, timed with it), not the polish subset.
    """

    def __init__(self, sg: ModuleType, map_voxel: float, registration_type: str) -> None:
        self.sg, self.registration_type = sg, registration_type
        self.voxels = sg.IncrementalVoxelMap(map_voxel)

    def insert(self, points_sensor: np.ndarray, T_target_sensor: np.ndarray) -> None:
        sg = self.sg
        self.voxels.insert(sg.PointCloud(points_sensor), T_target_sensor)
        self.cloud = sg.PointCloud(self.voxels.voxel_points()[:, :3])
        self.tree = sg.KdTree(self.cloud, THREADS)
        describe = sg.estimate_normals if self.registration_type == "PLANE_ICP" else sg.estimate_covariances
        describe(self.cloud, self.tree, NEIGHBOURS, THREADS)

    def polish(self, step: Step, initial: np.ndarray, stages: list[Stage]) -> tuple[np.ndarray, Optional[int]]:
        plane = self.registration_type == "PLANE_ICP"
        gicp_source = None if plane else covariance_cloud(self.sg, step.dense)
        return staged(stages, initial, lambda stage, T: self.sg.align(
            self.cloud, self.sg.PointCloud(stage.subset(step.polish)) if plane else gicp_source, self.tree, T,
            registration_type=self.registration_type, max_correspondence_distance=stage.max_distance,
            num_threads=THREADS, max_iterations=stage.iters, rotation_epsilon=CONVERGENCE,
            translation_epsilon=CONVERGENCE))


class SmallGicpVgicpMap:
    """small_gicp's VGICP: a ``GaussianVoxelMap`` (incremental) of scans whose covariances come from each scan's
    own k nearest; the source's whole voxel cloud with covariances (estimated in the polish, timed with it)."""

    def __init__(self, sg: ModuleType, map_voxel: float) -> None:
        self.sg = sg
        self.voxels = sg.GaussianVoxelMap(map_voxel)

    def insert(self, points_sensor: np.ndarray, T_target_sensor: np.ndarray) -> None:
        self.voxels.insert(covariance_cloud(self.sg, points_sensor), T_target_sensor)

    def polish(self, step: Step, initial: np.ndarray, stages: list[Stage]) -> tuple[np.ndarray, Optional[int]]:
        source = covariance_cloud(self.sg, step.dense)
        return staged(stages, initial, lambda stage, T: self.sg.align(
            self.voxels, source, T, max_correspondence_distance=stage.max_distance, num_threads=THREADS,
            max_iterations=stage.iters, rotation_epsilon=CONVERGENCE, translation_epsilon=CONVERGENCE))


class KissMap:
    """KISS-ICP's ``VoxelHashMap`` (points only: its ICP is point-to-point) and registration, with a
    Geman-McClure kernel of max_distance / 3 like ours; its Python binding does not return the iterations."""

    def __init__(self, kiss: ModuleType, map_voxel: float, points_per_voxel: int, max_range: float) -> None:
        self.kiss = kiss
        self.map = kiss.mapping.VoxelHashMap(map_voxel, max_range, points_per_voxel)

    def insert(self, points_sensor: np.ndarray, T_target_sensor: np.ndarray) -> None:
        self.map.update(points_sensor, T_target_sensor)  # moves the points itself, prunes around the pose

    def polish(self, step: Step, initial: np.ndarray, stages: list[Stage]) -> tuple[np.ndarray, Optional[int]]:
        T_target_source = initial
        for stage in stages:
            registration = self.kiss.registration.Registration(stage.iters, CONVERGENCE, THREADS)
            T_target_source = registration.align_points_to_map(stage.subset(step.polish), self.map, T_target_source,
                                                               stage.max_distance, stage.max_distance / 3.0)
        return np.asarray(T_target_source), None


def local_maps(peers: dict[str, ModuleType], config: AlignerConfig, voxel: float,
               max_range: float) -> dict[str, Any]:
    """An empty local map of every method (``insert`` a scan, ``polish`` a step), the node's map parameters."""
    map_voxel, per_voxel = voxel * config.map.voxel_factor, config.map.points_per_voxel
    maps: dict[str, Any] = {OURS: OursMap(map_voxel, per_voxel, max_range)}
    if "small_gicp" in peers:
        sg = peers["small_gicp"]
        maps["small_gicp plane"] = SmallGicpCloudMap(sg, map_voxel, "PLANE_ICP")
        maps["small_gicp gicp"] = SmallGicpCloudMap(sg, map_voxel, "GICP")
        maps["small_gicp vgicp"] = SmallGicpVgicpMap(sg, map_voxel)
    if "kiss_icp" in peers:
        maps["kiss_icp p2p"] = KissMap(peers["kiss_icp"], map_voxel, per_voxel, max_range)
    return maps


def filled_maps(step: Step, peers: dict[str, ModuleType], config: AlignerConfig, voxel: float,
                max_range: float) -> dict[str, Any]:
    """Every method's local map of ``step``'s map scans."""
    maps = local_maps(peers, config, voxel, max_range)
    for local_map in maps.values():
        for points, pose in zip(step.map_scans, step.T_target_map_scans):
            local_map.insert(points, pose)
    return maps


def nearest_calls(voxel_map: VoxelMap, query: np.ndarray, max_distance: float, peers: dict[str, ModuleType],
                  build_times: dict[str, list[float]]) -> dict[str, Callable[[], np.ndarray]]:
    """The nearest map point's distance (inf beyond ``max_distance``) of each query point, per method, on the same
    map points; the k-d trees are built here (their ms into ``build_times``), ours is the map itself. KISS-ICP's
    binding has no nearest-point query."""
    points = voxel_map.points
    trees = interleaved({"scipy": partial(cKDTree, points)}, 1, build_times)
    calls: dict[str, Callable[[], np.ndarray]] = {
        OURS: lambda: voxel_map.nearest(query, max_distance)[0],
        "scipy": lambda: trees["scipy"].query(query, k=1, distance_upper_bound=max_distance, workers=THREADS)[0]}
    if "small_gicp" in peers:
        sg = peers["small_gicp"]
        tree = interleaved({"small_gicp": partial(sg.KdTree, points, THREADS)}, 1, build_times)["small_gicp"]

        def small_gicp_nearest() -> np.ndarray:
            _, sq_dist = tree.batch_nearest_neighbor_search(query, THREADS)
            dist = np.sqrt(np.asarray(sq_dist))
            return np.where(dist <= max_distance, dist, np.inf)

        calls["small_gicp"] = small_gicp_nearest
    return calls


def agreement(ours: np.ndarray, other: np.ndarray) -> float:
    """Fraction of queries where two methods found the same nearest distance (or both none)."""
    return float(np.mean(np.isclose(ours, other, rtol=0.0, atol=1e-9)))  # inf == inf
