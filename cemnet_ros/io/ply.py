"""PLY point clouds: read the vertices' x, y, z (ascii, binary little/big endian); write binary PLY."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import List, Optional

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

# PLY scalar type names (both spellings) -> numpy base type.
PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_BYTE_ORDERS = {"binary_little_endian": "<", "binary_big_endian": ">"}
_FORMATS = ("ascii", *_BYTE_ORDERS)


@dataclass
class _Property:
    name: str
    type: str  # scalar type, or the item type of a list
    is_list: bool = False


@dataclass
class _Element:
    name: str
    count: int
    props: List[_Property] = field(default_factory=list)


def _property(path: Path, words: List[str], line: str) -> _Property:
    """One ``property <type> <name>`` or ``property list <count type> <item type> <name>`` line."""
    if len(words) == 5 and words[1] == "list":
        types, name, is_list = words[2:4], words[4], True
    elif len(words) == 3:
        types, name, is_list = words[1:2], words[2], False
    else:
        raise PointCloudFileError(path, f"malformed PLY property line {line!r}")
    unknown = [t for t in types if t not in PLY_TYPES]
    if unknown:
        raise PointCloudFileError(path, f"unsupported PLY property type {unknown[0]!r} (property {name}; "
                                        f"supported: {', '.join(PLY_TYPES)})")
    return _Property(name, types[-1], is_list)


def _parse_header(path: Path, lines: List[str]) -> tuple[str, List[_Element]]:
    """(format, elements) of a PLY header (lines from ``ply`` to ``end_header``)."""
    if not lines or lines[0] != "ply":
        raise PointCloudFileError(path, "not a PLY file (first line is not 'ply')")
    fmt: Optional[str] = None
    elements: List[_Element] = []
    for line in lines[1:-1]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format":
            if len(words) < 2 or words[1] not in _FORMATS:
                raise PointCloudFileError(path, f"unsupported PLY format line {line!r}")
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3:
            elements.append(_Element(words[1], to_int(words[2], f"element {words[1]} count", path)))
        elif words[0] == "property" and elements:
            elements[-1].props.append(_property(path, words, line))
        else:
            raise PointCloudFileError(path, f"malformed PLY header line {line!r}")
    if fmt is None:
        raise PointCloudFileError(path, "PLY header has no format line")
    return fmt, elements


def read_ply(path: Path, raw: bytes) -> np.ndarray:
    """x, y, z of every vertex (float64, NaN rows kept for the caller to drop)."""
    lines, body = read_header(path, raw, lambda line: line == "end_header")
    fmt, elements = _parse_header(path, lines)
    names = [e.name for e in elements]
    if "vertex" not in names:
        raise PointCloudFileError(path, "PLY file has no vertex element")
    index = names.index("vertex")
    vertex = elements[index]
    missing = [axis for axis in "xyz" if axis not in [p.name for p in vertex.props]]
    if missing:
        raise PointCloudFileError(path, f"PLY vertex element lacks properties {missing}")
    if vertex.count == 0:
        raise PointCloudFileError(path, "PLY has 0 vertices: no points")
    if fmt == "ascii":
        return _ascii(path, body, elements[:index], vertex)
    return _binary(path, body, _BYTE_ORDERS[fmt], elements[:index], vertex)


def _ascii(path: Path, body: bytes, before: List[_Element], vertex: _Element) -> np.ndarray:
    rows = [r for r in body.decode("ascii", errors="replace").splitlines() if r.strip()]
    skip, count, props = sum(e.count for e in before), vertex.count, vertex.props
    if len(rows) < skip + count:
        raise PointCloudFileError(path, f"truncated PLY: expected {count} vertex lines, found "
                                        f"{max(0, len(rows) - skip)}")
    if any(p.is_list for p in props):  # list properties make the column of x/y/z row dependent
        return _ascii_with_lists(path, rows[skip:skip + count], props)
    columns = {p.name: i for i, p in enumerate(props)}
    try:
        table = np.array([r.split() for r in rows[skip:skip + count]], dtype=np.float64)
    except ValueError:
        raise PointCloudFileError(path, "corrupt PLY vertex data (ragged or non-numeric rows)") from None
    if table.ndim != 2 or table.shape[1] != len(props):
        raise PointCloudFileError(path, f"corrupt PLY vertex data: expected {len(props)} values per row")
    return table[:, [columns["x"], columns["y"], columns["z"]]]


def _ascii_with_lists(path: Path, rows: List[str], props: List[_Property]) -> np.ndarray:
    out = np.empty((len(rows), 3))
    for r, row in enumerate(rows):
        words, pos, values = row.split(), 0, {}
        try:
            for prop in props:
                if prop.is_list:
                    pos += 1 + int(words[pos])
                else:
                    values[prop.name] = float(words[pos])
                    pos += 1
            out[r] = values["x"], values["y"], values["z"]
        except (IndexError, ValueError):
            raise PointCloudFileError(path, f"corrupt PLY vertex row {r}: {row[:80]!r}") from None
    return out


def _binary(path: Path, body: bytes, order: str, before: List[_Element], vertex: _Element) -> np.ndarray:
    offset = 0
    for element in before:  # skip preceding elements (fixed-size records only)
        if any(p.is_list for p in element.props):
            raise PointCloudFileError(path, f"binary PLY element {element.name!r} before the vertices has list "
                                            "properties (not supported)")
        offset += element.count * sum(np.dtype(PLY_TYPES[p.type]).itemsize for p in element.props)
    if any(p.is_list for p in vertex.props):
        raise PointCloudFileError(path, "binary PLY vertex element with list properties is not supported")
    dtype = np.dtype([(f"p{i}_{p.name}", order + PLY_TYPES[p.type]) for i, p in enumerate(vertex.props)])
    needed = offset + vertex.count * dtype.itemsize
    if len(body) < needed:
        raise PointCloudFileError(path, f"truncated PLY: {len(body)} data bytes, the header promises {needed}")
    table = np.frombuffer(body, dtype=dtype, count=vertex.count, offset=offset)
    fields = {p.name: f"p{i}_{p.name}" for i, p in enumerate(vertex.props)}
    return xyz_float64([table[fields[a]] for a in "xyz"])


def write_ply(path: PathLike, points: np.ndarray, dtype: type = np.float32) -> Path:
    """Write ``(n, 3)`` points as a binary little-endian PLY (float32 or float64 x, y, z), atomically."""
    data = xyz_little_endian(points, dtype, "write_ply")
    scalar = "float" if data.dtype.itemsize == 4 else "double"
    header = ("ply\nformat binary_little_endian 1.0\ncomment written by cemnet_ros\n"
              f"element vertex {len(data)}\n"
              + "".join(f"property {scalar} {axis}\n" for axis in "xyz")
              + "end_header\n")
    return write_cloud_file(path, header, data)
