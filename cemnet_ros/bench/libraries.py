"""The project's own classical point cloud code against the well-kept libraries, piece by piece (issue 21):
the voxel grid, the local map, nearest map points, the point-to-plane polish and the start-up.

Peers, the ``bench`` extras, each optional (a missing one is left out with a message): small_gicp
(``voxelgrid_sampling``, ``IncrementalVoxelMap`` / ``GaussianVoxelMap``, ``KdTree``, ``estimate_normals`` /
``estimate_covariances``, ``align``) and KISS-ICP (``voxel_down_sample``, ``VoxelHashMap``, its point-to-point
registration); scipy's ``cKDTree`` (a core dependency) for the nearest points.

Every method gets the node's parameters (frame voxel, map voxel and points per voxel, the polish's stages:
points, pairing distance, iteration cap) and :data:`THREADS` threads. Times are interleaved: a round runs every
method once in turn (A, B, C, A, B, C, ...), so that other load on the machine falls on all of them alike; the
ratio ours / method is taken per round and summarised by its median, also over the quiet rounds alone (other
processes below QUIET_CORES). Run it under the node's thread policy (``import cemnet_ros.ros`` before numpy, as
``scripts/bench_libraries.py`` does): numba's and small_gicp's OpenMP pools share the process, and spinning idle
threads slowed every method several times over on 2 cores. ``docs/libraries.md`` reads the figures.
"""
from __future__ import annotations

import importlib
import importlib.metadata
import inspect
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from types import ModuleType
from typing import Any, Callable, Mapping, Optional

import numba
import numpy as np
from scipy.spatial import cKDTree

from cemnet_ros.bench.metrics import percentile, relative_error
from cemnet_ros.bench.real import OFF_DEG, OFF_M, Sequence
from cemnet_ros.core.geometry import apply_transform, rigid_transform, so3_exp
from cemnet_ros.io.console import log, progress
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.frame import Frame, Preprocessor, cropped
from cemnet_ros.pipeline.steps.preprocess import voxel_downsample
from cemnet_ros.pipeline.steps.refine import point_to_plane_icp

THREADS = 2  # every method's thread count (numba's, small_gicp's num_threads, KISS-ICP's max_num_threads)
OURS = "ours"
NEIGHBOURS = 20  # small_gicp's default k for its normals and covariances
CONVERGENCE = 1e-4  # a step smaller than this (rad and m) ends a polish: point_to_plane_icp's default
WIDE_POINTS = 1000  # polish points of the timed schedule's wide stage
FINE_DISTANCE_VOXELS = 2.0  # the fine stage's pairing distance, frame voxels (as tracking.wide_polish)
OFFSETS = ((0.3, 3.0), (1.0, 10.0))  # start offsets from the true pose (m, deg), random directions
PEER_MODULES = {"small_gicp": ("small_gicp",),
                "kiss_icp": ("kiss_icp.voxelization", "kiss_icp.mapping", "kiss_icp.registration")}


def import_peers(names: tuple[str, ...] = tuple(PEER_MODULES)) -> dict[str, ModuleType]:
    """The installed peers by name (KISS-ICP's submodules loaded); each missing one is logged and left out."""
    found = {}
    for name in names:
        try:
            for module in PEER_MODULES[name]:
                importlib.import_module(module)
        except ImportError as exc:
            log(f"{name} is not installed ({exc}; pip install '.[bench]'): its column is left out")
            continue
        found[name] = sys.modules[name]
    return found


def versions() -> dict[str, Optional[str]]:
    """The installed versions of ours' runtime and of the peers (None: not installed)."""
    out: dict[str, Optional[str]] = {}
    for name in ("numpy", "numba", "scipy", "small_gicp", "kiss-icp"):
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None
    return out


# -- timing -----------------------------------------------------------------------------------------------------
OTHERS = "others_cores"  # the key, in a times dict, of each round's load from other processes (cores in use)
QUIET_CORES = 0.25  # a round during which other processes used less than this is a quiet one
TICK_S = 1.0 / os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 0.01


def cpu_ticks() -> Optional[tuple[int, int]]:
    """(busy ticks of the whole machine, steal included; ticks of this process) from /proc, None without it."""
    try:
        machine = Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]
        own = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return sum(int(machine[i]) for i in (0, 1, 2, 5, 6, 7)), int(own[11]) + int(own[12])


