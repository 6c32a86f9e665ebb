"""Point cloud file reading/writing: every format, and bad input giving clear errors."""
import struct

import numpy as np
import pytest
from shared_data import KITTI, requires_shared

from cemnet_ros.io.atomic import atomic_write_text
from cemnet_ros.io.pointcloud_files import (
    PointCloudFileError,
    lzf_decompress,
    read_points,
    write_pcd,
    write_ply,
    write_points,
)

RNG = np.random.default_rng(7)
POINTS = RNG.normal(size=(50, 3))


def _ply_header(fmt: str, n: int, props: str, extra: str = "") -> bytes:
    return (f"ply\nformat {fmt} 1.0\ncomment test\n{extra}element vertex {n}\n{props}end_header\n").encode()


def test_write_ply_roundtrip_float32_and_float64(tmp_path):
    write_ply(tmp_path / "a.ply", POINTS)
    np.testing.assert_allclose(read_points(tmp_path / "a.ply"), POINTS.astype(np.float32), rtol=0, atol=0)
    write_ply(tmp_path / "b.ply", POINTS, dtype=np.float64)
    np.testing.assert_array_equal(read_points(tmp_path / "b.ply"), POINTS)
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_write_ply_rejects_bad_shape(tmp_path):
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        write_ply(tmp_path / "bad.ply", np.zeros((4, 2)))


def test_write_pcd_is_a_pcl_binary_file_that_reads_back(tmp_path):
    write_pcd(tmp_path / "a.pcd", POINTS)
    data = (tmp_path / "a.pcd").read_bytes()
    header, body = data.split(b"DATA binary\n")
    assert header.decode().splitlines()[1:] == [  # PCL's order of the header lines (v0.7)
        "VERSION 0.7", "FIELDS x y z", "SIZE 4 4 4", "TYPE F F F", "COUNT 1 1 1", "WIDTH 50", "HEIGHT 1",
        "VIEWPOINT 0 0 0 1 0 0 0", "POINTS 50"]
    assert body == POINTS.astype("<f4").tobytes()
    np.testing.assert_array_equal(read_points(tmp_path / "a.pcd"), POINTS.astype(np.float32))
    write_pcd(tmp_path / "b.pcd", POINTS, dtype=np.float64)
    np.testing.assert_array_equal(read_points(tmp_path / "b.pcd"), POINTS)
    with pytest.raises(ValueError, match="float32 or float64"):
        write_pcd(tmp_path / "c.pcd", POINTS, dtype=np.int32)
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_write_points_picks_the_format_by_suffix(tmp_path):
    for name in ("map.pcd", "map.PLY"):
        write_points(tmp_path / name, POINTS)
        np.testing.assert_array_equal(read_points(tmp_path / name), POINTS.astype(np.float32))
    assert (tmp_path / "map.pcd").read_bytes().startswith(b"# .PCD v0.7")
    assert (tmp_path / "map.PLY").read_bytes().startswith(b"ply\n")
    with pytest.raises(ValueError, match="unknown point cloud suffix '.xyz'.*use .pcd or .ply"):
        write_points(tmp_path / "map.xyz", POINTS)
    assert not (tmp_path / "map.xyz").exists()


def test_written_pcd_loads_in_pypcd4(tmp_path):
    """An independent reader (pypcd4, not a dependency: skipped without it) reads the same points."""
    pypcd4 = pytest.importorskip("pypcd4")
    write_points(tmp_path / "map.pcd", POINTS)
    points = pypcd4.PointCloud.from_path(tmp_path / "map.pcd").numpy(("x", "y", "z"))
    np.testing.assert_array_equal(points, POINTS.astype(np.float32))


def test_written_ply_loads_in_plyfile(tmp_path):
    """An independent reader (plyfile, not a dependency: skipped without it) reads the same points."""
    plyfile = pytest.importorskip("plyfile")
    write_points(tmp_path / "map.ply", POINTS)
    vertex = plyfile.PlyData.read(str(tmp_path / "map.ply"))["vertex"]
    np.testing.assert_array_equal(np.stack([vertex[a] for a in "xyz"], axis=1), POINTS.astype(np.float32))


def test_ply_ascii_with_extra_properties_and_face_element(tmp_path):
    props = "property float nx\nproperty float x\nproperty uchar red\nproperty float y\nproperty float z\n"
    rows = "".join(f"0.5 {p[0]} 255 {p[1]} {p[2]}\n" for p in POINTS[:5])
    face = "element face 1\nproperty list uchar int vertex_indices\n"
    data = _ply_header("ascii", 5, props).replace(b"end_header", face.encode() + b"end_header") + rows.encode()
    data += b"3 0 1 2\n"
    (tmp_path / "a.ply").write_bytes(data)
    np.testing.assert_allclose(read_points(tmp_path / "a.ply"), POINTS[:5], atol=1e-12)


