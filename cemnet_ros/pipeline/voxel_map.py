"""Local map of the scan-to-map odometry: a voxel hash map of points with normals, in the odometry frame (metres).

In the spirit of KISS-ICP's VoxelHashMap: space is cut into voxels of ``voxel_size``, each keeping the first
``max_points_per_voxel`` points that fall into it (later points of a full voxel are dropped, so the map does not
grow where the sensor stays), and voxels farther than ``max_distance`` from the sensor are forgotten. Every point
carries a unit normal and a planarity weight in [0, 1], estimated once when it is inserted, from the map points
around it, for the point-to-plane ICP of :mod:`cemnet_ros.pipeline.refine`.

Storage is flat: voxel ``v`` owns the point slots ``v * M .. v * M + M - 1`` (``M = max_points_per_voxel``),
voxels are kept dense (a removed voxel is replaced by the last one) and an open-addressing hash table (linear
probing, backward-shift deletion) maps packed int64 voxel keys to voxel indices. Voxel indices are limited to
+-2^20 per axis (+-105 km at 0.1 m voxels).

The kernels are compiled once per process (:func:`compile_kernels`), not cached on disk (see
:mod:`cemnet_ros.core.nn_grid` for why).
"""
from __future__ import annotations

import numba
import numpy as np

# The threading policy of cemnet_ros.core.nn_grid (OpenMP first: thread-safe across calling threads).
numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]
EMPTY = -1  # a free hash table entry; packed keys are never negative
KEY_OFFSET = 1 << 20  # voxel indices are stored as 21-bit unsigned fields
KEY_MASK = (1 << 21) - 1
MIN_NEIGHBOURS = 5  # fewer map points around a new point leave its normal undefined (planarity 0)
NORMAL_RADIUS = 1.0  # neighbourhood of the normal estimation, in voxels
# fastmath without the no-inf/no-nan assumptions: distances start at the search bound, never at inf
FAST = {"nsz", "arcp", "contract", "afn", "reassoc"}
GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing: multiply, keep the top bits


# -- hash table -------------------------------------------------------------------------------------------------
@numba.njit
def _cell(x, voxel_size):
    """Voxel index of a coordinate (the same floor as :func:`cemnet_ros.pipeline.preprocess.voxel_downsample`)."""
    return np.int64(np.floor(x / voxel_size))


@numba.njit
def _pack(ix, iy, iz):
    """One non-negative int64 per voxel: three 21-bit fields."""
    x, y, z = (ix + KEY_OFFSET) & KEY_MASK, (iy + KEY_OFFSET) & KEY_MASK, (iz + KEY_OFFSET) & KEY_MASK
    return (x << 42) | (y << 21) | z


@numba.njit
def _unpack(key):
    """The voxel indices (ix, iy, iz) of a packed key."""
    return ((key >> 42) & KEY_MASK) - KEY_OFFSET, ((key >> 21) & KEY_MASK) - KEY_OFFSET, (key & KEY_MASK) - KEY_OFFSET


@numba.njit
def _home(key, shift):
    """The table entry where ``key``'s probe starts."""
    return np.int64((np.uint64(key) * GOLDEN) >> np.uint64(shift))


@numba.njit
def _find(key, table, shift):
    """Voxel index of ``key``, -1 if absent."""
    mask = table.shape[0] - 1
    i = _home(key, shift)
    while True:
        k = table[i, 0]
        if k == key:
            return table[i, 1]
        if k == EMPTY:
            return -1
        i = (i + 1) & mask


@numba.njit
def _find_or_add(key, table, shift, new_voxel):
    """Voxel index of ``key``; absent keys get ``new_voxel``. Returns (voxel, added)."""
    mask = table.shape[0] - 1
    i = _home(key, shift)
    while True:
        k = table[i, 0]
        if k == key:
            return table[i, 1], False
        if k == EMPTY:
            table[i, 0] = key
            table[i, 1] = new_voxel
            return new_voxel, True
        i = (i + 1) & mask


@numba.njit
def _remove_key(key, table, shift):
    """Delete ``key`` (present) and shift the rest of its probe cluster back, so that no tombstone is needed."""
    mask = table.shape[0] - 1
    i = _home(key, shift)
    while table[i, 0] != key:
        i = (i + 1) & mask
    j = i
    while True:
        j = (j + 1) & mask
        if table[j, 0] == EMPTY:
            break
        home = _home(table[j, 0], shift)
        stays = (i < home <= j) if i <= j else (home > i or home <= j)  # home lies cyclically in (i, j]
        if not stays:
            table[i, 0], table[i, 1] = table[j, 0], table[j, 1]
            i = j
    table[i, 0] = EMPTY