def interleaved(calls: Mapping[str, Callable[[], Any]], rounds: int, times: dict[str, list[float]]) -> dict[str, Any]:
    """Run every call once per round, in turn; append each one's ms to ``times[name]`` and the round's load from
    other processes to ``times[OTHERS]`` (nan without /proc). Returns the last outputs."""
    outputs = {}
    for _ in range(rounds):
        before, start = cpu_ticks(), time.perf_counter()
        for name, call in calls.items():
            call_start = time.perf_counter()
            outputs[name] = call()
            times.setdefault(name, []).append(1e3 * (time.perf_counter() - call_start))
        after, wall_s = cpu_ticks(), time.perf_counter() - start
        others = np.nan
        if before is not None and after is not None:
            others = ((after[0] - before[0]) - (after[1] - before[1])) * TICK_S / wall_s
        times.setdefault(OTHERS, []).append(others)
    return outputs


def timing_summary(times: dict[str, list[float]]) -> dict[str, dict]:
    """Per method: median and p90 ms, samples, and the median over rounds of ours / method (when ours ran); the
    same over the quiet rounds only (other processes below QUIET_CORES): a dedicated machine's figure."""
    others = np.asarray(times.get(OTHERS, []))
    out = {}
    for name, ms in times.items():
        if name == OTHERS:
            continue
        row: dict[str, Any] = {"ms_median": percentile(ms, 50), "ms_p90": percentile(ms, 90), "samples": len(ms)}
        if len(others) == len(ms):
            quiet = others < QUIET_CORES
            row.update(quiet_rounds=int(quiet.sum()), ms_median_quiet=percentile(list(np.asarray(ms)[quiet]), 50))
        if OURS in times and name != OURS:
            ratios = np.asarray(times[OURS]) / np.asarray(ms)
            row["ours_over"] = float(np.median(ratios))
            if "quiet_rounds" in row:
                row["ours_over_quiet"] = percentile(list(ratios[others < QUIET_CORES]), 50)
        out[name] = row
    return out


