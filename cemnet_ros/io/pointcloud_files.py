"""Read point clouds from common files into ``(n, 3) float64`` arrays; write binary PLY.

Supported: ``.ply`` (ascii, binary little/big endian), ``.pcd`` (ascii, binary, binary_compressed),
``.npy`` / ``.npz`` (key ``points`` or the single array; first 3 columns), KITTI ``.bin``
(float32 x, y, z, reflectance). Only x, y, z are kept. Rows with NaN/inf are dropped with a warning.
Bad input raises ``FileNotFoundError`` or ``ValueError`` with a message naming the file and the problem.
"""
from __future__ import annotations

import warnings
import zipfile
from pathlib import Path
from typing import Callable, Dict, List, Tuple

import numpy as np

from cemnet_ros.io.atomic import PathLike, atomic_write_bytes

# PLY scalar type names (both spellings) -> numpy base type.
_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_PLY_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
_PCD_TYPES = {("F", 4): "f4", ("F", 8): "f8", ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4",
              ("I", 8): "i8", ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8"}
_MAX_HEADER_BYTES = 1 << 16


def read_points(path: PathLike) -> np.ndarray:
    """Read the x, y, z of every point in ``path`` as an ``(n, 3) float64`` array (finite rows only)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"point cloud file not found: {path}")
    if not path.is_file():
        raise ValueError(f"{path} is not a regular file")
    suffix = path.suffix.lower()
    reader = _READERS.get(suffix)
    if reader is None:
        raise ValueError(f"{path}: unknown point cloud extension {suffix!r}; "
                         f"supported: {', '.join(sorted(_READERS))}")
    points = np.asarray(reader(path), dtype=np.float64)
    return _finite_rows(points, path)


def write_ply(path: PathLike, points: np.ndarray, dtype: type = np.float32) -> Path:
    """Write ``(n, 3)`` points as a binary little-endian PLY (float32 or float64 x, y, z), atomically."""
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"write_ply needs an (n, 3) array, got shape {points.shape}")
    dtype = np.dtype(dtype)
    names = {np.dtype(np.float32): "float", np.dtype(np.float64): "double"}
    if dtype not in names:
        raise ValueError(f"write_ply dtype must be float32 or float64, not {dtype}")
    header = ("ply\nformat binary_little_endian 1.0\ncomment written by cemnet_ros\n"
              f"element vertex {len(points)}\n"
              + "".join(f"property {names[dtype]} {axis}\n" for axis in "xyz")
              + "end_header\n")
    body = np.ascontiguousarray(points, dtype=dtype.newbyteorder("<")).tobytes()
    return atomic_write_bytes(path, header.encode("ascii") + body)


def _finite_rows(points: np.ndarray, path: Path) -> np.ndarray:
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"{path}: expected (n, 3) points, got shape {points.shape}")
    finite = np.isfinite(points).all(axis=1)
    n_bad = int((~finite).sum())
    if n_bad:
        warnings.warn(f"{path}: dropped {n_bad} of {len(points)} points with non-finite coordinates",
                      stacklevel=3)
        points = points[finite]
    if len(points) == 0:
        raise ValueError(f"{path}: contains no (finite) points")
    return points


# ----------------------------------------------------------------------------------------------- header
def _read_header(path: Path, terminator: Callable[[str], bool]) -> Tuple[List[str], bytes]:
    """Split a text header (lines up to and including the one ``terminator`` accepts) from the body."""
    raw = path.read_bytes()
    lines: List[str] = []
    pos = 0
    while True:
        end = raw.find(b"\n", pos)
        if end < 0 or end > _MAX_HEADER_BYTES:
            raise ValueError(f"{path}: header is not terminated (truncated or not a point cloud file)")
        try:
            line = raw[pos:end].decode("ascii").strip()
        except UnicodeDecodeError:
            raise ValueError(f"{path}: header contains non-text bytes (corrupt file)") from None
        pos = end + 1
        lines.append(line)
        if terminator(line):
            return lines, raw[pos:]


def _to_int(value: str, what: str, path: Path) -> int:
    try:
        number = int(value)
    except ValueError:
        raise ValueError(f"{path}: {what} must be an integer, got {value!r}") from None
    if number < 0:
        raise ValueError(f"{path}: {what} must be >= 0, got {number}")
    return number


# -------------------------------------------------------------------------------------------------- PLY
def _read_ply(path: Path) -> np.ndarray:
    lines, body = _read_header(path, lambda line: line == "end_header")
    if not lines or lines[0] != "ply":
        raise ValueError(f"{path}: not a PLY file (first line is not 'ply')")
    fmt = None
    elements: List[Tuple[str, int, List[Tuple[str, str, bool]]]] = []  # name, count, [(prop, type, is_list)]
    for line in lines[1:-1]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format":
            if len(words) < 2 or words[1] not in _PLY_FORMATS:
                raise ValueError(f"{path}: unsupported PLY format line {line!r}")
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3:
            elements.append((words[1], _to_int(words[2], f"element {words[1]} count", path), []))
        elif words[0] == "property" and elements:
            if len(words) == 5 and words[1] == "list":
                elements[-1][2].append((words[4], words[3], True))
            elif len(words) == 3 and words[1] in _PLY_TYPES:
                elements[-1][2].append((words[2], words[1], False))
            else:
                raise ValueError(f"{path}: malformed PLY property line {line!r}")
        else:
            raise ValueError(f"{path}: malformed PLY header line {line!r}")
    if fmt is None:
        raise ValueError(f"{path}: PLY header has no format line")
    names = [e[0] for e in elements]
    if "vertex" not in names:
        raise ValueError(f"{path}: PLY file has no vertex element")
    vertex_index = names.index("vertex")
    count, props = elements[vertex_index][1], elements[vertex_index][2]
    prop_names = [p[0] for p in props]
    missing = [axis for axis in "xyz" if axis not in prop_names]
    if missing:
        raise ValueError(f"{path}: PLY vertex element lacks properties {missing}")
    if fmt == "ascii":
        return _ply_ascii(path, body, elements[:vertex_index], count, props)
    return _ply_binary(path, body, _PLY_FORMATS[fmt], elements[:vertex_index], count, props)


def _ply_ascii(path: Path, body: bytes, before: list, count: int, props: list) -> np.ndarray:
    rows = body.decode("ascii", errors="replace").splitlines()
    rows = [r for r in rows if r.strip()]
    skip = sum(e[1] for e in before)
    if len(rows) < skip + count:
        raise ValueError(f"{path}: truncated PLY: expected {count} vertex lines, found {max(0, len(rows) - skip)}")
    if count == 0:
        return np.zeros((0, 3))
    if any(p[2] for p in props):  # list properties make the column of x/y/z row dependent
        return _ply_ascii_with_lists(path, rows[skip:skip + count], props)
    columns = {p[0]: i for i, p in enumerate(props)}
    try:
        table = np.array([r.split() for r in rows[skip:skip + count]], dtype=np.float64)
    except ValueError:
        raise ValueError(f"{path}: corrupt PLY vertex data (ragged or non-numeric rows)") from None
    if table.ndim != 2 or table.shape[1] != len(props):
        raise ValueError(f"{path}: corrupt PLY vertex data: expected {len(props)} values per row")
    return table[:, [columns["x"], columns["y"], columns["z"]]]


def _ply_ascii_with_lists(path: Path, rows: List[str], props: list) -> np.ndarray:
    out = np.empty((len(rows), 3))
    for r, row in enumerate(rows):
        words, pos, values = row.split(), 0, {}
        try:
            for name, _, is_list in props:
                if is_list:
                    pos += 1 + int(words[pos])
                else:
                    values[name] = float(words[pos])
                    pos += 1
            out[r] = values["x"], values["y"], values["z"]
        except (IndexError, ValueError):
            raise ValueError(f"{path}: corrupt PLY vertex row {r}: {row[:80]!r}") from None
    return out


def _ply_binary(path: Path, body: bytes, order: str, before: list, count: int, props: list) -> np.ndarray:
    offset = 0
    for name, n, eprops in before:  # skip preceding elements (fixed-size records only)
        if any(p[2] for p in eprops):
            raise ValueError(f"{path}: binary PLY element {name!r} before the vertices has list properties "
                             "(not supported)")
        offset += n * sum(np.dtype(_PLY_TYPES[p[1]]).itemsize for p in eprops)
    if any(p[2] for p in props):
        raise ValueError(f"{path}: binary PLY vertex element with list properties is not supported")
    dtype = np.dtype([(f"p{i}_{p[0]}", order + _PLY_TYPES[p[1]]) for i, p in enumerate(props)])
    needed = offset + count * dtype.itemsize
    if len(body) < needed:
        raise ValueError(f"{path}: truncated PLY: {len(body)} data bytes, the header promises {needed}")
    table = np.frombuffer(body, dtype=dtype, count=count, offset=offset)
    fields = {p[0]: f"p{i}_{p[0]}" for i, p in enumerate(props)}
    return np.stack([table[fields[a]].astype(np.float64) for a in "xyz"], axis=1)


# -------------------------------------------------------------------------------------------------- PCD
def _read_pcd(path: Path) -> np.ndarray:
    lines, body = _read_header(path, lambda line: line.upper().startswith("DATA"))
    header: Dict[str, List[str]] = {}
    for line in lines:
        words = line.split()
        if words and not words[0].startswith("#"):
            header[words[0].upper()] = words[1:]
    fields = header.get("FIELDS")
    if not fields:
        raise ValueError(f"{path}: PCD header has no FIELDS line")
    missing = [axis for axis in "xyz" if axis not in fields]
    if missing:
        raise ValueError(f"{path}: PCD has no fields {missing} (fields: {fields})")
    nf = len(fields)
    sizes = [_to_int(v, "SIZE", path) for v in header.get("SIZE", ["4"] * nf)]
    types = [t.upper() for t in header.get("TYPE", ["F"] * nf)]
    counts = [_to_int(v, "COUNT", path) for v in header.get("COUNT", ["1"] * nf)]
    if not len(sizes) == len(types) == len(counts) == nf:
        raise ValueError(f"{path}: PCD FIELDS/SIZE/TYPE/COUNT lengths differ")
    if "POINTS" in header:
        n = _to_int(header["POINTS"][0], "POINTS", path)
    else:
        n = _to_int(header.get("WIDTH", ["0"])[0], "WIDTH", path) * _to_int(header.get("HEIGHT", ["1"])[0],
                                                                             "HEIGHT", path)
    mode = header["DATA"][0].lower() if header.get("DATA") else ""
    try:
        dtypes = [np.dtype("<" + _PCD_TYPES[(t, s)]) for t, s in zip(types, sizes)]
    except KeyError:
        raise ValueError(f"{path}: unsupported PCD TYPE/SIZE combination {list(zip(types, sizes))}") from None
    if mode == "ascii":
        return _pcd_ascii(path, body, fields, counts, n)
    if mode == "binary":
        record = np.dtype([(f"f{i}", dt, (c,)) for i, (dt, c) in enumerate(zip(dtypes, counts))])
        if len(body) < n * record.itemsize:
            raise ValueError(f"{path}: truncated PCD: {len(body)} data bytes, expected {n * record.itemsize}")
        table = np.frombuffer(body, dtype=record, count=n)
        return np.stack([table[f"f{fields.index(a)}"][:, 0].astype(np.float64) for a in "xyz"], axis=1)
    if mode == "binary_compressed":
        return _pcd_compressed(path, body, fields, dtypes, counts, n)
    raise ValueError(f"{path}: unsupported PCD DATA mode {mode!r} (ascii, binary, binary_compressed)")


def _pcd_ascii(path: Path, body: bytes, fields: List[str], counts: List[int], n: int) -> np.ndarray:
    rows = [r for r in body.decode("ascii", errors="replace").splitlines() if r.strip()]
    if len(rows) < n:
        raise ValueError(f"{path}: truncated PCD: expected {n} points, found {len(rows)}")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    cols = [int(starts[fields.index(a)]) for a in "xyz"]
    if n == 0:
        return np.zeros((0, 3))
    try:
        table = np.array([r.split() for r in rows[:n]], dtype=np.float64)
    except ValueError:
        raise ValueError(f"{path}: corrupt PCD ascii data (ragged or non-numeric rows)") from None
    if table.ndim != 2 or table.shape[1] != sum(counts):
        raise ValueError(f"{path}: corrupt PCD ascii data: expected {sum(counts)} values per row")
    return table[:, cols]


def _pcd_compressed(path: Path, body: bytes, fields: List[str], dtypes: list, counts: List[int],
                    n: int) -> np.ndarray:
    if len(body) < 8:
        raise ValueError(f"{path}: truncated binary_compressed PCD (no size words)")
    compressed_size, raw_size = np.frombuffer(body[:8], dtype="<u4")
    data = body[8:8 + int(compressed_size)]
    if len(data) < compressed_size:
        raise ValueError(f"{path}: truncated binary_compressed PCD: {len(data)} of {compressed_size} bytes")
    raw = lzf_decompress(data, int(raw_size))
    offset = 0
    columns = {}
    for name, dt, c in zip(fields, dtypes, counts):  # the decompressed data is stored field by field
        size = n * c * dt.itemsize
        if offset + size > len(raw):
            raise ValueError(f"{path}: corrupt binary_compressed PCD: field {name!r} runs past the data")
        columns[name] = np.frombuffer(raw, dtype=dt, count=n * c, offset=offset).reshape(n, c)[:, 0]
        offset += size
    return np.stack([columns[a].astype(np.float64) for a in "xyz"], axis=1)


def lzf_decompress(data: bytes, expected_size: int) -> bytes:
    """Decompress LZF (liblzf, as used by PCL's binary_compressed PCD); checks the output size."""
    out = bytearray()
    i, n = 0, len(data)
    try:
        while i < n:
            ctrl = data[i]
            i += 1
            if ctrl < 32:  # literal run of ctrl + 1 bytes
                run = data[i:i + ctrl + 1]
                if len(run) != ctrl + 1:
                    raise IndexError
                out += run
                i += ctrl + 1
                continue
            length = ctrl >> 5
            if length == 7:
                length += data[i]
                i += 1
            ref = len(out) - ((ctrl & 0x1F) << 8) - data[i] - 1
            i += 1
            length += 2
            if ref < 0:
                raise IndexError
            if ref + length <= len(out):
                out += out[ref:ref + length]
            else:  # overlapping back-reference: repeat the pattern
                for k in range(length):
                    out.append(out[ref + k])
    except IndexError:
        raise ValueError("corrupt LZF data (reference or run outside the buffer)") from None
    if len(out) != expected_size:
        raise ValueError(f"corrupt LZF data: {len(out)} bytes decompressed, header says {expected_size}")
    return bytes(out)


# ---------------------------------------------------------------------------------------- numpy / KITTI
def _read_npy(path: Path) -> np.ndarray:
    try:
        array = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise ValueError(f"{path}: cannot read .npy ({exc})") from None
    return _xyz_columns(array, path)


def _read_npz(path: Path) -> np.ndarray:
    try:
        archive = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{path}: cannot read .npz ({exc})") from None
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise ValueError(f"{path}: not an .npz archive (it holds a single .npy array)")
    with archive:
        keys = list(archive.files)
        if "points" in keys:
            key = "points"
        elif len(keys) == 1:
            key = keys[0]
        else:
            raise ValueError(f"{path}: .npz has no 'points' array and {len(keys)} arrays {keys}; "
                             "cannot tell which one holds the points")
        try:
            array = archive[key]
        except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
            raise ValueError(f"{path}: cannot read array {key!r} ({exc})") from None
    return _xyz_columns(array, path)


def _xyz_columns(array: np.ndarray, path: Path) -> np.ndarray:
    if array.ndim != 2 or array.shape[1] < 3:
        raise ValueError(f"{path}: expected an (n, 3+) array of points, got shape {array.shape}")
    if not np.issubdtype(array.dtype, np.number):
        raise ValueError(f"{path}: expected a numeric array, got dtype {array.dtype}")
    return array[:, :3]


def _read_kitti_bin(path: Path) -> np.ndarray:
    raw = path.read_bytes()
    if len(raw) % 16:
        raise ValueError(f"{path}: size {len(raw)} bytes is not a multiple of 16: not a KITTI .bin "
                         "(float32 x, y, z, reflectance) or truncated")
    return np.frombuffer(raw, dtype="<f4").reshape(-1, 4)[:, :3]


_READERS: Dict[str, Callable[[Path], np.ndarray]] = {
    ".ply": _read_ply, ".pcd": _read_pcd, ".npy": _read_npy, ".npz": _read_npz, ".bin": _read_kitti_bin,
}