@numba.njit
def _rehash(voxel_keys, n_voxels, table, shift):
    """Fill an empty table with the keys of voxels 0 .. n_voxels - 1."""
    for v in range(n_voxels):
        _find_or_add(voxel_keys[v], table, shift, v)


# -- insertion, normals, pruning -----------------------------------------------------------------------------
@numba.njit
def _insert(points, voxel_size, m, pts, counts, voxel_keys, n_voxels, table, shift, inserted):
    """Put each point into its voxel unless the voxel is full; returns (n_voxels, n_inserted).

    ``inserted`` receives the slots written; the caller has reserved room for one new voxel per point.
    """
    n_inserted = 0
    for i in range(points.shape[0]):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        key = _pack(_cell(x, voxel_size), _cell(y, voxel_size), _cell(z, voxel_size))
        v, added = _find_or_add(key, table, shift, n_voxels)
        if added:
            voxel_keys[v] = key
            counts[v] = 0
            n_voxels += 1
        c = counts[v]
        if c >= m:
            continue
        slot = v * m + c
        pts[slot, 0], pts[slot, 1], pts[slot, 2] = x, y, z
        counts[v] = c + 1
        inserted[n_inserted] = slot
        n_inserted += 1
    return n_voxels, n_inserted


@numba.njit
def _smallest_eigen(a00, a01, a02, a11, a12, a22):
    """(normal, planarity) of a 3x3 covariance: the smallest principal axis and (s_mid - s_min) / s_max.

    s are the principal standard deviations. That planarity is near 1 for a patch of a surface and near 0 for a
    line of points (one LiDAR ring, its range noise across it), whose smallest axis is an arbitrary direction
    across the line: such a normal would bias the point-to-plane fit.

    Closed form: the eigenvalues by the trigonometric solution, the eigenvector as the largest cross product of
    two rows of (A - lambda_min I).
    """
    q = (a00 + a11 + a22) / 3.0
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    p = np.sqrt(((a00 - q) ** 2 + (a11 - q) ** 2 + (a22 - q) ** 2 + 2.0 * p1) / 6.0)
    if p < 1e-150:
        return 0.0, 0.0, 1.0, 0.0  # isotropic (or a single point): no plane
    b00, b11, b22 = (a00 - q) / p, (a11 - q) / p, (a22 - q) / p
    b01, b02, b12 = a01 / p, a02 / p, a12 / p
    det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02)
    phi = np.arccos(min(max(det / 2.0, -1.0), 1.0)) / 3.0
    lam_max = q + 2.0 * p * np.cos(phi)
    lam_min = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    lam_mid = 3.0 * q - lam_max - lam_min
    s_min, s_mid, s_max = np.sqrt(max(lam_min, 0.0)), np.sqrt(max(lam_mid, 0.0)), np.sqrt(max(lam_max, 0.0))
    planarity = min(max((s_mid - s_min) / s_max, 0.0), 1.0) if s_max > 0.0 else 0.0
    c00, c11, c22 = a00 - lam_min, a11 - lam_min, a22 - lam_min
    x0, x1, x2 = a01 * a12 - a02 * c11, a02 * a01 - c00 * a12, c00 * c11 - a01 * a01
    y0, y1, y2 = a01 * c22 - a02 * a12, a02 * a02 - c00 * c22, c00 * a12 - a01 * a02
    z0, z1, z2 = c11 * c22 - a12 * a12, a12 * a02 - a01 * c22, a01 * a12 - c11 * a02
    nx, ny, nz = x0 * x0 + x1 * x1 + x2 * x2, y0 * y0 + y1 * y1 + y2 * y2, z0 * z0 + z1 * z1 + z2 * z2
    if nx >= ny and nx >= nz and nx > 0.0:
        s = 1.0 / np.sqrt(nx)
        return x0 * s, x1 * s, x2 * s, planarity
    if ny >= nz and ny > 0.0:
        s = 1.0 / np.sqrt(ny)
        return y0 * s, y1 * s, y2 * s, planarity
    if nz > 0.0:
        s = 1.0 / np.sqrt(nz)
        return z0 * s, z1 * s, z2 * s, planarity
    return 0.0, 0.0, 1.0, 0.0


