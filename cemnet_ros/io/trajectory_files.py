"""Trajectory files: TUM and KITTI, written atomically, and read back; one writer for the node and the replay.

- TUM (evo's ``evo_ape tum``): one line per pose, ``stamp tx ty tz qx qy qz qw``, the stamp in seconds with all
  nine decimals of the nanoseconds;
- KITTI (the odometry benchmark's poses): one line per pose, the 3x4 ``[R | t]`` row-major, 12 numbers; no
  stamps (the flags file written beside it by the node has them, in the same order).

Poses are ``(n, 4, 4)`` transforms ``T_world_frame``; stamps are integer nanoseconds. The format of a path is its
suffix's (:data:`TRAJECTORY_FORMATS`).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping, Sequence, Union

import numpy as np
from scipy.spatial.transform import Rotation

from cemnet_ros.io.atomic import atomic_write_text

PathLike = Union[str, "os.PathLike[str]"]
TRAJECTORY_FORMATS = {".tum": "tum", ".txt": "tum", ".kitti": "kitti"}  # suffix (any case) -> format
NS = 1_000_000_000


def as_poses(poses: Sequence[np.ndarray] | np.ndarray) -> np.ndarray:
    """``(n, 4, 4)`` float64 finite transforms; ValueError for another shape or NaN / inf."""
    arr = np.asarray(poses, dtype=np.float64)
    if arr.size == 0:
        return arr.reshape(0, 4, 4)
    if arr.ndim != 3 or arr.shape[1:] != (4, 4):
        raise ValueError(f"poses must have shape (n, 4, 4), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("poses contain NaN or inf")
    return arr


def stamp_texts(stamps_ns: Sequence[int] | np.ndarray) -> list[str]:
    """Nanosecond stamps (>= 0) as seconds with nine decimals, exactly: ``1700000000.123456789``."""
    stamps = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    if np.any(stamps < 0):
        raise ValueError("trajectory stamps must be >= 0")
    return [f"{s // NS}.{s % NS:09d}" for s in stamps.tolist()]


def tum_text(stamps_ns: Sequence[int] | np.ndarray, poses: Sequence[np.ndarray] | np.ndarray) -> str:
    """The TUM file's text: a comment line, then ``stamp tx ty tz qx qy qz qw`` per pose (9 decimals)."""
    arr, stamps = as_poses(poses), stamp_texts(stamps_ns)
    if len(stamps) != len(arr):
        raise ValueError(f"{len(stamps)} stamps but {len(arr)} poses")
    values = np.hstack([arr[:, :3, 3], Rotation.from_matrix(arr[:, :3, :3]).as_quat()]) if len(arr) else \
        np.zeros((0, 7))
    rows = " ".join(["%.9f"] * 7)
    return "# timestamp tx ty tz qx qy qz qw\n" + "".join(
        f"{stamp} {rows % tuple(row)}\n" for stamp, row in zip(stamps, values.tolist()))


def kitti_text(poses: Sequence[np.ndarray] | np.ndarray) -> str:
    """The KITTI file's text: the 3x4 ``[R | t]`` of each pose, row-major, 12 numbers a line (9 decimals)."""
    arr = as_poses(poses)
    row = " ".join(["%.9f"] * 12)
    return "".join(f"{row % tuple(values)}\n" for values in arr[:, :3, :].reshape(-1, 12).tolist())


def write_tum(path: PathLike, stamps_ns: Sequence[int] | np.ndarray, poses: Sequence[np.ndarray] | np.ndarray
              ) -> Path:
    """Write a TUM file atomically, its folder created when missing."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_text(path, tum_text(stamps_ns, poses))


def write_kitti(path: PathLike, poses: Sequence[np.ndarray] | np.ndarray) -> Path:
    """Write a KITTI poses file atomically, its folder created when missing."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_text(path, kitti_text(poses))


def trajectory_format(path: PathLike) -> str:
    """"tum" or "kitti" by the suffix of ``path``; ValueError naming the suffixes for another one."""
    suffix = Path(path).suffix.lower()
    if suffix not in TRAJECTORY_FORMATS:
        known = ", ".join(f"{s} ({f.upper()})" for s, f in TRAJECTORY_FORMATS.items())
        raise ValueError(f"unknown trajectory suffix {suffix!r} in {path}: use {known}")
    return TRAJECTORY_FORMATS[suffix]


def write_trajectory(path: PathLike, stamps_ns: Sequence[int] | np.ndarray,
                     poses: Sequence[np.ndarray] | np.ndarray) -> Path:
    """Write a TUM or KITTI file by the suffix of ``path`` (:func:`trajectory_format`)."""
    if trajectory_format(path) == "kitti":
        return write_kitti(path, poses)
    return write_tum(path, stamps_ns, poses)


def write_columns(path: PathLike, stamps_ns: Sequence[int] | np.ndarray,
                  columns: Mapping[str, np.ndarray]) -> Path:
    """A CSV of per-pose values: ``stamp`` (as in the TUM file, so the two join on it) then ``columns`` (booleans
    as 0 / 1), one row per pose, written atomically."""
    stamps = stamp_texts(stamps_ns)
    cells = [[str(int(v)) if isinstance(v, bool) else repr(v) for v in np.asarray(c).tolist()]
             for c in columns.values()]
    if any(len(c) != len(stamps) for c in cells):
        raise ValueError("every column needs one value per stamp")
    lines = [",".join(["stamp", *columns])] + [",".join(row) for row in zip(stamps, *cells)]
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_text(path, "\n".join(lines) + "\n")


def read_tum(path: PathLike) -> tuple[np.ndarray, np.ndarray]:
    """A TUM file -> (stamps_ns (n,) int64, poses (n, 4, 4)); ValueError naming the line of a malformed one."""
    stamps, values = [], []
    for lineno, line in enumerate(Path(path).read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        if len(parts) != 8:
            raise ValueError(f"{path}:{lineno}: expected 8 columns, got {len(parts)}")
        try:
            values.append([float(v) for v in parts[1:]])
            sec, _, frac = parts[0].partition(".")
            stamps.append(int(sec) * NS + int((frac + "000000000")[:9] or 0))
        except ValueError as err:
            raise ValueError(f"{path}:{lineno}: {err}") from None
    table = np.asarray(values, dtype=np.float64).reshape(-1, 7)
    poses = np.tile(np.eye(4), (len(table), 1, 1))
    if len(table):
        poses[:, :3, :3] = Rotation.from_quat(table[:, 3:]).as_matrix()
        poses[:, :3, 3] = table[:, :3]
    return np.asarray(stamps, dtype=np.int64), poses


def read_kitti(path: PathLike) -> np.ndarray:
    """A KITTI poses file -> poses (n, 4, 4); ValueError for a line without 12 numbers."""
    rows = [line.split() for line in Path(path).read_text().splitlines() if line.strip()]
    bad = next((k for k, row in enumerate(rows, 1) if len(row) != 12), None)
    if bad is not None:
        raise ValueError(f"{path}:{bad}: expected 12 numbers, got {len(rows[bad - 1])}")
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :] = np.asarray(rows, dtype=np.float64).reshape(-1, 3, 4)
    return poses
