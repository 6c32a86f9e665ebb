"""What ``~/save_map`` and ``~/save_trajectory`` write, and where, as plain code: the service only answers.

A path parameter (``save_map_path``, ``save_trajectory_path``) is a file name or a path; ``{time}`` in it becomes
the local date and time (``20260102_153000``), ``~`` the home folder, and a relative one lies in
``save_directory`` (``''``: ``$ROS_HOME/cemnet_ros``, else ``~/.ros/cemnet_ros``). The suffix picks the format
(``.pcd``/``.ply``; ``.tum``/``.txt``/``.kitti``). Folders are created, files written atomically, and every
failure (an unknown suffix, a folder that cannot be made, permission denied, a full disk) is one line in the
:class:`Saved` answer, never an exception.
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Optional

import numpy as np

from cemnet_ros.io.pointcloud_files import WRITTEN_SUFFIXES, write_points
from cemnet_ros.io.trajectory_files import trajectory_format, write_columns, write_trajectory
from cemnet_ros.runtime.trajectory_log import Trajectory

FLAGS_SUFFIX = ".flags.csv"


@dataclass
class Saved:
    """A service's answer: whether the file was written, and one line saying where or why not."""

    success: bool
    message: str


def save_directory(value: str, environ: Mapping[str, str] = os.environ) -> Path:
    """The folder of relative save paths: ``value`` (``~`` expanded), or for ``''`` ROS's home's ``cemnet_ros``."""
    if value.strip():
        return Path(value).expanduser()
    return Path(environ.get("ROS_HOME") or Path.home() / ".ros").expanduser() / "cemnet_ros"


def save_path(template: str, directory: str, now: Optional[time.struct_time] = None) -> Path:
    """The absolute path a path parameter names (``{time}``, ``~``, relative to :func:`save_directory`)."""
    name = template.strip().replace("{time}", time.strftime("%Y%m%d_%H%M%S", now or time.localtime()))
    if not name:
        raise ValueError("the path parameter is empty")
    return (save_directory(directory) / Path(name).expanduser()).absolute()


def flags_path(trajectory_path: Path) -> Path:
    """Where the flags of a trajectory file go: ``run.tum`` -> ``run.flags.csv``."""
    return trajectory_path.with_suffix(FLAGS_SUFFIX)


def save_map(points: Optional[np.ndarray], template: str, directory: str, frame: str) -> Saved:
    """Write the local map's points (``(n, 3)`` in ``frame``; None: no map yet)."""
    if points is None:
        return Saved(False, "no map yet: no scan has been registered")
    try:
        path = save_path(template, directory)
        if path.suffix.lower() not in WRITTEN_SUFFIXES:
            raise ValueError(f"unknown map suffix {path.suffix!r} in {path}: use .pcd (binary PCD) or .ply")
    except ValueError as exc:
        return Saved(False, f"map not saved: {exc}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_points(path, points)
    except OSError as exc:
        return Saved(False, f"map not saved: {_cannot_write(path, exc)}")
    return Saved(True, f"wrote {len(points)} map points ({frame}) to {path}")


def save_trajectory(trajectory: Trajectory, template: str, directory: str, frame: str, child: str) -> Saved:
    """Write the published poses (``child`` in ``frame``) as TUM or KITTI, and their flags beside them."""
    n = len(trajectory.stamps_ns)
    if n == 0:
        return Saved(False, "no trajectory yet: no scan has been processed")
    try:
        path = save_path(template, directory)
        kind = trajectory_format(path)
    except ValueError as exc:
        return Saved(False, f"trajectory not saved: {exc}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_trajectory(path, trajectory.stamps_ns, trajectory.poses)
        flags = write_columns(flags_path(path), trajectory.stamps_ns, {
            "accepted": trajectory.accepted, "degenerate": trajectory.degenerate,
            "recovered": trajectory.recovered, "fitness": np.round(trajectory.fitness, 4)})
    except OSError as exc:
        return Saved(False, f"trajectory not saved: {_cannot_write(path, exc)}")
    flagged = n - int(trajectory.accepted.sum())
    message = (f"wrote {n} poses of {child} in {frame} ({flagged} flagged) as {kind.upper()} to {path}, their "
               f"flags to {flags}")
    if trajectory.dropped:
        message += f"; the {trajectory.dropped} oldest poses were dropped before (trajectory_max_poses)"
    return Saved(True, message)


def _cannot_write(path: Path, exc: OSError) -> str:
    """One line: the file, the system's words, and the folder that failed when it is not the file's own."""
    blocking = next((p for p in (path.parent, *path.parent.parents) if p.exists() and not p.is_dir()), None)
    if blocking is not None:
        return f"cannot write {path}: {blocking} is a file, not a folder"
    where = Path(exc.filename) if exc.filename is not None else path
    at = "" if where in (path, path.parent) or where.parent == path.parent else f" (at {where})"
    return f"cannot write {path}: {(exc.strerror or str(exc)).lower()}{at}"
