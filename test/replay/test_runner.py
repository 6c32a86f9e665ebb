"""cemnet-replay over a bag with bad cloud messages in the middle: each is skipped with a counted warning, the
valid scans all go through, and their poses are those of the same bag without the bad messages."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer

from cemnet_ros.data import scenes
from cemnet_ros.pointcloud2 import make_pointcloud2
from cemnet_ros.replay.bag_io import POINTCLOUD2, TYPESTORE, BagReader, SkippedMessage, ns_to_stamp, stamp_to_ns
from cemnet_ros.replay.report import skipped_line
from cemnet_ros.runtime.extrinsic import pose_msg_to_matrix
from cemnet_ros.tools.replay_cli import main

STAMP0, PERIOD = 1_700_000_000_000_000_000, 100_000_000
QUIET = ["--quiet", "--no-plot"]
N_VALID = 5
SCANS = [scenes.lidar_scan(scenes.courtyard_scene(), pose, scenes.LidarModel(n_beams=16, n_azimuth=360),
                           np.random.default_rng(k)) for k, pose in enumerate(scenes.synthetic_trajectory(N_VALID))]


def _cloud(points: np.ndarray, stamp_ns: int):
    types = TYPESTORE.types
    return make_pointcloud2(types[POINTCLOUD2], types["sensor_msgs/msg/PointField"], points, "lidar",
                            ns_to_stamp(stamp_ns), header_cls=types["std_msgs/msg/Header"])


def _truncated(stamp_ns: int):
    """A cloud whose data is shorter than row_step * height (a cut-off driver buffer)."""
    msg = _cloud(SCANS[0], stamp_ns)
    msg.data = msg.data[: len(msg.data) // 2].copy()
    return msg


def _raw(msg) -> bytes:
    return bytes(TYPESTORE.serialize_cdr(msg, POINTCLOUD2))


BAD = {  # kind -> CDR bytes of a bad message at that stamp
    "truncated": lambda ns: _raw(_truncated(ns)),
    "empty": lambda ns: _raw(_cloud(np.zeros((0, 3)), ns)),  # width 0: a count-0 cloud
    "invalid": lambda ns: b"\x00\x01\x00\x00garbage, not a PointCloud2",  # undecodable CDR
    "sparse": lambda ns: _raw(_cloud(SCANS[0][:10], ns)),  # decodes, but the aligner rejects it (ScanRejected)
}


def _write(path: Path, bad: dict[int, str], with_bad: bool = True) -> list[int]:
    """The N_VALID ray-cast scans of a courtyard drive and, at the slots in ``bad`` (slot -> kind), a bad message
    between them (or nothing, without ``with_bad``: the same bag without the bad messages); returns the stamps
    of the valid scans."""
    valid_stamps, i = [], 0
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/points", POINTCLOUD2, typestore=TYPESTORE)
        for slot in range(N_VALID + len(bad)):
            stamp = STAMP0 + slot * PERIOD
            if slot in bad:
                if with_bad:
                    writer.write(conn, stamp, BAD[bad[slot]](stamp))
                continue
            writer.write(conn, stamp, _raw(_cloud(SCANS[i], stamp)))
            valid_stamps.append(stamp)
            i += 1
    return valid_stamps


def _odometry(bag: Path) -> tuple[list[int], np.ndarray]:
    """(header stamps, 4x4 poses) of replay.mcap's /align_node/odometry, as written (float64)."""
    stamps, poses = [], []
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic == "/align_node/odometry"]
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            stamps.append(stamp_to_ns(msg.header.stamp))
            poses.append(pose_msg_to_matrix(msg.pose.pose))
    return stamps, np.asarray(poses)


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict:
    """The replay of a clean bag and of the same bag with a bad message between valid scans, per kind."""
    root = tmp_path_factory.mktemp("skips")
    bad = {2: "truncated", 4: "empty", 5: "invalid", 7: "sparse"}
    stamps = _write(root / "bad.mcap", bad)
    assert _write(root / "clean.mcap", bad, with_bad=False) == stamps
    out = {"stamps": stamps, "bad_slots": bad}
    for name in ("clean", "bad"):
        assert main([str(root / f"{name}.mcap"), "--out", str(root / name), *QUIET]) == 0
        out[name] = json.loads((root / name / "summary.json").read_text())
        out[f"{name}_odometry"] = _odometry(root / name / "replay.mcap")
    return out


