"""Local map of the scan-to-map odometry: a voxel hash map of points with normals, in the odometry frame (metres).

In the spirit of KISS-ICP's VoxelHashMap: space is cut into voxels of ``voxel_size``, each keeping the first
``max_points_per_voxel`` points that fall into it (later points of a full voxel are dropped, so the map does not
grow where the sensor stays), and voxels farther than ``max_distance`` from the sensor are forgotten. Every point
carries a unit normal and a planarity weight in [0, 1], estimated once when it is inserted, from the map points
around it, for the point-to-plane ICP of :mod:`cemnet_ros.pipeline.steps.refine`. The last scan inserted is also kept
thinned to the voxel with covariances: the target of the polish's wide stage (:mod:`..steps.basin`).

The storage and its kernels are :mod:`.voxel_hash` (hash table, insertion, pruning), the normals
:mod:`.voxel_normals`, the queries :mod:`.voxel_query`; the numba policy (cached on disk, made ready at start by
:func:`compile_kernels`) is :mod:`cemnet_ros.core.jit`'s.
"""
from __future__ import annotations

from typing import Callable, Optional

import numba
import numpy as np

from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.pipeline.map.free_space import FreeSpace
from cemnet_ros.pipeline.map.gicp_cloud import GICP_VOXELS, GicpCloud, gicp_cloud
from cemnet_ros.pipeline.map.voxel_hash import EMPTY, insert_points, prune_far_voxels, rehash
from cemnet_ros.pipeline.map.voxel_normals import NORMAL_RADIUS, estimate_normals
from cemnet_ros.pipeline.map.voxel_query import nearest_batch, slots_within


