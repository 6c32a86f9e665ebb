"""Point clouds stored as arrays: numpy ``.npy`` / ``.npz`` (first 3 columns) and KITTI ``.bin`` scans."""
from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np

from cemnet_ros.io.cloud_format import PointCloudFileError

_LOAD_ERRORS = (ValueError, OSError, EOFError, zipfile.BadZipFile)  # np.load on a corrupt or foreign file


def read_npy(path: Path, raw: bytes) -> np.ndarray:
    """An (n, 3+) numeric array; never unpickles (object arrays are refused)."""
    try:
        array = np.load(io.BytesIO(raw), allow_pickle=False)
    except _LOAD_ERRORS as exc:
        raise PointCloudFileError(path, f"cannot read .npy ({exc})") from None
    if isinstance(array, np.lib.npyio.NpzFile):
        array.close()
        raise PointCloudFileError(path, "not a .npy array (it is an .npz archive: rename it to .npz)")
    return xyz_columns(array, path)


def read_npz(path: Path, raw: bytes) -> np.ndarray:
    """The archive's ``points`` array, or its only array, as for .npy."""
    try:
        archive = np.load(io.BytesIO(raw), allow_pickle=False)
    except _LOAD_ERRORS as exc:
        raise PointCloudFileError(path, f"cannot read .npz ({exc})") from None
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise PointCloudFileError(path, "not an .npz archive (it holds a single .npy array)")
    with archive:
        keys = list(archive.files)
        if "points" in keys:
            key = "points"
        elif len(keys) == 1:
            key = keys[0]
        else:
            raise PointCloudFileError(path, f".npz has no 'points' array and {len(keys)} arrays {keys}; "
                                            "cannot tell which one holds the points")
        try:
            array = archive[key]
        except _LOAD_ERRORS as exc:
            raise PointCloudFileError(path, f"cannot read array {key!r} ({exc})") from None
    return xyz_columns(array, path)


def xyz_columns(array: np.ndarray, path: Path) -> np.ndarray:
    """The first three columns of an (n, 3+) integer or float array with n >= 1."""
    if not isinstance(array, np.ndarray):  # e.g. an .npz member that is not a .npy file (np.load gives bytes)
        raise PointCloudFileError(path, f"holds {type(array).__name__}, not a numpy array")
    if array.ndim != 2 or array.shape[1] < 3:
        raise PointCloudFileError(path, f"expected an (n, 3+) array of points, got shape {array.shape}")
    if array.dtype.kind not in "iuf":
        raise PointCloudFileError(path, f"expected a numeric (integer or float) array, got dtype {array.dtype}")
    if len(array) == 0:
        raise PointCloudFileError(path, "the array has 0 rows: no points")
    return array[:, :3]


def read_kitti_bin(path: Path, raw: bytes) -> np.ndarray:
    """A KITTI velodyne scan: float32 x, y, z, reflectance per point."""
    if len(raw) % 16:
        raise PointCloudFileError(path, f"size {len(raw)} bytes is not a multiple of 16: not a KITTI .bin "
                                        "(float32 x, y, z, reflectance) or truncated")
    return np.frombuffer(raw, dtype="<f4").reshape(-1, 4)[:, :3]