def test_every_valid_scan_processed_and_each_bad_one_counted(runs):
    summary, bad = runs["bad"], runs["bad_slots"]
    assert summary["messages"] == N_VALID + len(bad) and summary["scans"] == N_VALID
    assert summary["skipped_count"] == len(bad) == len(summary["skipped"])
    assert [s["index"] for s in summary["skipped"]] == sorted(bad)
    kinds = [s["kind"] for s in summary["skipped"]]
    assert kinds[:3] == ["truncated", "empty", "invalid"] and kinds[3]  # the aligner's kind for its rejection
    assert [s["stamp_ns"] for s in summary["skipped"]] == [STAMP0 + slot * PERIOD for slot in sorted(bad)]
    assert all(s["topic"] == "/points" and s["reason"] for s in summary["skipped"])
    reasons = [s["reason"] for s in summary["skipped"]]
    assert "truncated cloud" in reasons[0] and "width=0" in reasons[1] and "deserialize" in reasons[2]
    assert "10" in reasons[3] and "points" in reasons[3]  # too few points
    assert [r["index"] for r in summary["rejected"]] == [7]  # the aligner's refusals, as before
    assert [s["stamp_ns"] for s in summary["steps"]] == runs["stamps"]
    clean = runs["clean"]
    assert clean["skipped_count"] == 0 and clean["skipped"] == [] and clean["scans"] == N_VALID


def test_valid_poses_equal_those_of_the_clean_bag(runs):
    stamps, poses = runs["bad_odometry"]
    clean_stamps, clean_poses = runs["clean_odometry"]
    assert stamps == clean_stamps == runs["stamps"]
    np.testing.assert_allclose(poses, clean_poses, rtol=0, atol=1e-9)
    assert np.linalg.norm(poses[-1][:3, 3]) > 0.3  # it moved: the poses are not all identity
    for key in ("fitness", "accepted", "n_points", "linear_m_s"):
        assert [s[key] for s in runs["bad"]["steps"]] == [s[key] for s in runs["clean"]["steps"]], key


def test_skips_warned_once_per_kind_and_summarised(tmp_path, capsys):
    bag = tmp_path / "two_truncated.mcap"
    _write(bag, {1: "truncated", 3: "truncated", 4: "empty"})
    assert main([str(bag), "--out", str(tmp_path / "out"), *QUIET]) == 0
    captured = capsys.readouterr()
    warnings = [line for line in captured.err.splitlines() if "warning: skipped" in line]
    assert len(warnings) == 2 and "[truncated]" in warnings[0] and "[empty]" in warnings[1]
    assert "Traceback" not in captured.err
    assert "skipped 3 of 8 messages: 2 truncated (t=0.100, 0.300 s), 1 empty (t=0.400 s)" in captured.out


def test_only_bad_messages_exit_1_with_the_count(tmp_path, capsys):
    bag = tmp_path / "all_bad.mcap"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/points", POINTCLOUD2, typestore=TYPESTORE)
        for k, kind in enumerate(("truncated", "empty")):
            writer.write(conn, STAMP0 + k, BAD[kind](STAMP0 + k))
    assert main([str(bag), "--out", str(tmp_path / "out"), *QUIET]) == 1
    assert "no scan could be processed (skipped 2 of 2 messages: 1 truncated" in capsys.readouterr().err


def test_reader_scans_reports_each_message(tmp_path):
    bag = tmp_path / "b.mcap"
    _write(bag, {1: "invalid", 2: "truncated"})
    with BagReader(bag) as reader:
        items = list(reader.scans())
        limited = list(reader.scans(limit=2))
    assert [isinstance(x, SkippedMessage) for x in items] == [False, True, True] + [False] * (N_VALID - 1)
    assert [x.index for x in items] == list(range(len(items))) and len(limited) == 2
    assert items[2].t_s == pytest.approx(0.2) and items[3].t_s == pytest.approx(0.3)


def test_skipped_line_lists_the_first_times_of_each_kind():
    skipped = [{"kind": "truncated", "t_s": 0.1 * k} for k in range(7)] + [{"kind": "empty", "t_s": 12.3}]
    assert skipped_line(skipped, 120) == ("skipped 8 of 120 messages: 7 truncated (t=0.000, 0.100, 0.200, 0.300, "
                                          "0.400, ... s), 1 empty (t=12.300 s)")
    assert skipped_line([], 5) == "skipped 0 of 5 messages"


def test_a_nanosec_out_of_range_is_skipped_as_the_node_rejects_it(tmp_path):
    bag = tmp_path / "bad_nanosec.mcap"
    msg = _cloud(SCANS[0], STAMP0)
    msg.header.stamp = TYPESTORE.types["builtin_interfaces/msg/Time"](sec=STAMP0 // 10 ** 9, nanosec=2 ** 32 - 1)
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/points", POINTCLOUD2, typestore=TYPESTORE)
        writer.write(conn, STAMP0, _raw(msg))
        writer.write(conn, STAMP0 + PERIOD, _raw(_cloud(SCANS[1], STAMP0 + PERIOD)))
    with BagReader(bag) as reader:
        items = list(reader.scans())
    assert isinstance(items[0], SkippedMessage) and items[0].kind == "stamp" and "nanosec" in items[0].reason
    assert not isinstance(items[1], SkippedMessage) and items[1].stamp_ns == STAMP0 + PERIOD
