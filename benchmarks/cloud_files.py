"""The project's PLY and PCD readers and writers (``cemnet_ros/io``) against plyfile and pypcd4: which files each
reads right, what each does with the malformed files of ``test/io/test_file_edge_cases.py``, and the time to write
and read a 1M-point cloud.

Correctness is a matrix: every writer's file (ours, and the libraries' layouts: ascii, big endian, doubles, extra
properties, a face element, binary_compressed) read by every reader of that format, compared point by point with
what was written. Timing interleaves the methods per round (``benchmarks/libraries/timing.py``); every writer
writes through the same :func:`~cemnet_ros.io.atomic.atomic_file` (temporary file, fsync, rename), so the
figures compare the formatting, not the syncing.
"""
from __future__ import annotations

import importlib.util
import warnings
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

from benchmarks.libraries.timing import interleaved, timing_summary
from cemnet_ros.io.atomic import atomic_file
from cemnet_ros.io.pointcloud_files import read_points, write_pcd, write_ply

REPO = Path(__file__).resolve().parents[1]
EDGE_CASES_FILE = REPO / "test" / "io" / "test_file_edge_cases.py"
# Edge cases that are well-formed files: all-NaN points (ours refuses them as useless, a library may return them)
# and clouds of 0 points (a library may return an empty array). The rest are malformed and should raise.
WELL_FORMED = ("nan_only", "points0", "0_vertices", "width0")