@numba.njit
def _neighbour_voxels(v, rings, voxel_keys, table, shift, out):
    """The occupied voxels within ``rings`` of voxel ``v`` (itself included) into ``out``; returns how many."""
    ix, iy, iz = _unpack(voxel_keys[v])
    k = 0
    for a in range(ix - rings, ix + rings + 1):
        for b in range(iy - rings, iy + rings + 1):
            for c in range(iz - rings, iz + rings + 1):
                u = _find(_pack(a, b, c), table, shift)
                if u >= 0:
                    out[k] = u
                    k += 1
    return k


@numba.njit(fastmath=FAST)
def _voxel_normals(v, n_new, voxel_size, m, pts, counts, normals, planarity, voxel_keys, table, shift, around):
    """Normal and planarity of the last ``n_new`` points of voxel ``v``: PCA of the map points around each.

    The neighbouring voxels are looked up once, for all the voxel's new points; ``around`` is scratch space.
    """
    radius = NORMAL_RADIUS * voxel_size
    r_sq = radius * radius
    n_around = _neighbour_voxels(v, int(np.ceil(NORMAL_RADIUS)), voxel_keys, table, shift, around)
    for slot in range(v * m + counts[v] - n_new, v * m + counts[v]):
        px, py, pz = pts[slot, 0], pts[slot, 1], pts[slot, 2]
        n = sx = sy = sz = sxx = sxy = sxz = syy = syz = szz = 0.0
        for a in range(n_around):
            u = around[a]
            for j in range(u * m, u * m + counts[u]):
                dx, dy, dz = pts[j, 0] - px, pts[j, 1] - py, pts[j, 2] - pz  # small: no cancellation
                w = 1.0 if dx * dx + dy * dy + dz * dz <= r_sq else 0.0  # a select, not a branch
                n += w
                sx += w * dx
                sy += w * dy
                sz += w * dz
                sxx += w * dx * dx
                sxy += w * dx * dy
                sxz += w * dx * dz
                syy += w * dy * dy
                syz += w * dy * dz
                szz += w * dz * dz
        if n < MIN_NEIGHBOURS:
            normals[slot, 0], normals[slot, 1], normals[slot, 2], planarity[slot] = 0.0, 0.0, 1.0, 0.0
            continue
        mx, my, mz = sx / n, sy / n, sz / n
        normals[slot, 0], normals[slot, 1], normals[slot, 2], planarity[slot] = _smallest_eigen(
            sxx / n - mx * mx, sxy / n - mx * my, sxz / n - mx * mz, syy / n - my * my, syz / n - my * mz,
            szz / n - mz * mz)


@numba.njit(parallel=True)
def _estimate_normals(voxels, n_new, voxel_size, m, pts, counts, normals, planarity, voxel_keys, table, shift,
                      around):
    """:func:`_voxel_normals` of each voxel ``voxels[i]`` (``n_new[i]`` new points) in parallel.

    ``around`` (threads, (2 rings + 1)^3) is per-thread scratch space.
    """
    with numba.parallel_chunksize(64):  # handed out dynamically: voxels differ in cost, threads in speed
        for i in numba.prange(voxels.shape[0]):
            _voxel_normals(voxels[i], n_new[i], voxel_size, m, pts, counts, normals, planarity, voxel_keys, table,
                           shift, around[numba.get_thread_id()])


@numba.njit
def _prune(sensor, max_distance, voxel_size, m, pts, normals, planarity, counts, voxel_keys, n_voxels,
           table, shift):
    """Remove the voxels whose centre is farther than ``max_distance`` from ``sensor``; returns n_voxels.

    A removed voxel is overwritten by the last one (already checked: the loop runs backwards).
    """
    max_sq = max_distance * max_distance
    for v in range(n_voxels - 1, -1, -1):
        key = voxel_keys[v]
        distance_sq = 0.0
        for axis, cell in enumerate(_unpack(key)):
            distance_sq += ((cell + 0.5) * voxel_size - sensor[axis]) ** 2
        if distance_sq <= max_sq:
            continue
        _remove_key(key, table, shift)
        last = n_voxels - 1
        n_voxels = last
        if v == last:
            continue
        voxel_keys[v] = voxel_keys[last]
        counts[v] = counts[last]
        for k in range(counts[last]):
            for axis in range(3):
                pts[v * m + k, axis] = pts[last * m + k, axis]
                normals[v * m + k, axis] = normals[last * m + k, axis]
            planarity[v * m + k] = planarity[last * m + k]
        mask = table.shape[0] - 1
        i = _home(voxel_keys[v], shift)
        while table[i, 0] != voxel_keys[v]:
            i = (i + 1) & mask
        table[i, 1] = v
    return n_voxels