class VoxelMap:
    """Points (with normals and planarity) in voxels of ``voxel_size``, at most ``max_points_per_voxel`` each."""

    _pts: np.ndarray  # (capacity * max_points_per_voxel, 3) slots, voxel by voxel
    _normals: np.ndarray
    _planarity: np.ndarray
    _counts: np.ndarray  # (capacity,) points in each voxel
    _voxel_keys: np.ndarray
    _table: np.ndarray  # (size, 2) hash table rows (key, voxel)

    def __init__(self, voxel_size: float, max_points_per_voxel: int = 10, max_distance: float = 100.0) -> None:
        if voxel_size <= 0.0 or max_points_per_voxel < 1 or max_distance <= 0.0:
            raise ValueError("voxel_size and max_distance must be > 0, max_points_per_voxel >= 1")
        self.voxel_size = float(voxel_size)
        self.max_points_per_voxel = int(max_points_per_voxel)
        self.max_distance = float(max_distance)
        self.clear()

    def clear(self) -> None:
        """Forget every point."""
        self._n_voxels = 0
        self._n_points = 0
        self._allocate_voxels(1024)
        self._allocate_table(4096)
        self._dense: Optional[tuple[np.ndarray, np.ndarray, np.ndarray]] = None
        self._last_scan: Optional[GicpCloud] = None
        self._make_last_scan: Optional[Callable[[], GicpCloud]] = None
        self._free_space: Optional[FreeSpace] = None
        self._last_points: Optional[tuple[np.ndarray, np.ndarray]] = None  # (points, sensor position), odom

    @property
    def gicp_voxel(self) -> float:
        """The voxel its last scan is thinned to for GICP (:mod:`.gicp_cloud`), m."""
        return GICP_VOXELS * self.voxel_size

    def __len__(self) -> int:
        return self._n_points

    def empty(self) -> bool:
        return self._n_points == 0

    @property
    def last_scan(self) -> Optional[GicpCloud]:
        """The last points inserted, thinned to the voxel, with covariances (:mod:`..steps.basin`); None when empty."""
        if self._last_scan is None and self._make_last_scan is not None:
            self._last_scan = self._make_last_scan()
        return self._last_scan

    @property
    def free_space(self) -> Optional[FreeSpace]:
        """What the last scan inserted saw as empty (:mod:`.free_space`, made when first asked for); None when
        empty."""
        if self._free_space is None and self._last_points is not None:
            self._free_space = FreeSpace(*self._last_points)
        return self._free_space

    @property
    def points(self) -> np.ndarray:
        """(n, 3) map points, voxel by voxel."""
        return self._dense_arrays()[0]

    @property
    def normals(self) -> np.ndarray:
        """(n, 3) unit normals of :attr:`points` (sign arbitrary)."""
        return self._dense_arrays()[1]

    @property
    def planarity(self) -> np.ndarray:
        """(n,) 1 - lambda_min / lambda_mid of each point's neighbourhood: 1 on a plane, 0 on a line or blob."""
        return self._dense_arrays()[2]

    def view(self) -> tuple:
        """The kernels' read-only view of the map, for :func:`nearest_slot`."""
        return self._pts, self._counts, self._table, self._shift, self.voxel_size, self.max_points_per_voxel

    def slot_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(points, normals, planarity) indexed by the slots that :func:`nearest_slot` returns."""
        return self._pts, self._normals, self._planarity

    def update(self, points: np.ndarray, sensor_position: np.ndarray,
               scan: Optional[Callable[[], GicpCloud]] = None) -> None:
        """Insert ``points`` (map frame) into voxels with room, estimate their normals, drop far voxels.

        ``scan``: makes the same points as a :class:`~..steps.basin.GicpCloud` thinned to the map's voxel, placed where
        they were inserted (:attr:`last_scan`, made when first asked for; from ``points`` when not given)."""
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        self._reserve(len(points))
        m = self.max_points_per_voxel
        inserted = np.empty(len(points), dtype=np.int64)
        self._n_voxels, n_inserted = insert_points(points, self.voxel_size, m, self._pts, self._counts,
                                                   self._voxel_keys, self._n_voxels, self._table, self._shift, inserted)
        voxels, n_new = np.unique(inserted[:n_inserted] // m, return_counts=True)
        rings = int(np.ceil(NORMAL_RADIUS))
        # numba.config sets its attributes at import: no stub knows them
        threads = numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]
        around = np.empty((threads, (2 * rings + 1) ** 3), dtype=np.int64)
        estimate_normals(voxels, n_new, self.voxel_size, m, self._pts, self._counts, self._normals, self._planarity,
                         self._voxel_keys, self._table, self._shift, around)
        sensor = np.ascontiguousarray(sensor_position, dtype=np.float64).reshape(3)
        self._n_voxels = prune_far_voxels(sensor, self.max_distance, self.voxel_size, m, self._pts, self._normals,
                                          self._planarity, self._counts, self._voxel_keys, self._n_voxels,
                                          self._table, self._shift)
        self._n_points = int(self._counts[:self._n_voxels].sum())
        self._dense = None
        self._last_scan = None
        self._free_space = None
        self._last_points = (points, sensor)
        self._make_last_scan = scan or (lambda: gicp_cloud(points, self.gicp_voxel))

    def snapshot(self) -> VoxelMap:
        """A copy that later updates of this map leave as it is (for a registration on another thread); the last
        scan and the free space are shared until one of the two is updated."""
        copy = VoxelMap.__new__(VoxelMap)
        copy.__dict__.update(self.__dict__)
        for name in ("_pts", "_normals", "_planarity", "_counts", "_voxel_keys", "_table"):
            setattr(copy, name, getattr(self, name).copy())
        return copy

    def nearest(self, query: np.ndarray, max_distance: float) -> tuple[np.ndarray, np.ndarray]:
        """(n,) distances (inf if none within ``max_distance``) and (n,) indices into :attr:`points` (-1)."""
        dist, slots = self._query(query, max_distance)
        counts = self._counts[:self._n_voxels]
        first_index = np.cumsum(counts) - counts  # of each voxel's first point in :attr:`points`
        m = self.max_points_per_voxel
        found = slots >= 0
        index = np.full(len(slots), -1, dtype=np.int64)
        index[found] = first_index[slots[found] // m] + slots[found] % m
        return dist, index

    def inlier_fraction(self, source: np.ndarray, T_map_source: np.ndarray, distance: float,
                        residual: float = np.inf) -> float:
        """Fraction of ``source`` (source frame) that lies on the map after ``T_map_source``: the nearest map
        point within ``distance`` and, within ``residual`` of its plane (of the point itself where it has no
        normal). The plane test tells centimetres apart on any map density: a nearest-point radius does not."""
        return self.overlap(source, T_map_source, distance, residual, distance)[0]

    def overlap(self, source: np.ndarray, T_map_source: np.ndarray, distance: float, residual: float,
                reach: float) -> tuple[float, float]:
        """(:meth:`inlier_fraction`, coverage) of ``source`` after ``T_map_source``, from one nearest-point query:
        the coverage is the fraction with a map point within ``reach`` (>= ``distance``), the share of the scan
        that lands where the map has surfaces at all."""
        source = np.asarray(source, dtype=np.float64).reshape(-1, 3)
        if len(source) == 0:
            return 0.0, 0.0
        moved = apply_transform(np.asarray(T_map_source, dtype=np.float64), source)
        dist, slots = self._query(moved, max(reach, distance))
        covered = float(np.count_nonzero(slots >= 0)) / len(source)
        found = dist <= distance
        if not np.isfinite(residual):
            return float(np.count_nonzero(found)) / len(source), covered
        slots, dist = slots[found], dist[found]
        offsets = np.einsum("ij,ij->i", self._normals[slots], moved[found] - self._pts[slots])
        off_plane = np.where(self._planarity[slots] > 0.0, np.abs(offsets), dist)
        return float(np.count_nonzero(off_plane <= residual)) / len(source), covered

    def sample(self, n: int, centre: np.ndarray, radius: float, seed: int = 0) -> np.ndarray:
        """At most ``n`` map points within ``radius`` of ``centre``: a seeded random subset (the CEM's target)."""
        slots = slots_within(np.ascontiguousarray(centre, dtype=np.float64).reshape(3), float(radius),
                              self._n_voxels, self.view(), self._voxel_keys)
        if len(slots) > n:
            slots = np.sort(np.random.default_rng(seed).choice(slots, size=n, replace=False))
        return self._pts[slots]

    # -- storage ------------------------------------------------------------------------------------------------
    def _allocate_voxels(self, capacity: int) -> None:
        """Voxel storage for ``capacity`` voxels, keeping the current ones."""
        m = self.max_points_per_voxel
        pts, normals = np.zeros((capacity * m, 3)), np.zeros((capacity * m, 3))
        planarity, counts = np.zeros(capacity * m), np.zeros(capacity, dtype=np.int64)
        keys = np.full(capacity, EMPTY, dtype=np.int64)
        used = self._n_voxels
        if used:
            pts[:used * m], normals[:used * m] = self._pts[:used * m], self._normals[:used * m]
            planarity[:used * m], counts[:used], keys[:used] = (self._planarity[:used * m], self._counts[:used],
                                                                 self._voxel_keys[:used])
        self._pts, self._normals, self._planarity = pts, normals, planarity
        self._counts, self._voxel_keys = counts, keys

    def _allocate_table(self, size: int) -> None:
        """A hash table of ``size`` (a power of two) entries holding the current voxels."""
        self._table = np.full((size, 2), EMPTY, dtype=np.int64)  # (key, voxel) rows: one cache line per probe
        self._shift = 64 - int(size).bit_length() + 1
        rehash(self._voxel_keys, self._n_voxels, self._table, self._shift)

    def _reserve(self, n_new: int) -> None:
        """Room for ``n_new`` more voxels, with the hash table at most half full."""
        needed = self._n_voxels + n_new
        if needed > len(self._counts):
            self._allocate_voxels(max(needed, 2 * len(self._counts)))
        if 2 * needed > len(self._table):
            self._allocate_table(1 << int(2 * needed - 1).bit_length())

    def _query(self, query: np.ndarray, max_distance: float) -> tuple[np.ndarray, np.ndarray]:
        """(n,) distances (inf if none) and (n,) slots (-1) of the nearest map points within ``max_distance``."""
        query = np.ascontiguousarray(query, dtype=np.float64).reshape(-1, 3)
        dist = np.empty(len(query))
        slots = np.empty(len(query), dtype=np.int64)
        nearest_batch(query, float(max_distance), self.view(), dist, slots)
        return dist, slots

    def _dense_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(points, normals, planarity) without the empty slots, voxel by voxel; cached until the next update."""
        if self._dense is None:
            m, used = self.max_points_per_voxel, self._n_voxels
            keep = (np.arange(m) < self._counts[:used, None]).ravel()
            self._dense = (self._pts[:used * m][keep], self._normals[:used * m][keep],
                           self._planarity[:used * m][keep])
        return self._dense


def compile_kernels() -> None:
    """Compile the map's kernels on a tiny map now, so that the first real scan is not the slow one."""
    points = np.random.default_rng(0).random((64, 3))
    voxel_map = VoxelMap(0.5, max_points_per_voxel=4, max_distance=1.0)
    voxel_map.update(points, np.zeros(3))
    voxel_map.update(points + 5.0, np.full(3, 5.0))
    voxel_map.nearest(points, 0.3)
    voxel_map.inlier_fraction(points, np.eye(4), 0.3)
    voxel_map.sample(8, np.full(3, 5.0), 1.0)