def test_ply_binary_big_endian_double_with_skipped_properties(tmp_path):
    props = "property double x\nproperty double y\nproperty double z\nproperty uchar label\n"
    body = b"".join(struct.pack(">dddB", *p, 3) for p in POINTS)
    (tmp_path / "be.ply").write_bytes(_ply_header("binary_big_endian", len(POINTS), props) + body)
    np.testing.assert_array_equal(read_points(tmp_path / "be.ply"), POINTS)


def test_ply_binary_little_endian_after_other_element(tmp_path):
    props = "property float x\nproperty float y\nproperty float z\n"
    extra = "element camera 2\nproperty float view\nproperty int id\n"
    body = struct.pack("<fifi", 1.0, 1, 2.0, 2) + POINTS.astype("<f4").tobytes()
    (tmp_path / "le.ply").write_bytes(_ply_header("binary_little_endian", len(POINTS), props, extra) + body)
    np.testing.assert_allclose(read_points(tmp_path / "le.ply"), POINTS.astype(np.float32))


def test_truncated_binary_ply(tmp_path):
    write_ply(tmp_path / "t.ply", POINTS)
    data = (tmp_path / "t.ply").read_bytes()
    (tmp_path / "t.ply").write_bytes(data[:-7])
    with pytest.raises(ValueError, match="truncated"):
        read_points(tmp_path / "t.ply")


@pytest.mark.parametrize("content, message", [
    (b"not a ply\nend_header\n", "not a PLY"),
    (b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n", "not terminated"),
    (b"ply\nformat weird 1.0\nelement vertex 1\nend_header\n", "unsupported PLY format"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n",
     "lacks properties"),
    (b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
     b"end_header\n1 2 3\n4 five 6\n", "corrupt"),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
     b"end_header\n1 2 3\n", "truncated"),
    (b"ply\nformat ascii 1.0\nelement vertex many\nend_header\n", "integer"),
])
def test_corrupt_ply(tmp_path, content, message):
    (tmp_path / "c.ply").write_bytes(content)
    with pytest.raises(ValueError, match=message):
        read_points(tmp_path / "c.ply")


def test_nan_rows_dropped_with_warning(tmp_path):
    points = POINTS.copy()
    points[[3, 10]] = np.nan
    points[20, 1] = np.inf
    write_ply(tmp_path / "n.ply", points, dtype=np.float64)
    with pytest.warns(UserWarning, match="dropped 3 of 50"):
        out = read_points(tmp_path / "n.ply")
    assert out.shape == (47, 3)
    np.testing.assert_array_equal(out, np.delete(POINTS, [3, 10, 20], axis=0))


def test_all_nan_is_an_error(tmp_path):
    np.save(tmp_path / "nan.npy", np.full((4, 3), np.nan))
    with pytest.raises(PointCloudFileError, match="no \\(finite\\) points: all 4 have NaN"):
        read_points(tmp_path / "nan.npy")


def test_missing_file_and_unknown_extension(tmp_path):
    with pytest.raises(FileNotFoundError, match="not found"):
        read_points(tmp_path / "nope.ply")
    (tmp_path / "cloud.xyz").write_text("1 2 3\n")
    with pytest.raises(ValueError, match="unknown point cloud extension '.xyz'"):
        read_points(tmp_path / "cloud.xyz")
    with pytest.raises(ValueError, match="not a regular file"):
        read_points(tmp_path)


def test_pcd_ascii_with_count_and_nan(tmp_path):
    header = ("# .PCD v0.7\nVERSION 0.7\nFIELDS rgb x y z normal\nSIZE 4 4 4 4 4\nTYPE F F F F F\n"
              "COUNT 1 1 1 1 3\nWIDTH 4\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA ascii\n")
    rows = "".join(f"0 {p[0]} {p[1]} {p[2]} 0 0 1\n" for p in POINTS[:3]) + "0 nan nan nan 0 0 1\n"
    (tmp_path / "a.pcd").write_text(header + rows)
    with pytest.warns(UserWarning, match="dropped 1"):
        np.testing.assert_allclose(read_points(tmp_path / "a.pcd"), POINTS[:3], atol=1e-12)


def _pcd_binary_header(mode: str, n: int) -> bytes:
    return ("VERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 2\nTYPE F F F U\nCOUNT 1 1 1 1\n"
            f"WIDTH {n}\nHEIGHT 1\nPOINTS {n}\nDATA {mode}\n").encode()


def test_pcd_binary(tmp_path):
    body = b"".join(struct.pack("<fffH", *p, 9) for p in POINTS)
    (tmp_path / "b.pcd").write_bytes(_pcd_binary_header("binary", len(POINTS)) + body)
    np.testing.assert_allclose(read_points(tmp_path / "b.pcd"), POINTS.astype(np.float32))
    (tmp_path / "t.pcd").write_bytes(_pcd_binary_header("binary", len(POINTS)) + body[:-1])
    with pytest.raises(ValueError, match="truncated"):
        read_points(tmp_path / "t.pcd")


def _lzf_literals(data: bytes) -> bytes:
    """A valid LZF stream made of literal runs only (enough to exercise the reader's framing)."""
    out = bytearray()
    for i in range(0, len(data), 32):
        chunk = data[i:i + 32]
        out += bytes([len(chunk) - 1]) + chunk
    return bytes(out)


