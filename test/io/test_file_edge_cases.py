"""Every PCD/PLY/NPY edge case gives a PointCloudFileError (a ValueError) naming the file and the problem, in one
line, never an IndexError/struct.error/UnicodeDecodeError traceback nor a silently wrong cloud."""
import io
import struct
import warnings
import zipfile

import numpy as np
import pytest

from cemnet_ros.io.pointcloud_files import PointCloudFileError, read_points

POINTS = np.random.default_rng(7).normal(size=(50, 3))


def _ply_header(fmt: str, n: int, props: str) -> bytes:
    return f"ply\nformat {fmt} 1.0\nelement vertex {n}\n{props}end_header\n".encode()


def _pcd(fields: str = "x y z", size: str = "4 4 4", typ: str = "F F F", count: str = "1 1 1", points: str = "2",
         data: str = "ascii", body: bytes = b"1 2 3\n4 5 6\n", extra: str = "") -> bytes:
    header = f"VERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {typ}\nCOUNT {count}\n{extra}"
    return (header + (f"POINTS {points}\n" if points is not None else "") + f"DATA {data}\n").encode() + body


def _npy(array: np.ndarray, **kwargs) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array, **kwargs)
    return buf.getvalue()


def _npz(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def _zip(**members: str) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as archive:
        for name, text in members.items():
            archive.writestr(f"{name}.npy", text)
    return buf.getvalue()


XYZ_PROPS = "property float x\nproperty float y\nproperty float z\n"
_COMPRESSED_ZERO = struct.pack("<II", 0, 0)
EDGE_CASES = {  # name -> (file name, content, what the message says)
    # PCD: count 0 / POINTS 0 in every DATA kind
    "pcd_count0_ascii": ("a.pcd", _pcd(count="0 1 1", body=b"2 3\n5 6\n"), "COUNT 0"),
    "pcd_count0_binary": ("a.pcd", _pcd(count="0 1 1", data="binary", body=b"\0" * 16), "COUNT 0"),
    "pcd_count0_compressed": ("a.pcd", _pcd(count="1 0 1", data="binary_compressed", body=_COMPRESSED_ZERO),
                              "COUNT 0"),
    "pcd_points0_ascii": ("a.pcd", _pcd(points="0", body=b""), "0 points"),
    "pcd_points0_binary": ("a.pcd", _pcd(points="0", data="binary", body=b""), "0 points"),
    "pcd_points0_compressed": ("a.pcd", _pcd(points="0", data="binary_compressed", body=_COMPRESSED_ZERO),
                               "0 points"),
    "pcd_width0": ("a.pcd", _pcd(points=None, extra="WIDTH 0\nHEIGHT 1\n", body=b""), "0 points"),
    # PCD: truncated data
    "pcd_truncated_binary": ("a.pcd", _pcd(data="binary", body=b"\0" * 23), "truncated PCD: 23 data bytes"),
    "pcd_truncated_ascii": ("a.pcd", _pcd(points="3"), "truncated PCD: expected 3 points"),
    "pcd_truncated_compressed_sizes": ("a.pcd", _pcd(data="binary_compressed", body=b"\0\0\0"), "no size words"),
    "pcd_compressed_too_small": ("a.pcd", _pcd(data="binary_compressed", body=struct.pack("<II", 1, 4) + b"\0"),
                                 "4 uncompressed bytes, the 2 points need 24"),
    "pcd_compressed_corrupt_lzf": ("a.pcd", _pcd(data="binary_compressed",
                                                 body=struct.pack("<II", 2, 24) + bytes([0x20, 5])),
                                   "corrupt binary_compressed PCD: corrupt LZF"),
    # PCD: header
    "pcd_no_xyz": ("a.pcd", _pcd(fields="a b c"), "no fields ['x', 'y', 'z']"),
    "pcd_no_z": ("a.pcd", _pcd(fields="x y w"), "no fields ['z']"),
    "pcd_no_fields_line": ("a.pcd", b"VERSION 0.7\nPOINTS 1\nDATA ascii\n1 2 3\n", "no FIELDS line"),
    "pcd_unknown_data": ("a.pcd", _pcd(data="binary_lz4"), "unsupported PCD DATA kind 'binary_lz4'"),
    "pcd_data_without_kind": ("a.pcd", _pcd(data=""), "unsupported PCD DATA kind ''"),
    "pcd_no_data_line": ("a.pcd", b"FIELDS x y z\nPOINTS 1\n1 2 3\n", "not terminated"),
    "pcd_size_not_numeric": ("a.pcd", _pcd(size="4 four 4"), "SIZE must be an integer, got 'four'"),
    "pcd_count_not_numeric": ("a.pcd", _pcd(count="1 1 x"), "COUNT must be an integer"),
    "pcd_count_negative": ("a.pcd", _pcd(count="1 -1 1"), "COUNT must be >= 0"),
    "pcd_points_not_numeric": ("a.pcd", _pcd(points="many"), "POINTS must be an integer"),
    "pcd_points_without_value": ("a.pcd", _pcd(points=""), "POINTS must have one value"),
    "pcd_width_not_numeric": ("a.pcd", _pcd(points=None, extra="WIDTH w\n"), "WIDTH must be an integer"),
    "pcd_size_length": ("a.pcd", _pcd(size="4 4"), "lengths differ (3 fields, 2 sizes"),
    "pcd_type_length": ("a.pcd", _pcd(typ="F F F F"), "lengths differ (3 fields, 3 sizes, 4 types"),
    "pcd_count_length": ("a.pcd", _pcd(count="1"), "lengths differ"),
    "pcd_type_size": ("a.pcd", _pcd(size="2 4 4"), "unsupported PCD TYPE/SIZE combination"),
    "pcd_non_text_header": ("a.pcd", b"FIELDS x y \xff\nDATA ascii\n", "non-text bytes"),
    "pcd_ragged_ascii": ("a.pcd", _pcd(body=b"1 2 3\n4 5\n"), "corrupt PCD ascii data"),
    "pcd_non_numeric_ascii": ("a.pcd", _pcd(body=b"1 2 3\n4 five 6\n"), "corrupt PCD ascii data"),
    "pcd_nan_only": ("a.pcd", _pcd(body=b"nan nan nan\n1 inf 2\n"), "no (finite) points: all 2"),
    # PLY
    "ply_0_vertices_ascii": ("a.ply", _ply_header("ascii", 0, XYZ_PROPS), "0 vertices"),
    "ply_0_vertices_binary": ("a.ply", _ply_header("binary_little_endian", 0, XYZ_PROPS), "0 vertices"),
    "ply_truncated_binary": ("a.ply", _ply_header("binary_big_endian", 2, XYZ_PROPS) + b"\0" * 13,
                             "truncated PLY: 13 data bytes, the header promises 24"),
    "ply_unsupported_type": ("a.ply", _ply_header("ascii", 1, "property int128 x\nproperty float y\n"
                                                             "property float z\n") + b"1 2 3\n",
                             "unsupported PLY property type 'int128' (property x"),
    "ply_unsupported_list_type": ("a.ply", _ply_header("ascii", 1, XYZ_PROPS + "property list uchar quad v\n")
                                  + b"1 2 3 0\n", "unsupported PLY property type 'quad' (property v"),
    "ply_no_vertex": ("a.ply", b"ply\nformat ascii 1.0\nelement face 0\nend_header\n", "no vertex element"),
    "ply_no_format": ("a.ply", b"ply\nelement vertex 1\n" + XYZ_PROPS.encode() + b"end_header\n1 2 3\n",
                      "no format line"),
    "ply_negative_count": ("a.ply", _ply_header("ascii", -2, XYZ_PROPS), "must be >= 0"),
    "ply_missing_z": ("a.ply", _ply_header("ascii", 1, "property float x\nproperty float y\n") + b"1 2\n",
                      "lacks properties ['z']"),
    "ply_nan_only": ("a.ply", _ply_header("ascii", 1, XYZ_PROPS) + b"nan 1 2\n", "no (finite) points"),
    # NPY / NPZ / KITTI .bin
    "npy_one_column": ("a.npy", _npy(np.zeros((4, 1))), "expected an (n, 3+) array of points, got shape (4, 1)"),
    "npy_3d": ("a.npy", _npy(np.zeros((2, 3, 3))), "got shape (2, 3, 3)"),
    "npy_object": ("a.npy", _npy(np.array([[object()] * 3], dtype=object), allow_pickle=True), "cannot read .npy"),
    "npy_strings": ("a.npy", _npy(np.array([["a", "b", "c"]])), "numeric (integer or float) array"),
    "npy_bool": ("a.npy", _npy(np.ones((2, 3), dtype=bool)), "numeric (integer or float) array"),
    "npy_complex": ("a.npy", _npy(np.ones((2, 3), dtype=complex)), "numeric (integer or float) array"),
    "npy_structured": ("a.npy", _npy(np.zeros(2, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])), "shape (2,)"),
    "npy_0_rows": ("a.npy", _npy(np.zeros((0, 3))), "0 rows"),
    "npy_truncated": ("a.npy", _npy(POINTS)[:-10], "cannot read .npy"),
    "npy_not_numpy": ("a.npy", b"1 2 3\n", "cannot read .npy"),
    "npy_is_npz": ("a.npy", _npz(points=POINTS), "it is an .npz archive"),
    "npz_0_rows": ("a.npz", _npz(points=np.zeros((0, 4))), "0 rows"),
    "npz_object": ("a.npz", _npz(points=np.array([object()], dtype=object)), "cannot read array 'points'"),
    "npz_is_npy": ("a.npz", _npy(POINTS), "not an .npz archive"),
    "npz_member_not_npy": ("a.npz", _zip(points="1 2 3\n"), "holds bytes, not a numpy array"),
    "bin_truncated": ("a.bin", POINTS.astype("<f4").tobytes()[:-4], "not a multiple of 16"),
    "bin_nan_only": ("a.bin", np.full((3, 4), np.nan, dtype="<f4").tobytes(), "no (finite) points"),
    # any format: an empty file
    **{f"empty_{ext}": (f"a.{ext}", b"", "empty file (0 bytes)") for ext in ("pcd", "ply", "npy", "npz", "bin")},
}