# -- queries ----------------------------------------------------------------------------------------------------
@numba.njit(fastmath=FAST)
def _scan_voxel(v, qx, qy, qz, pts, counts, m, best_sq, best):
    """Closest of voxel ``v``'s points if nearer than ``best_sq``: (best_sq, best slot)."""
    for j in range(v * m, v * m + counts[v]):
        dx, dy, dz = pts[j, 0] - qx, pts[j, 1] - qy, pts[j, 2] - qz
        d = dx * dx + dy * dy + dz * dz
        if d < best_sq:
            best_sq, best = d, j
    return best_sq, best


@numba.njit(fastmath=FAST)
def _axis_order(q, max_distance, voxel_size):
    """A query's cells along one axis, nearest first: (own cell, step towards its nearer face, cells to visit).

    The j-th cell is own + side * (j + 1) // 2 for odd j, own - side * j // 2 for even j; its distance from the
    query never decreases with j, so a search along the axis can stop at the first cell that is too far.
    """
    own = _cell(q, voxel_size)
    side = 1 if q - own * voxel_size > 0.5 * voxel_size else -1
    reach = max(own - _cell(q - max_distance, voxel_size), _cell(q + max_distance, voxel_size) - own)
    return own, side, 2 * reach + 1


@numba.njit(fastmath=FAST)
def _axis_cell(own, side, j):
    """The j-th cell of :func:`_axis_order`."""
    return own + side * ((j + 1) // 2) if j % 2 == 1 else own - side * (j // 2)


@numba.njit(fastmath=FAST)
def _gap(q, cell, own, voxel_size):
    """Distance along one axis from coordinate ``q`` (in voxel ``own``) to voxel ``cell``."""
    if cell < own:
        return q - (cell + 1) * voxel_size
    if cell > own:
        return cell * voxel_size - q
    return 0.0


@numba.njit(fastmath=FAST)
def nearest_slot(qx, qy, qz, max_distance, view):
    """(squared distance, slot) of the nearest map point within ``max_distance``; (max_distance^2, -1) if none.

    Exact for any ``max_distance``: every voxel that the ball reaches is visited, nearest cells first along each
    axis, until its box is farther than the best point found so far.
    """
    pts, counts, table, shift, voxel_size, m = view
    best_sq, best = max_distance * max_distance, -1
    ox, sx, nx = _axis_order(qx, max_distance, voxel_size)
    oy, sy, ny = _axis_order(qy, max_distance, voxel_size)
    oz, sz, nz = _axis_order(qz, max_distance, voxel_size)
    for i in range(nx):
        a = _axis_cell(ox, sx, i)
        gx = _gap(qx, a, ox, voxel_size)
        if gx * gx >= best_sq:
            break
        for j in range(ny):
            b = _axis_cell(oy, sy, j)
            gy = _gap(qy, b, oy, voxel_size)
            gxy_sq = gx * gx + gy * gy
            if gxy_sq >= best_sq:
                break
            for k in range(nz):
                c = _axis_cell(oz, sz, k)
                gz = _gap(qz, c, oz, voxel_size)
                if gxy_sq + gz * gz >= best_sq:
                    break
                v = _find(_pack(a, b, c), table, shift)
                if v >= 0:
                    best_sq, best = _scan_voxel(v, qx, qy, qz, pts, counts, m, best_sq, best)
    return best_sq, best


@numba.njit(parallel=True)
def _nearest_batch(query, max_distance, view, dist, slots):
    """Distance (inf if none) and slot (-1) of each query's nearest map point within ``max_distance``."""
    for i in numba.prange(query.shape[0]):
        d_sq, s = nearest_slot(query[i, 0], query[i, 1], query[i, 2], max_distance, view)
        slots[i] = s
        dist[i] = np.sqrt(d_sq) if s >= 0 else np.inf


@numba.njit
def _slots_within(centre, radius, n_voxels, view, voxel_keys):
    """Slots of the map points within ``radius`` of ``centre``, voxel by voxel (the order of ``points``)."""
    pts, counts, _, _, voxel_size, m = view
    r_sq = radius * radius
    out = np.empty(n_voxels * m, dtype=np.int64)
    k = 0
    for v in range(n_voxels):
        gap_sq = 0.0  # from the centre to the voxel's box
        for axis, cell in enumerate(_unpack(voxel_keys[v])):
            gap = max(cell * voxel_size - centre[axis], centre[axis] - (cell + 1) * voxel_size, 0.0)
            gap_sq += gap * gap
        if gap_sq > r_sq:
            continue
        for j in range(v * m, v * m + counts[v]):
            dx, dy, dz = pts[j, 0] - centre[0], pts[j, 1] - centre[1], pts[j, 2] - centre[2]
            if dx * dx + dy * dy + dz * dz <= r_sq:
                out[k] = j
                k += 1
    return out[:k]


# -- the map ----------------------------------------------------------------------------------------------------
class VoxelMap:
    """Points (with normals and planarity) in voxels of ``voxel_size``, at most ``max_points_per_voxel`` each."""

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
        self._counts = None
        self._allocate_voxels(1024)
        self._allocate_table(4096)
        self._dense = None

    def __len__(self) -> int:
        return self._n_points

    def empty(self) -> bool:
        return self._n_points == 0

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

    def update(self, points: np.ndarray, sensor_position: np.ndarray) -> None:
        """Insert ``points`` (map frame) into voxels with room, estimate their normals, drop far voxels."""
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        self._reserve(len(points))
        m = self.max_points_per_voxel
        inserted = np.empty(len(points), dtype=np.int64)
        self._n_voxels, n_inserted = _insert(points, self.voxel_size, m, self._pts, self._counts, self._voxel_keys,
                                             self._n_voxels, self._table, self._shift, inserted)
        voxels, n_new = np.unique(inserted[:n_inserted] // m, return_counts=True)
        rings = int(np.ceil(NORMAL_RADIUS))
        around = np.empty((numba.config.NUMBA_NUM_THREADS, (2 * rings + 1) ** 3), dtype=np.int64)
        _estimate_normals(voxels, n_new, self.voxel_size, m, self._pts, self._counts, self._normals, self._planarity,
                          self._voxel_keys, self._table, self._shift, around)
        sensor = np.ascontiguousarray(sensor_position, dtype=np.float64).reshape(3)
        self._n_voxels = _prune(sensor, self.max_distance, self.voxel_size, m, self._pts, self._normals,
                                self._planarity, self._counts, self._voxel_keys, self._n_voxels, self._table,
                                self._shift)
        self._n_points = int(self._counts[:self._n_voxels].sum())
        self._dense = None

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

    def inlier_fraction(self, source: np.ndarray, T_map_source: np.ndarray, distance: float) -> float:
        """Fraction of ``source`` (source frame) with a map point within ``distance`` after ``T_map_source``."""
        source = np.asarray(source, dtype=np.float64).reshape(-1, 3)
        if len(source) == 0:
            return 0.0
        T = np.asarray(T_map_source, dtype=np.float64)
        dist, _ = self._query(source @ T[:3, :3].T + T[:3, 3], distance)
        return float(np.count_nonzero(np.isfinite(dist))) / len(source)

    def sample(self, n: int, centre: np.ndarray, radius: float, seed: int = 0) -> np.ndarray:
        """At most ``n`` map points within ``radius`` of ``centre``: a seeded random subset (the CEM's target)."""
        slots = _slots_within(np.ascontiguousarray(centre, dtype=np.float64).reshape(3), float(radius),
                              self._n_voxels, self.view(), self._voxel_keys)
        if len(slots) > n:
            slots = np.sort(np.random.default_rng(seed).choice(slots, size=n, replace=False))
        return self._pts[slots]

    # -- storage ------------------------------------------------------------------------------------------------
    def _allocate_voxels(self, capacity: int) -> None:
        """Voxel storage for ``capacity`` voxels, keeping the current ones."""
        m = self.max_points_per_voxel
        old = self._counts
        pts, normals = np.zeros((capacity * m, 3)), np.zeros((capacity * m, 3))
        planarity, counts = np.zeros(capacity * m), np.zeros(capacity, dtype=np.int64)
        keys = np.full(capacity, EMPTY, dtype=np.int64)
        if old is not None:
            used = self._n_voxels
            pts[:used * m], normals[:used * m] = self._pts[:used * m], self._normals[:used * m]
            planarity[:used * m], counts[:used], keys[:used] = (self._planarity[:used * m], self._counts[:used],
                                                                 self._voxel_keys[:used])
        self._pts, self._normals, self._planarity = pts, normals, planarity
        self._counts, self._voxel_keys = counts, keys

    def _allocate_table(self, size: int) -> None:
        """A hash table of ``size`` (a power of two) entries holding the current voxels."""
        self._table = np.full((size, 2), EMPTY, dtype=np.int64)  # (key, voxel) rows: one cache line per probe
        self._shift = 64 - int(size).bit_length() + 1
        _rehash(self._voxel_keys, self._n_voxels, self._table, self._shift)

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
        _nearest_batch(query, float(max_distance), self.view(), dist, slots)
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