def edge_cases() -> dict[str, tuple[str, bytes]]:
    """The PLY and PCD cases of test/io/test_file_edge_cases.py: name -> (file name, content). Their PCD headers
    lack WIDTH and HEIGHT, which PCL's format requires and pypcd4 refuses: each gets ``WIDTH <POINTS> HEIGHT 1``
    here, so that a reader is judged on the fault the case is about."""
    spec = importlib.util.spec_from_file_location("file_edge_cases", EDGE_CASES_FILE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return {name: (filename, _with_width(content) if filename.endswith(".pcd") else content)
            for name, (filename, content, _) in module.EDGE_CASES.items() if filename.endswith((".ply", ".pcd"))}


def _with_width(content: bytes) -> bytes:
    """A PCD with a POINTS line and no WIDTH line gets ``WIDTH <the POINTS value>`` and ``HEIGHT 1`` before it."""
    start = content.find(b"\nPOINTS")
    if start < 0 or b"WIDTH" in content:
        return content
    end = content.index(b"\n", start + 1)
    value = content[start + len(b"\nPOINTS"):end].strip() or b"1"
    return content[:start] + b"\nWIDTH " + value + b"\nHEIGHT 1" + content[start:]


# -- readers: path -> (n, 3) float64 -----------------------------------------------------------------------------
def read_plyfile(path: Path) -> np.ndarray:
    from plyfile import PlyData

    vertex = PlyData.read(str(path))["vertex"]
    return np.stack([np.asarray(vertex[a], dtype=np.float64) for a in "xyz"], axis=1)


def read_pypcd4(path: Path) -> np.ndarray:
    from pypcd4 import PointCloud

    return PointCloud.from_path(path).numpy(("x", "y", "z")).astype(np.float64)


def read_ours(path: Path) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # NaN rows dropped: counted as a difference below, not a warning
        return read_points(path)


READERS: dict[str, dict[str, Callable[[Path], np.ndarray]]] = {
    ".ply": {"ours": read_ours, "plyfile": read_plyfile}, ".pcd": {"ours": read_ours, "pypcd4": read_pypcd4}}


# -- writers: (path, points) -> None, through atomic_file --------------------------------------------------------
def _plyfile(path: Path, points: np.ndarray, *, text: bool = False, byte_order: str = "<", dtype: str = "f4",
             extra: bool = False) -> None:
    from plyfile import PlyData, PlyElement

    fields = [(a, dtype) for a in "xyz"] + ([("label", "u1")] if extra else [])
    vertex = np.zeros(len(points), dtype=fields)
    for k, a in enumerate("xyz"):
        vertex[a] = points[:, k]
    elements = [PlyElement.describe(vertex, "vertex")]
    if extra:  # a face element after the vertices, as a mesh file has
        faces = np.zeros(1, dtype=[("vertex_indices", "i4", (3,))])
        faces["vertex_indices"][0] = (0, 1, 2)
        elements.append(PlyElement.describe(faces, "face"))
    with atomic_file(path) as handle:
        PlyData(elements, text=text, byte_order=byte_order).write(handle)


def _pypcd4(path: Path, points: np.ndarray, encoding: str = "binary", rings: bool = False) -> None:
    """pypcd4's file of ``points`` (float32 x, y, z), with ``rings`` also intensity (float32) and ring (uint16)
    fields, as a LiDAR driver's cloud has: LZF shrinks the ring column, so binary_compressed stays compressed
    (pypcd4 silently writes ``binary`` when LZF does not shrink the data, as on x, y, z alone: refused here)."""
    from pypcd4 import Encoding, PointCloud

    if rings:
        index = np.arange(len(points))
        cloud = PointCloud.from_xyzir_points(np.column_stack([points, index % 256, index % 64]))
    else:
        cloud = PointCloud.from_xyz_points(points.astype(np.float32))
    with atomic_file(path) as handle:
        cloud.save(handle, encoding=Encoding(encoding))
    kind = path.read_bytes().split(b"\nDATA ", 1)[1].split(b"\n", 1)[0].decode()
    if kind != encoding:
        raise RuntimeError(f"pypcd4 wrote DATA {kind}, not {encoding}")


WRITERS: dict[str, tuple[str, Callable[[Path, np.ndarray], Any]]] = {  # name -> (suffix, writer)
    "ours float32": (".ply", write_ply),
    "ours float64": (".ply", lambda p, x: write_ply(p, x, dtype=np.float64)),
    "plyfile binary LE float32": (".ply", _plyfile),
    "plyfile binary BE float64": (".ply", lambda p, x: _plyfile(p, x, byte_order=">", dtype="f8")),
    "plyfile ascii float64": (".ply", lambda p, x: _plyfile(p, x, text=True, dtype="f8")),
    "plyfile + label, face element": (".ply", lambda p, x: _plyfile(p, x, extra=True)),
    "ours pcd float32": (".pcd", write_pcd),
    "ours pcd float64": (".pcd", lambda p, x: write_pcd(p, x, dtype=np.float64)),
    "pypcd4 binary": (".pcd", _pypcd4),
    "pypcd4 ascii": (".pcd", lambda p, x: _pypcd4(p, x, "ascii")),
    "pypcd4 binary_compressed, + intensity, ring": (".pcd", lambda p, x: _pypcd4(p, x, "binary_compressed", True)),
}


def _outcome(read: Callable[[Path], np.ndarray], path: Path, expected: Optional[np.ndarray]) -> str:
    """'same', 'differs' or 'error: <type>' (the file should read as ``expected``); for a malformed file
    (``expected`` None): 'error: <type>' or 'returned N points'."""
    try:
        points = read(path)
    except Exception as exc:  # noqa: BLE001 - what each library raises is what is measured
        return f"error: {type(exc).__name__}"
    if expected is None:
        return f"returned {len(points)} points"
    if points.shape != expected.shape:
        return f"differs ({points.shape[0]} points)"
    if np.array_equal(points, expected):
        return "same"
    close = np.allclose(points, expected, rtol=1e-9, atol=1e-9)  # a text file's digits, read as float64
    return "same to 1e-9 (text digits)" if close else "differs"


def cross_reading(folder: Path, points: np.ndarray) -> list[dict]:
    """Every writer's file read by every reader of its format: one row per (writer, reader)."""
    rows = []
    for name, (suffix, write) in WRITERS.items():
        path = folder / f"{name.replace(' ', '_').replace(',', '')}{suffix}"
        write(path, points)
        stored = points if "float64" in name else points.astype(np.float32).astype(np.float64)
        for reader, read in READERS[suffix].items():
            rows.append({"file": name, "reader": reader, "outcome": _outcome(read, path, stored)})
    return rows


def malformed(folder: Path) -> list[dict]:
    """Each PLY/PCD edge case of test/io read by every reader of its format."""
    rows = []
    for name, (filename, content) in sorted(edge_cases().items()):
        path = folder / f"{name}{Path(filename).suffix}"
        path.write_bytes(content)
        for reader, read in READERS[path.suffix].items():
            rows.append({"case": name, "well_formed": any(w in name for w in WELL_FORMED), "reader": reader,
                         "outcome": _outcome(read, path, None)})
    return rows


def timings(folder: Path, points: np.ndarray, rounds: int) -> dict[str, dict]:
    """ms per write and read of ``points`` (float32 x, y, z), ours against the library, interleaved."""
    ply, pcd, compressed = folder / "big.ply", folder / "big.pcd", folder / "big_compressed.pcd"
    cases: dict[str, dict[str, Callable[[], Any]]] = {
        "PLY write (binary LE)": {"ours": lambda: write_ply(ply, points), "plyfile": lambda: _plyfile(ply, points)},
        "PLY read (binary LE)": {"ours": lambda: read_ours(ply), "plyfile": lambda: read_plyfile(ply)},
        "PCD write (binary)": {"ours": lambda: write_pcd(pcd, points), "pypcd4": lambda: _pypcd4(pcd, points)},
        "PCD read (binary)": {"ours": lambda: read_ours(pcd), "pypcd4": lambda: read_pypcd4(pcd)},
        "PCD read (binary_compressed x y z intensity ring, by pypcd4)": {
            "ours": lambda: read_ours(compressed), "pypcd4": lambda: read_pypcd4(compressed)},
    }
    _pypcd4(compressed, points, "binary_compressed", rings=True)
    out = {}
    for case, calls in cases.items():
        for call in calls.values():  # one untimed call each: imports, file cache
            call()
        times: dict[str, list[float]] = {}
        interleaved(calls, rounds, times)
        out[case] = timing_summary(times)
    return out
