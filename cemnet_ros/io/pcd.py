"""PCD point clouds (PCL's format): read the x, y, z of ascii, binary and binary_compressed files; write binary."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List

import numpy as np

from cemnet_ros.io.atomic import PathLike
from cemnet_ros.io.cloud_format import (
    PointCloudFileError,
    read_header,
    to_int,
    write_cloud_file,
    xyz_float64,
    xyz_little_endian,
)
from cemnet_ros.io.lzf import lzf_decompress

_TYPES = {("F", 4): "f4", ("F", 8): "f8", ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4",
          ("I", 8): "i8", ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8"}
_MODES = ("ascii", "binary", "binary_compressed")


@dataclass
class _Header:
    """The parts of a PCD header the readers use, validated."""

    fields: List[str]
    dtypes: List[np.dtype]
    counts: List[int]
    n: int  # points
    mode: str  # one of _MODES

    def column(self, axis: str) -> int:
        """Index of field ``axis`` (x, y or z)."""
        return self.fields.index(axis)


def _entries(lines: List[str]) -> Dict[str, List[str]]:
    """Header keyword (upper case) -> its values; comments skipped."""
    header: Dict[str, List[str]] = {}
    for line in lines:
        words = line.split()
        if words and not words[0].startswith("#"):
            header[words[0].upper()] = words[1:]
    return header


def _single(path: Path, header: Dict[str, List[str]], key: str, default: str) -> int:
    values = header.get(key, [default])
    if len(values) != 1:
        raise PointCloudFileError(path, f"PCD {key} must have one value, got {values}")
    return to_int(values[0], key, path)


def _parse_header(path: Path, lines: List[str]) -> _Header:
    header = _entries(lines)
    fields = header.get("FIELDS")
    if not fields:
        raise PointCloudFileError(path, "PCD header has no FIELDS line")
    missing = [axis for axis in "xyz" if axis not in fields]
    if missing:
        raise PointCloudFileError(path, f"PCD has no fields {missing} (fields: {fields})")
    nf = len(fields)
    sizes = [to_int(v, "SIZE", path) for v in header.get("SIZE", ["4"] * nf)]
    types = [t.upper() for t in header.get("TYPE", ["F"] * nf)]
    counts = [to_int(v, "COUNT", path) for v in header.get("COUNT", ["1"] * nf)]
    if not len(sizes) == len(types) == len(counts) == nf:
        raise PointCloudFileError(path, f"PCD FIELDS/SIZE/TYPE/COUNT lengths differ ({nf} fields, {len(sizes)} "
                                        f"sizes, {len(types)} types, {len(counts)} counts)")
    empty = [axis for axis in "xyz" if counts[fields.index(axis)] == 0]
    if empty:
        raise PointCloudFileError(path, f"PCD field(s) {empty} have COUNT 0 (no value per point)")
    try:
        dtypes = [np.dtype("<" + _TYPES[(t, s)]) for t, s in zip(types, sizes)]
    except KeyError:
        raise PointCloudFileError(path, f"unsupported PCD TYPE/SIZE combination {list(zip(types, sizes))}") from None
    if "POINTS" in header:
        n = _single(path, header, "POINTS", "")
    else:
        n = _single(path, header, "WIDTH", "0") * _single(path, header, "HEIGHT", "1")
    if n == 0:
        raise PointCloudFileError(path, "PCD header says 0 points (POINTS 0 or WIDTH/HEIGHT 0): no points")
    mode = (header.get("DATA") or [""])[0].lower()
    if mode not in _MODES:
        raise PointCloudFileError(path, f"unsupported PCD DATA kind {mode!r} ({', '.join(_MODES)})")
    return _Header(fields, dtypes, counts, n, mode)


def read_pcd(path: Path, raw: bytes) -> np.ndarray:
    """x, y, z of every point (float64, NaN rows kept for the caller to drop)."""
    lines, body = read_header(path, raw, lambda line: line.upper().startswith("DATA"))
    header = _parse_header(path, lines)
    readers = {"ascii": _ascii, "binary": _binary, "binary_compressed": _compressed}
    return readers[header.mode](path, body, header)


def _ascii(path: Path, body: bytes, h: _Header) -> np.ndarray:
    rows = [r for r in body.decode("ascii", errors="replace").splitlines() if r.strip()]
    if len(rows) < h.n:
        raise PointCloudFileError(path, f"truncated PCD: expected {h.n} points, found {len(rows)}")
    starts = np.concatenate([[0], np.cumsum(h.counts)[:-1]])
    try:
        table = np.array([r.split() for r in rows[:h.n]], dtype=np.float64)
    except ValueError:
        raise PointCloudFileError(path, "corrupt PCD ascii data (ragged or non-numeric rows)") from None
    if table.ndim != 2 or table.shape[1] != sum(h.counts):
        raise PointCloudFileError(path, f"corrupt PCD ascii data: expected {sum(h.counts)} values per row")
    return table[:, [int(starts[h.column(a)]) for a in "xyz"]]


def _binary(path: Path, body: bytes, h: _Header) -> np.ndarray:
    record = np.dtype([(f"f{i}", dt, (c,)) for i, (dt, c) in enumerate(zip(h.dtypes, h.counts))])
    if len(body) < h.n * record.itemsize:
        raise PointCloudFileError(path, f"truncated PCD: {len(body)} data bytes, expected {h.n * record.itemsize}")
    table = np.frombuffer(body, dtype=record, count=h.n)
    return xyz_float64([table[f"f{h.column(a)}"][:, 0] for a in "xyz"])


def _compressed(path: Path, body: bytes, h: _Header) -> np.ndarray:
    """binary_compressed: two uint32 sizes, then LZF data holding the points field by field."""
    if len(body) < 8:
        raise PointCloudFileError(path, "truncated binary_compressed PCD (no size words)")
    compressed_size, raw_size = (int(v) for v in np.frombuffer(body[:8], dtype="<u4"))
    data = body[8:8 + compressed_size]
    if len(data) < compressed_size:
        raise PointCloudFileError(path, f"truncated binary_compressed PCD: {len(data)} of {compressed_size} bytes")
    sizes = [h.n * c * dt.itemsize for dt, c in zip(h.dtypes, h.counts)]
    if raw_size < sum(sizes):
        raise PointCloudFileError(path, f"corrupt binary_compressed PCD: {raw_size} uncompressed bytes, the "
                                        f"{h.n} points need {sum(sizes)}")
    try:
        raw = lzf_decompress(data, raw_size)
    except ValueError as exc:
        raise PointCloudFileError(path, f"corrupt binary_compressed PCD: {exc}") from None
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(int)
    columns = [np.frombuffer(raw, dtype=h.dtypes[k], count=h.n * h.counts[k], offset=int(starts[k]))
               .reshape(h.n, h.counts[k])[:, 0] for k in map(h.column, "xyz")]
    return xyz_float64(columns)


def write_pcd(path: PathLike, points: np.ndarray, dtype: type = np.float32) -> Path:
    """Write ``(n, 3)`` points as a binary PCD v0.7 (x, y, z float32 or float64, unorganised, viewpoint at the
    origin), as PCL's ``savePCDFileBinary`` does, atomically."""
    data = xyz_little_endian(points, dtype, "write_pcd")
    size = data.dtype.itemsize
    header = ("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\n"
              f"SIZE {size} {size} {size}\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {len(data)}\nHEIGHT 1\n"
              f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(data)}\nDATA binary\n")
    return write_cloud_file(path, header, data)
