"""A corpus of hostile PointCloud2 messages (no ROS import: message classes are passed in).

Each case is built from a valid scan of the stream it is slipped into, so that it looks as real as possible:
malformed layouts, degenerate geometry, stamp faults, data-level faults (a sector, another robot's frame, a
few points of the previous scan), oversized clouds and byte streams that are no serialized PointCloud2 (a
publisher may send raw CDR bytes; ``build`` then returns ``bytes``). The node must reject each one with a
counted reason, or publish it flagged, or (``handled``) process it with a warning; and the valid scans around
them must come out as they would without them. Used by test/ros/test_node_hostile.py and scripts/soak_node.py.
"""
from __future__ import annotations

import copy
import struct
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from cemnet_ros.pointcloud2 import make_pointcloud2

FLOAT32, FLOAT64 = 7, 8
INTEGER_TYPES = (1, 2, 3, 4, 5, 6)
FRAME = "lidar"  # the frame of the valid stream the cases are slipped into (the frame_ cases differ from it)


@dataclass
class Case:
    name: str
    category: str  # layout, geometry, stamp, data, size, cdr
    expect: str  # "rejected", "rejected_or_flagged" or "handled" (processed with a warning)
    build: Callable[[Any, Any, np.ndarray, Any], Any]  # (PointCloud2, PointField, points, stamp) -> message/bytes


def _msg(cls: Any, field_cls: Any, points: np.ndarray, stamp: Any, frame: str = FRAME) -> Any:
    return make_pointcloud2(cls, field_cls, np.asarray(points, dtype=np.float64), frame, stamp)


def _edit(edit: Callable[[Any], None]) -> Callable:
    """A valid message of the scan, then ``edit(msg)`` (layout faults)."""
    def build(cls: Any, field_cls: Any, points: np.ndarray, stamp: Any) -> Any:
        msg = _msg(cls, field_cls, points, stamp)
        msg.fields = [copy.copy(f) for f in msg.fields]
        edit(msg)
        return msg
    return build


def _points(make: Callable[[np.ndarray], np.ndarray], frame: str = FRAME) -> Callable:
    """A message of ``make(scan points)`` (geometry and data faults)."""
    return lambda cls, field_cls, points, stamp: _msg(cls, field_cls, make(points), stamp, frame)


def _stamped(sec: int, nanosec: int) -> Callable:
    """The valid scan under a faulty stamp."""
    def build(cls: Any, field_cls: Any, points: np.ndarray, stamp: Any) -> Any:
        msg = _msg(cls, field_cls, points, stamp)
        msg.header.stamp = type(stamp)(sec=sec, nanosec=nanosec)
        return msg
    return build


def _set_field(name: str, **values: Any) -> Callable[[Any], None]:
    def edit(msg: Any) -> None:
        for f in msg.fields:
            if f.name == name:
                for key, value in values.items():
                    setattr(f, key, value)
    return edit


def _drop_fields(*names: str) -> Callable[[Any], None]:
    def edit(msg: Any) -> None:
        msg.fields = [f for f in msg.fields if f.name not in names]
    return edit


def _truncate(fraction: float, minus: int = 0) -> Callable[[Any], None]:
    def edit(msg: Any) -> None:
        msg.data = bytes(msg.data)[: max(int(len(msg.data) * fraction) - minus, 0)]
    return edit


def _set(**values: Any) -> Callable[[Any], None]:
    def edit(msg: Any) -> None:
        for key, value in values.items():
            setattr(msg, key, value)
    return edit


def _rng(points: np.ndarray) -> np.random.Generator:
    return np.random.default_rng(len(points))


def _sector(points: np.ndarray, degrees: float) -> np.ndarray:
    azimuth = np.degrees(np.arctan2(points[:, 1], points[:, 0])) % 360.0
    return points[azimuth < degrees]


def _huge(points: np.ndarray) -> np.ndarray:
    """Over 2 million points: the scan repeated with centimetre noise."""
    copies = int(np.ceil(2_100_000 / len(points)))
    rng = _rng(points)
    return np.vstack([points + rng.normal(0.0, 0.01, points.shape) for _ in range(copies)])