@pytest.mark.parametrize("name", sorted(EDGE_CASES))
def test_edge_cases_give_a_typed_error_naming_the_file(tmp_path, name):
    filename, content, message = EDGE_CASES[name]
    path = tmp_path / filename
    path.write_bytes(content)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the error says it all: no warning before it
        with pytest.raises(PointCloudFileError) as info:
            read_points(path)
    assert isinstance(info.value, ValueError) and info.value.path == path
    text = str(info.value)
    assert text.startswith(f"{path}: ") and message in text, text
    assert "\n" not in text


def test_pcd_count0_of_another_field_and_binary_with_padding_field(tmp_path):
    """COUNT 0 is refused only for x, y, z: a field without values elsewhere takes no bytes."""
    body = b"".join(struct.pack("<fffB", *p, 7) for p in POINTS[:4])
    path = tmp_path / "pad.pcd"
    path.write_bytes(_pcd("x y z rgb _", "4 4 4 4 1", "F F F F U", "1 1 1 0 1", "4", "binary", body))
    np.testing.assert_allclose(read_points(path), POINTS[:4].astype(np.float32))
    path.write_bytes(_pcd("x y z rgb", "4 4 4 4", "F F F F", "1 1 1 0", "1", "ascii", b"1 2 3\n"))
    np.testing.assert_array_equal(read_points(path), [[1, 2, 3]])