def test_lzf_back_references():
    # "abc" literal, then a back-reference of length 6 at distance 3 (overlapping: repeats "abc").
    assert lzf_decompress(bytes([2]) + b"abc" + bytes([(4 << 5) | 0, 2]), 9) == b"abcabcabc"
    # long back-reference (length code 7 + extra byte) at distance 1: run-length of one byte
    assert lzf_decompress(bytes([0]) + b"z" + bytes([7 << 5, 3, 0]), 1 + 7 + 3 + 2) == b"z" * 13
    with pytest.raises(ValueError, match="corrupt LZF"):
        lzf_decompress(bytes([(1 << 5) | 0, 5]), 3)  # reference before the start
    with pytest.raises(ValueError, match="header says"):
        lzf_decompress(bytes([2]) + b"abc", 4)


def test_pcd_binary_compressed(tmp_path):
    n = len(POINTS)
    columns = (POINTS[:, 0].astype("<f4").tobytes() + POINTS[:, 1].astype("<f4").tobytes()
               + POINTS[:, 2].astype("<f4").tobytes() + np.full(n, 9, "<u2").tobytes())
    packed = _lzf_literals(columns)
    body = struct.pack("<II", len(packed), len(columns)) + packed
    (tmp_path / "c.pcd").write_bytes(_pcd_binary_header("binary_compressed", n) + body)
    np.testing.assert_allclose(read_points(tmp_path / "c.pcd"), POINTS.astype(np.float32))
    (tmp_path / "bad.pcd").write_bytes(_pcd_binary_header("binary_compressed", n) + body[:-5])
    with pytest.raises(ValueError, match="truncated"):
        read_points(tmp_path / "bad.pcd")


def test_pcd_without_xyz(tmp_path):
    (tmp_path / "a.pcd").write_text("FIELDS a b c\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 1\nDATA ascii\n1 2 3\n")
    with pytest.raises(ValueError, match="no fields"):
        read_points(tmp_path / "a.pcd")


def test_npy_and_npz(tmp_path):
    np.save(tmp_path / "a.npy", np.hstack([POINTS, np.ones((50, 2))]))
    np.testing.assert_array_equal(read_points(tmp_path / "a.npy"), POINTS)
    np.savez(tmp_path / "p.npz", points=POINTS, other=np.zeros(3))
    np.testing.assert_array_equal(read_points(tmp_path / "p.npz"), POINTS)
    np.savez(tmp_path / "single.npz", cloud=POINTS.astype(np.float32))
    np.testing.assert_allclose(read_points(tmp_path / "single.npz"), POINTS.astype(np.float32))
    assert read_points(tmp_path / "single.npz").dtype == np.float64


@pytest.mark.parametrize("array, message", [
    (np.zeros((5, 2)), "shape"), (np.zeros(6), "shape"), (np.zeros((2, 3, 3)), "shape"),
    (np.array([["a", "b", "c"]]), "numeric"),
])
def test_npy_wrong_shapes(tmp_path, array, message):
    np.save(tmp_path / "w.npy", array)
    with pytest.raises(ValueError, match=message):
        read_points(tmp_path / "w.npy")


def test_npz_ambiguous_and_corrupt(tmp_path):
    np.savez(tmp_path / "two.npz", a=POINTS, b=POINTS)
    with pytest.raises(ValueError, match="no 'points' array"):
        read_points(tmp_path / "two.npz")
    (tmp_path / "junk.npz").write_bytes(b"PK\x03\x04 this is not a zip")
    with pytest.raises(ValueError, match="cannot read"):
        read_points(tmp_path / "junk.npz")
    np.save(tmp_path / "obj.npy", np.array([object()], dtype=object), allow_pickle=True)
    with pytest.raises(ValueError, match="cannot read"):
        read_points(tmp_path / "obj.npy")


def test_kitti_bin(tmp_path):
    scan = np.hstack([POINTS, RNG.uniform(size=(50, 1))]).astype("<f4")
    scan.tofile(tmp_path / "000000.bin")
    np.testing.assert_allclose(read_points(tmp_path / "000000.bin"), POINTS.astype(np.float32))
    (tmp_path / "bad.bin").write_bytes(scan.tobytes()[:-4])
    with pytest.raises(ValueError, match="multiple of 16"):
        read_points(tmp_path / "bad.bin")


def test_atomic_write_needs_existing_folder(tmp_path):
    atomic_write_text(tmp_path / "a.txt", "hello")
    assert (tmp_path / "a.txt").read_text() == "hello"
    with pytest.raises(FileNotFoundError):
        atomic_write_text(tmp_path / "missing" / "a.txt", "x")


@requires_shared(KITTI)
def test_real_kitti_scan():
    points = read_points(KITTI / "velodyne" / "000000.bin")
    assert points.shape[1] == 3 and len(points) > 100_000
    assert 20 < np.linalg.norm(points, axis=1).max() < 200  # metres