def layout_cases() -> list[Case]:
    cases = [Case("empty_width0", "layout", "rejected", _edit(_set(width=0, row_step=0, data=b""))),
             Case("empty_height0", "layout", "rejected", _edit(_set(height=0))),
             Case("no_fields", "layout", "rejected", _edit(_drop_fields("x", "y", "z")))]
    cases += [Case(f"missing_{n}", "layout", "rejected", _edit(_drop_fields(*n))) for n in ("x", "y", "z", "xy")]
    cases += [Case(f"{axis}_type_{t}", "layout", "rejected", _edit(_set_field(axis, datatype=t)))
              for axis in "xyz" for t in INTEGER_TYPES]
    cases += [Case(f"{axis}_type_unknown_{t}", "layout", "rejected", _edit(_set_field(axis, datatype=t)))
              for axis in "xz" for t in (0, 9, 255)]
    cases += [Case(f"{axis}_offset_beyond", "layout", "rejected", _edit(_set_field(axis, offset=1000)))
              for axis in "xyz"]
    cases += [Case("x_offset_negative_like", "layout", "rejected", _edit(_set_field("x", offset=2 ** 32 - 4))),
              Case("point_step_0", "layout", "rejected", _edit(_set(point_step=0))),
              Case("point_step_small", "layout", "rejected", _edit(_set(point_step=8))),
              Case("row_step_small", "layout", "rejected", _edit(lambda m: setattr(m, "row_step", m.row_step // 2))),
              Case("row_step_0", "layout", "rejected", _edit(_set(row_step=0))),
              Case("width_overflow", "layout", "rejected",
                   _edit(lambda m: (setattr(m, "width", 2 ** 31), setattr(m, "row_step", 2 ** 31 * m.point_step)))),
              Case("height_2_same_data", "layout", "rejected", _edit(_set(height=2)))]
    cases += [Case(f"truncated_{int(f * 100)}", "layout", "rejected", _edit(_truncate(f))) for f in (0.0, 0.5, 0.9)]
    cases += [Case("truncated_1_byte", "layout", "rejected", _edit(_truncate(1.0, minus=1))),
              Case("data_empty", "layout", "rejected", _edit(_set(data=b""))),
              Case("point_step_huge", "layout", "rejected", _edit(_set(point_step=1_000_000))),
              Case("garbage_bytes", "layout", "rejected_or_flagged",
                   _edit(lambda m: setattr(m, "data", np.random.default_rng(7).bytes(len(m.data))))),
              Case("bigendian_flag", "layout", "rejected_or_flagged", _edit(_set(is_bigendian=True))),
              Case("x_float64_claimed", "layout", "rejected_or_flagged", _edit(_set_field("x", datatype=FLOAT64)))]
    return cases


def geometry_cases() -> list[Case]:
    return [
        Case("all_nan", "geometry", "rejected", _points(lambda p: np.full_like(p, np.nan))),
        Case("all_inf", "geometry", "rejected", _points(lambda p: np.full_like(p, np.inf))),
        Case("all_zero", "geometry", "rejected", _points(lambda p: np.zeros_like(p))),
        Case("one_point_repeated", "geometry", "rejected", _points(lambda p: np.repeat(p[:1], len(p), axis=0))),
        Case("three_points", "geometry", "rejected", _points(lambda p: p[:3])),
        Case("one_point", "geometry", "rejected", _points(lambda p: p[:1])),
        Case("collinear", "geometry", "rejected_or_flagged",
             _points(lambda p: np.outer(np.linspace(-20, 20, len(p)), [1.0, 0.3, 0.0]))),
        Case("millimetre_cube", "geometry", "rejected_or_flagged",
             _points(lambda p: _rng(p).uniform(0, 1e-3, p.shape))),
        Case("huge_coordinates", "geometry", "rejected_or_flagged", _points(lambda p: p * 1e30)),
        Case("ninety_percent_nan", "geometry", "rejected",
             _points(lambda p: np.where(_rng(p).random((len(p), 1)) < 0.9, np.nan, p))),
        Case("noise_ball", "geometry", "rejected_or_flagged", _points(lambda p: _rng(p).normal(0, 20, p.shape))),
        Case("mirrored", "geometry", "rejected_or_flagged", _points(lambda p: p * [1.0, -1.0, 1.0])),
        Case("scaled_x2", "geometry", "rejected_or_flagged", _points(lambda p: p * 2.0)),
        Case("shifted_50m", "geometry", "rejected_or_flagged", _points(lambda p: p + [50.0, 0.0, 0.0])),
        Case("upside_down", "geometry", "rejected_or_flagged", _points(lambda p: p * [1.0, -1.0, -1.0])),
    ]


def stamp_cases(last_ns: int) -> list[Case]:
    """Stamp faults relative to ``last_ns``, the stamp of the last valid scan."""
    sec = last_ns // 1_000_000_000
    return [
        Case("sec_int32_max", "stamp", "rejected", _stamped(2 ** 31 - 1, 0)),
        Case("nanosec_uint32_max", "stamp", "rejected", _stamped(sec, 2 ** 32 - 1)),
        Case("nanosec_1e9", "stamp", "rejected", _stamped(sec, 1_000_000_000)),
        Case("sec_zero", "stamp", "rejected", _stamped(0, 0)),
        Case("sec_negative", "stamp", "rejected", _stamped(-5, 0)),
        Case("one_hour_ahead", "stamp", "rejected", _stamped(sec + 3600, 0)),
        Case("one_day_back", "stamp", "rejected", _stamped(max(sec - 86400, 1), 0)),
        Case("back_2s", "stamp", "rejected", _stamped_ns(last_ns - 2_000_000_000)),
        Case("back_100ms", "stamp", "rejected", _stamped_ns(last_ns - 100_000_000)),
        Case("duplicate_stamp", "stamp", "rejected_or_flagged", _stamped_ns(last_ns)),
    ]


def _stamped_ns(ns: int) -> Callable:
    return _stamped(ns // 1_000_000_000, ns % 1_000_000_000)


def data_cases() -> list[Case]:
    cases = [Case(f"sector_{d}deg", "data", "rejected", _points(lambda p, d=d: _sector(p, d))) for d in (45, 90, 120)]
    cases += [Case(f"first_{n}_points", "data", "rejected", _points(lambda p, n=n: p[:n])) for n in (60, 200, 1000)]
    cases += [Case(f"random_{n}_points", "data", "rejected",
                   _points(lambda p, n=n: p[_rng(p).choice(len(p), n, replace=False)])) for n in (60, 200, 500)]
    cases += [Case(f"frame_{name}", "data", "rejected", _points(lambda p: p, frame=name))
              for name in ("robot2/velodyne", "base_link", "map")]
    cases += [Case("near_points_only", "data", "rejected", _points(lambda p: p[np.linalg.norm(p, axis=1) < 3.0])),
              Case("far_points_only", "data", "rejected_or_flagged",
                   _points(lambda p: p[np.linalg.norm(p, axis=1) > 15.0]))]
    return cases


def size_cases() -> list[Case]:
    return [Case("two_million_points", "size", "handled", _points(_huge))]


CDR_LE = b"\x00\x01\x00\x00"  # the encapsulation of little-endian plain CDR


def _cdr_header(stamp: Any, frame: str = FRAME) -> bytes:
    """The CDR bytes of a std_msgs/Header (after the encapsulation), padded to 4 bytes."""
    name = frame.encode() + b"\0"
    out = struct.pack("<iII", stamp.sec, stamp.nanosec, len(name)) + name
    return out + b"\0" * (-len(out) % 4)


def _cdr_cloud(stamp: Any, data_length: int, data: bytes) -> bytes:
    """A PointCloud2 stream of one point (x float32) whose data sequence claims ``data_length`` bytes."""
    field = struct.pack("<I", 2) + b"x\0" + b"\0\0" + struct.pack("<IBxxxI", 0, FLOAT32, 1)
    body = struct.pack("<II", 1, 1) + struct.pack("<I", 1) + field + struct.pack("<?xxxII", False, 4, 4)
    return CDR_LE + _cdr_header(stamp) + body + struct.pack("<I", data_length) + data + b"\x01"


def cdr_cases() -> list[Case]:
    """Byte streams a raw publisher could send: the subscription takes them raw, the node must refuse them."""
    return [
        Case("cdr_encapsulation_only", "cdr", "rejected", lambda c, f, p, stamp: CDR_LE),
        Case("cdr_unknown_encapsulation", "cdr", "rejected",
             lambda c, f, p, stamp: b"\x7f\x7f\x00\x00" + _cdr_header(stamp) + bytes(64)),
        Case("cdr_ends_after_header", "cdr", "rejected", lambda c, f, p, stamp: CDR_LE + _cdr_header(stamp)),
        Case("cdr_data_beyond_buffer", "cdr", "rejected",
             lambda c, f, p, stamp: _cdr_cloud(stamp, 1_000_000_000, bytes(16))),
        Case("cdr_random_after_header", "cdr", "rejected",
             lambda c, f, p, stamp: CDR_LE + _cdr_header(stamp) + np.random.default_rng(11).bytes(256)),
    ]


def corpus(last_ns: int) -> list[Case]:
    """Every case; stamp faults are relative to ``last_ns``, the last valid scan's stamp (each case's own stamp,
    passed to ``build``, is the stamp to use otherwise)."""
    return layout_cases() + geometry_cases() + stamp_cases(last_ns) + data_cases() + size_cases() + cdr_cases()