# -- inputs -----------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Stage:
    """One point-to-plane polish run: about ``points`` of the polish points, pairs within ``max_distance``."""

    points: int
    max_distance: float  # m
    iters: int

    def subset(self, polish: np.ndarray) -> np.ndarray:
        """Every k-th polish point, about ``points`` of them: the polish points are in scan order, so a stride
        spans the whole scan (a prefix would be a wedge)."""
        return polish[::max(1, len(polish) // self.points)]


def polish_stages(config: AlignerConfig, voxel: float) -> list[Stage]:
    """A two-stage point-to-plane polish from a start that may be a metre or degrees off, the schedule compared
    with the libraries' ICPs: a wide pairing on a subset finds the basin, the fine pairing on every polish point
    brings the precision (the node's own wide stage is small_gicp's GICP, :mod:`cemnet_ros.pipeline.basin`)."""
    return [Stage(WIDE_POINTS, config.polish.wide_distance * voxel, config.polish.wide_iters),
            Stage(config.polish.points, FINE_DISTANCE_VOXELS * voxel, config.polish.iters)]


def sequence_frames(sequence: Sequence, config: AlignerConfig) -> list[Frame]:
    """Every scan through the node's preprocessing at the first scan's scale (adopted, as the node does)."""
    preprocessor = Preprocessor(config)
    first = preprocessor.frame(sequence.scans[0])
    preprocessor.adopt(first)
    return [first] + [preprocessor.frame(points) for points in sequence.scans[1:]]


@dataclass
class Step:
    """Scan ``index`` (the source) against the scans before it (the map), all placed in the frame of the last
    map scan (the target) by the true poses."""

    index: int
    map_scans: list[np.ndarray]  # voxel clouds, each in its sensor frame
    T_target_map_scans: list[np.ndarray]
    dense: np.ndarray  # the source's voxel cloud (sensor frame)
    polish: np.ndarray  # its polish subset
    T_target_source: np.ndarray  # the truth


def polish_steps(frames: list[Frame], poses: list[np.ndarray], map_scans: int, pairs: int) -> list[Step]:
    """Up to ``pairs`` steps k -> k + 1 whose map holds ``map_scans`` scans (k - map_scans + 1 .. k)."""
    steps = []
    for k in range(map_scans - 1, min(map_scans - 1 + pairs, len(frames) - 1)):
        T_world_target = poses[k]
        kept = range(k - map_scans + 1, k + 1)
        steps.append(Step(k + 1, [frames[j].dense for j in kept],
                          [np.linalg.inv(T_world_target) @ poses[j] for j in kept], frames[k + 1].dense,
                          frames[k + 1].polish, np.linalg.inv(T_world_target) @ poses[k + 1]))
    return steps


def orthonormal(T: np.ndarray) -> np.ndarray:
    """``T`` with its rotation made exactly orthonormal (SVD): KISS-ICP's Sophus aborts on KITTI's poses, whose
    rotations are off by ~1e-6."""
    u, _, vt = np.linalg.svd(T[:3, :3])
    return rigid_transform(u @ vt, T[:3, 3])


def perturbed(T_target_source: np.ndarray, metres: float, degrees: float, rng: np.random.Generator) -> np.ndarray:
    """``T_target_source`` moved in the source frame by ``metres`` along and ``degrees`` about random directions."""
    axis, direction = rng.normal(size=3), rng.normal(size=3)
    offset = rigid_transform(so3_exp(np.radians(degrees) * axis / np.linalg.norm(axis)),
                             metres * direction / np.linalg.norm(direction))
    return T_target_source @ offset


def box_scan(n_points: int, seed: int = 0, size: float = 20.0, noise: float = 0.01) -> np.ndarray:
    """(n, 3) points on the floor and four walls of a box around the sensor, with an off-centre pillar (so that
    no motion leaves it unchanged): a small synthetic scan with planes for every piece to work on."""
    rng = np.random.default_rng(seed)
    half = size / 2.0
    uv = rng.uniform(-half, half, (n_points, 2))
    face = rng.integers(0, 6, n_points)
    points = np.empty((n_points, 3))
    points[:, 0], points[:, 1], points[:, 2] = uv[:, 0], uv[:, 1], -2.0  # floor
    for k, (axis, sign) in enumerate([(0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0)], start=1):
        on = face == k
        points[on, axis] = sign * half
        points[on, 1 - axis] = uv[on, 0]
        points[on, 2] = -2.0 + (uv[on, 1] + half) / size * 4.0  # walls 4 m high
    pillar = face == 5
    angle = rng.uniform(0.0, 2.0 * np.pi, int(pillar.sum()))
    points[pillar] = np.c_[3.0 + 0.5 * np.cos(angle), 2.0 + 0.5 * np.sin(angle),
                           -2.0 + (uv[pillar, 1] + half) / size * 4.0]
    return points + rng.normal(0.0, noise, points.shape)


# -- the pieces ---------------------------------------------------------------------------------------------------
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


# -- one sequence -------------------------------------------------------------------------------------------------
def bench_downsample(sequence: Sequence, frames: list[Frame], config: AlignerConfig, peers: dict[str, ModuleType],
                     n_scans: int, rounds: int) -> dict:
    """ms per full cropped scan of each voxel grid at the frame voxel, and the points each keeps."""
    times: dict[str, list[float]] = {}
    kept: dict[str, list[int]] = {}
    for points in progress(sequence.scans[:n_scans], desc=f"{sequence.name}: downsample"):
        scan = cropped(points, config.preprocess)
        kept.setdefault("in", []).append(len(scan))
        outputs = interleaved(downsample_calls(scan, frames[0].voxel, peers), rounds, times)
        for name, out in outputs.items():
            kept.setdefault(name, []).append(len(out))
    counts = {name: int(np.mean(n)) for name, n in kept.items()}
    return {"ms": timing_summary(times), "points_in": counts.pop("in"), "points_out": counts}


def bench_map_update(frames: list[Frame], poses: list[np.ndarray], config: AlignerConfig,
                     peers: dict[str, ModuleType], max_range: float, n_scans: int, rounds: int) -> dict:
    """ms per scan inserted into each method's growing local map (a fresh stream of ``n_scans`` per round; the
    first insertion, into an empty map, is left out)."""
    times: dict[str, list[float]] = {}
    T_first_world = np.linalg.inv(poses[0])
    for _ in progress(range(rounds), desc="map update"):
        maps = local_maps(peers, config, frames[0].voxel, max_range)
        for k in range(n_scans):
            calls = {name: partial(m.insert, frames[k].dense, T_first_world @ poses[k]) for name, m in maps.items()}
            interleaved(calls, 1, {} if k == 0 else times)
    return {"ms": timing_summary(times), "scans": n_scans}


def bench_nearest(steps: list[Step], frames: list[Frame], config: AlignerConfig, peers: dict[str, ModuleType],
                  max_range: float, rounds: int) -> dict:
    """ms per query of a whole voxel cloud against the step's map, at the fine pairing distance; the k-d trees'
    build ms; how often each method agrees with ours."""
    voxel = frames[0].voxel
    max_distance = FINE_DISTANCE_VOXELS * voxel
    times: dict[str, list[float]] = {}
    build_times: dict[str, list[float]] = {}
    same: dict[str, list[float]] = {}
    for step in progress(steps, desc="nearest"):
        ours = filled_maps(step, {}, config, voxel, max_range)[OURS]
        query = apply_transform(step.T_target_source, step.dense)
        outputs = interleaved(nearest_calls(ours.map, query, max_distance, peers, build_times), rounds, times)
        for name, dist in outputs.items():
            same.setdefault(name, []).append(agreement(outputs[OURS], dist))
    return {"ms": timing_summary(times), "build_ms": timing_summary(build_times), "max_distance_m": max_distance,
            "agreement": {name: float(np.mean(v)) for name, v in same.items()}}


def bench_polish(steps: list[Step], frames: list[Frame], config: AlignerConfig, peers: dict[str, ModuleType],
                 max_range: float, seeds: int, rounds: int) -> tuple[dict, list[dict]]:
    """Each step polished by every method from the truth perturbed by each of :data:`OFFSETS` (``seeds`` random
    directions each): ms per polish, steps taken and errors, per offset; and every trial's record."""
    stages = polish_stages(config, frames[0].voxel)
    times: dict[str, dict[str, list[float]]] = {}
    trials = []
    for step in progress(steps, desc="polish"):
        maps = filled_maps(step, peers, config, frames[0].voxel, max_range)
        for metres, degrees in OFFSETS:
            offset = f"{metres:g} m / {degrees:g} deg"
            for seed in range(seeds):
                initial = perturbed(step.T_target_source, metres, degrees, np.random.default_rng([seed, step.index]))
                calls = {name: partial(m.polish, step, initial, stages) for name, m in maps.items()}
                for name, (T_target_source, steps_taken) in interleaved(calls, rounds,
                                                                        times.setdefault(offset, {})).items():
                    rte, rre = relative_error(T_target_source, step.T_target_source)
                    trials.append({"method": name, "offset": offset, "seed": seed, "index": step.index,
                                   "rte_m": rte, "rre_deg": rre, "iterations": steps_taken})
    summary = {offset: polish_summary(t, [r for r in trials if r["offset"] == offset]) for offset, t in times.items()}
    return summary, trials


def polish_summary(times: dict[str, list[float]], trials: list[dict]) -> dict[str, dict]:
    """:func:`timing_summary` with each method's median steps, median errors and success rate (within
    OFF_M and OFF_DEG of the truth)."""
    out = timing_summary(times)
    for name, row in out.items():
        mine = [r for r in trials if r["method"] == name]
        iterations = [r["iterations"] for r in mine if r["iterations"] is not None]
        row.update(trials=len(mine), iterations_median=percentile(iterations, 50),
                   rte_median_m=percentile([r["rte_m"] for r in mine], 50),
                   rre_median_deg=percentile([r["rre_deg"] for r in mine], 50),
                   success=float(np.mean([r["rte_m"] <= OFF_M and r["rre_deg"] <= OFF_DEG for r in mine])))
    return out


def bench_sequence(sequence: Sequence, peers: dict[str, ModuleType], pairs: int, map_scans: int, seeds: int,
                   rounds: int, config: Optional[AlignerConfig] = None) -> dict:
    """Every piece on one sequence: downsample, map update, nearest points, polish (1 and ``map_scans`` scans)."""
    config = config or AlignerConfig()
    numba.set_num_threads(THREADS)
    frames = sequence_frames(sequence, config)
    poses = [orthonormal(T_world_sensor) for T_world_sensor in sequence.poses]
    n_scans = min(len(frames), map_scans + pairs)
    out: dict[str, Any] = {
        "voxel_m": frames[0].voxel, "map_voxel_m": frames[0].voxel * config.map.voxel_factor,
        "stages": [vars(s) for s in polish_stages(config, frames[0].voxel)],
        "dense_points": int(np.mean([len(f.dense) for f in frames])),
        "downsample": bench_downsample(sequence, frames, config, peers, n_scans, rounds),
        "map_update": bench_map_update(frames, poses, config, peers, sequence.max_range, n_scans, rounds),
        "nearest": bench_nearest(polish_steps(frames, poses, map_scans, pairs), frames, config, peers,
                                 sequence.max_range, rounds),
        "polish": {}, "trials": {}}
    for n_map in sorted({1, map_scans}):
        label = f"map of {n_map} scan{'s' if n_map > 1 else ''}"
        steps = polish_steps(frames, poses, n_map, pairs)
        out["polish"][label], out["trials"][label] = bench_polish(steps, frames, config, peers, sequence.max_range,
                                                                  seeds, rounds)
    return out


# -- start-up -----------------------------------------------------------------------------------------------------
IMPORTS = {OURS: ("cemnet_ros.pipeline.steps.preprocess", "cemnet_ros.pipeline.map.voxel_map",
                  "cemnet_ros.pipeline.steps.refine"),
           "small_gicp": PEER_MODULES["small_gicp"], "kiss_icp": PEER_MODULES["kiss_icp"]}
FIRST_CALL_MAP = {OURS: OURS, "small_gicp": "small_gicp plane", "kiss_icp": "kiss_icp p2p"}


def first_calls(library: str) -> dict[str, float]:
    """ms of each piece of ``library`` on a synthetic 30k-point scan, in two passes on fresh objects: the first
    pass includes numba's compilation or cache load for ours (run it in a fresh process: :func:`startup_run`)."""
    peers = {} if library == OURS else import_peers((library,))
    scan, voxel = box_scan(30_000), 0.2
    dense = scan[::3]  # not voxel_downsample's: its first call is one of those timed
    step = Step(1, [dense], [np.eye(4)], dense, dense[:3000],
                rigid_transform(so3_exp(np.array([0.0, 0.0, 0.02])), np.array([0.1, 0.0, 0.0])))
    stages = [Stage(1000, 6 * voxel, 30), Stage(3000, 2 * voxel, 10)]
    out = {}
    for which in ("first", "second"):
        local_map = local_maps(peers, AlignerConfig(), voxel, 100.0)[FIRST_CALL_MAP[library]]
        calls: dict[str, Callable] = {"downsample": downsample_calls(scan, voxel, peers)[library],
                                      "map_update": partial(local_map.insert, dense, np.eye(4)),
                                      "polish": partial(local_map.polish, step, np.eye(4), stages)}
        if library == OURS:
            calls["nearest"] = partial(local_map.map.nearest, dense, 2 * voxel)
        times: dict[str, list[float]] = {}
        interleaved(calls, 1, times)
        out.update({f"{piece}_{which}_ms": ms[0] for piece, ms in times.items() if piece != OTHERS})
    return out


def _probe(library: str, modules: tuple[str, ...]) -> dict[str, float]:
    """In a fresh process: ms to import ``modules`` (numpy already loaded: every method needs it), then
    :func:`first_calls`. Its source runs on its own in the child, hence its own imports."""
    import importlib
    import time

    import numpy  # noqa: F401 - loaded before the clock starts

    start = time.perf_counter()
    for module in modules:
        importlib.import_module(module)
    import_ms = 1e3 * (time.perf_counter() - start)
    from cemnet_ros.bench.libraries import first_calls

    return {"import_ms": import_ms, **first_calls(library)}


def startup_run(library: str, cache_dir: Optional[str] = None) -> dict[str, float]:
    """:func:`_probe` of ``library`` in a fresh Python process (``cache_dir``: numba's cache folder, for an empty
    one: the first-ever compilation)."""
    code = (inspect.getsource(_probe) + "\nimport json, sys\n"
            "print(json.dumps(_probe(sys.argv[1], tuple(sys.argv[2:]))))\n")
    env = dict(os.environ, NUMBA_NUM_THREADS=str(THREADS))
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    repo = Path(__file__).resolve().parents[2]
    env["PYTHONPATH"] = os.pathsep.join([str(repo)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    done = subprocess.run([sys.executable, "-c", code, library, *IMPORTS[library]], env=env, capture_output=True,
                          text=True)
    if done.returncode != 0:
        raise RuntimeError(f"the start-up probe of {library} failed: {done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def startup(libraries: list[str], runs: int, cold: bool) -> dict:
    """Median over ``runs`` fresh processes per library, interleaved, after one untimed run each (it fills ours'
    numba cache when the kernels changed); ``cold``: also ours once with an empty numba cache."""
    for library in libraries:
        startup_run(library)
    samples: dict[str, list[dict]] = {library: [] for library in libraries}
    for _ in progress(range(runs), desc="start-up"):
        for library in libraries:
            samples[library].append(startup_run(library))
    out: dict[str, Any] = {library: {key: float(np.median([s[key] for s in runs_])) for key in runs_[0]}
                           for library, runs_ in samples.items()}
    if cold and OURS in libraries:
        with tempfile.TemporaryDirectory(prefix="numba-cold-") as empty:
            log("start-up: ours with an empty numba cache (compiles these pieces' kernels)")
            out["ours, empty numba cache"] = startup_run(OURS, empty)
    return out


# -- tables -------------------------------------------------------------------------------------------------------
def _f(value: Optional[float], fmt: str = ".1f") -> str:
    return "-" if value is None else format(value, fmt)


def _ratios(name: str, row: dict) -> str:
    """``ours / method | same, quiet rounds (their count)`` cells (1 for ours)."""
    quiet = row.get("quiet_rounds", "-")
    if name == OURS:
        return f"1 | 1 ({quiet})"
    return f"{_f(row.get('ours_over'), '.2f')} | {_f(row.get('ours_over_quiet'), '.2f')} ({quiet})"


def speed_rows(piece: str, sequence: str, summary: dict[str, dict], extra: Callable[[str], str]) -> list[str]:
    """Markdown rows ``| piece | sequence | method | ms | ours / method | quiet | extra |``."""
    return [f"| {piece} | {sequence} | {name} | {_f(row['ms_median'])} | {_ratios(name, row)} | {extra(name)} |"
            for name, row in summary.items()]


def libraries_table(results: dict) -> str:
    """The measured figures as one markdown table per piece family (speed; polish accuracy; start-up)."""
    rows = ["| piece | sequence | method | ms median | ours / method | quiet rounds | notes |",
            "|---|---|---|---|---|---|---|"]
    for seq, r in results["sequences"].items():
        down = r["downsample"]
        rows += speed_rows("downsample", seq, down["ms"],
                           lambda n: f"{down['points_in']} -> {down['points_out'][n]} points")
        rows += speed_rows("map update", seq, r["map_update"]["ms"], lambda n: "")
        near = r["nearest"]
        rows += speed_rows("nearest", seq, near["ms"],
                           lambda n: f"agrees with ours {100 * near['agreement'][n]:.2f} %"
                           + (f", tree build {_f(near['build_ms'][n]['ms_median'])} ms" if n in near["build_ms"]
                              else ""))
    rows += ["", "| sequence | map | start offset | method | ms median | ours / method | quiet rounds | steps "
             "| RTE median cm | RRE median deg | within 10 cm / 1 deg |", "|---" * 11 + "|"]
    for seq, r in results["sequences"].items():
        for label, offsets in r["polish"].items():
            for offset, methods in offsets.items():
                for name, m in methods.items():
                    rows.append(f"| {seq} | {label} | {offset} | {name} | {_f(m['ms_median'])} | {_ratios(name, m)} | "
                                f"{_f(m['iterations_median'], '.0f')} | {_f(100 * m['rte_median_m'], '.2f')} | "
                                f"{_f(m['rre_median_deg'], '.3f')} | {100 * m['success']:.0f} % ({m['trials']}) |")
    if results.get("startup"):
        keys = sorted({k for v in results["startup"].values() for k in v})
        rows += ["", "| start-up (fresh process) | " + " | ".join(keys) + " |", "|---" * (len(keys) + 1) + "|"]
        for library, figures in results["startup"].items():
            rows.append(f"| {library} | " + " | ".join(_f(figures.get(k)) for k in keys) + " |")
    return "\n".join(rows)
