"""cemnet-replay end to end: outputs, accuracy against ground truth, bad input, configuration."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from cemnet_ros.io.trajectory_files import read_tum
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.replay.bag_io import BagReader, BagWriter
from cemnet_ros.replay.trajectory import absolute_trajectory_error
from cemnet_ros.schema import build
from cemnet_ros.tools.replay_cli import load_params, main

REPO = Path(__file__).resolve().parents[2]



def test_replay_without_matplotlib_writes_everything_but_the_figure(tiny_bag, tmp_path, capsys, monkeypatch):
    for name in ("matplotlib", "matplotlib.figure"):
        monkeypatch.setitem(sys.modules, name, None)  # as on a headless robot without python3-matplotlib
    out = tmp_path / "out"
    assert main([str(tiny_bag), "--out", str(out), "--quiet"]) == 0
    assert not (out / "replay.png").exists()
    assert (out / "trajectory_tum.txt").is_file() and "plot" not in json.loads((out / "summary.json").read_text())[
        "outputs"]
    err = capsys.readouterr().err
    assert "replay.png not written" in err and "python3-matplotlib" in err and "--no-plot" in err, err


def test_replay_tiny_bag_with_a_cem_preset(tiny_bag, tmp_path, capsys):
    out = tmp_path / "out"
    rc = main([str(tiny_bag), "--out", str(out), "--quiet", "--registration.cem_preset", "refine",
               "--publish_aligned_cloud", "true"])
    assert rc == 0
    report = capsys.readouterr().out
    assert "ATE RMSE" in report and "RPE translation" in report and "latency p50" in report
    for name in ("replay.mcap", "trajectory_tum.txt", "ground_truth_tum.txt", "summary.json", "replay.png"):
        assert (out / name).is_file(), name
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary left behind
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scans"] == 4 and summary["accuracy"]["matched"] == 4
    assert summary["config"]["registration"]["cem_preset"] == "refine"
    # ~0.7 m and ~3 deg per scan: dead reckoning with identity would be off by 70 cm per pair.
    for pair in summary["accuracy"]["per_pair"]:
        assert pair["trans_m"] < 0.05 and pair["rot_deg"] < 0.5, pair
    # The TUM files reproduce the reported ATE.
    _, est = read_tum(out / "trajectory_tum.txt")
    _, gt = read_tum(out / "ground_truth_tum.txt")
    assert absolute_trajectory_error(est, gt).rmse == pytest.approx(summary["accuracy"]["ate"]["rmse_m"], abs=1e-6)
    # The output bag: one pose, odometry and aligned cloud per scan, in the odom frame, same stamps as the input.
    with BagReader(out / "replay.mcap", topic="/align_node/aligned_cloud", gt_topic="/align_node/pose") as reader:
        assert reader.info.topics["/align_node/odometry"] == "nav_msgs/msg/Odometry"
        clouds = list(reader.clouds())
        stamps, poses, frame = reader.ground_truth()
    with BagReader(tiny_bag) as reader:
        in_stamps = [f.stamp_ns for f in reader.clouds()]
    assert frame == "odom" and [c.frame_id for c in clouds] == ["odom"] * 4
    assert stamps.tolist() == in_stamps
    np.testing.assert_allclose(poses, est, atol=1e-6)
    # Aligned clouds of the first and last scan overlap: the ground (z ~ -1.8 m in the first sensor frame)
    # is at the same height in both.
    low0 = np.median(clouds[0].points[clouds[0].points[:, 2] < -1.0, 2])
    low3 = np.median(clouds[3].points[clouds[3].points[:, 2] < -1.0, 2])
    assert abs(low0 - low3) < 0.05


def test_a_realtime_replay_drops_what_the_node_queue_would_and_scores_what_came_out(tiny_bag, tmp_path, capsys):
    out = tmp_path / "live"
    # 10000x: the 4 scans arrive within 0.04 ms, so the first one's registration holds up the others; a queue
    # of 2 keeps the newest two, and the first of them starts behind the last
    assert main([str(tiny_bag), "--out", str(out), "--quiet", "--no-plot",
                 "--realtime", "10000", "--queue_size", "2", "--behind_effort", "0.25"]) == 0
    assert "live at 10000x" in capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    live = summary["live"]
    assert (live["scans"], live["processed"], live["dropped"], live["behind"]) == (4, 3, 1, 1)
    assert summary["scans"] == 3 and summary["accuracy"]["matched"] == 3 and live["latency_ms_p50"] > 0
    assert [(s["index"], s["effort"]) for s in summary["steps"]] == [(0, 1.0), (2, 0.25), (3, 1.0)]


def test_replay_without_ground_truth_reports_speed_only(tmp_path, capsys):
    rng = np.random.default_rng(0)
    base = rng.uniform(-5, 5, size=(3000, 3))
    bag = tmp_path / "nogt.mcap"
    with BagWriter(bag) as writer:
        for i in range(3):
            writer.write_cloud("/cloud", base + [0.1 * i, 0, 0], "cam", 10**18 + i * 10**8)
    out = tmp_path / "out"
    assert main([str(bag), "--out", str(out), "--quiet", "--limit", "2", "--no-plot"]) == 0
    report = capsys.readouterr().out
    assert "speed only" in report and "ATE" not in report
    summary = json.loads((out / "summary.json").read_text())
    assert summary["accuracy"] is None and summary["scans"] == 2
    assert not (out / "replay.png").exists() and not (out / "ground_truth_tum.txt").exists()


def test_replay_reports_rejected_scans_and_goes_on(tmp_path, capsys):
    rng = np.random.default_rng(1)
    base = rng.uniform(-5, 5, size=(3000, 3))
    bag = tmp_path / "sparse.mcap"
    with BagWriter(bag) as writer:
        for i in range(4):
            cloud = base[:10] if i == 1 else base + [0.1 * i, 0, 0]
            writer.write_cloud("/cloud", cloud, "cam", 10**18 + i * 10**8)
    out = tmp_path / "out"
    assert main([str(bag), "--out", str(out), "--quiet", "--no-plot"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scans"] == 3
    assert [r["index"] for r in summary["rejected"]] == [1] and "10" in summary["rejected"][0]["reason"]
    assert summary["skipped_count"] == 1 and summary["skipped"][0]["reason"] == summary["rejected"][0]["reason"]
    report = capsys.readouterr().out
    assert "rejected scans: 1" in report and "skipped 1 of 4 messages: 1 " in report


def test_replay_with_no_usable_scan_exits_1(tmp_path, capsys):
    bag = tmp_path / "tiny_clouds.mcap"
    with BagWriter(bag) as writer:
        for i in range(2):
            writer.write_cloud("/cloud", np.random.default_rng(i).uniform(-5, 5, size=(10, 3)), "cam", 10**18 + i)
    out = tmp_path / "out"
    assert main([str(bag), "--out", str(out), "--quiet", "--no-plot"]) == 1
    last = capsys.readouterr().err.splitlines()[-1]  # after the warning on the first skipped message
    assert last.startswith("cemnet-replay: no scan could be processed (skipped 2 of 2 messages: 2 too_few_points")
    assert not (out / "summary.json").exists()


@pytest.mark.parametrize("argv, message", [
    (["{tmp}/missing.mcap"], "bag not found"),
    (["{bag}", "--topic", "/nope"], "topic /nope not in"),
    (["{bag}", "--gt-topic", "/nope"], "ground-truth topic /nope"),
    (["{bag}", "--registration.n_points", "4"], "bad configuration"),
    (["{bag}", "--fixed_position_variance", "0"], "bad configuration"),  # a node parameter, checked as live
    (["{bag}", "--config", "{tmp}/bad.yaml"], "bad configuration"),
])
def test_replay_bad_inputs_exit_2(tiny_bag, tmp_path, capsys, argv, message):
    argv = [a.format(tmp=tmp_path, bag=tiny_bag) for a in argv]
    (tmp_path / "bad.yaml").write_text("/**:\n  ros__parameters:\n    tracking.centre: magic\n")
    assert main(argv + ["--out", str(tmp_path / "o"), "--quiet"]) == 2
    assert message in capsys.readouterr().err


def build_config(values):
    return build(AlignerConfig(), values)


def test_config_yaml_ros_format_and_overrides(tmp_path):
    cfg_file = tmp_path / "p.yaml"
    cfg_file.write_text("/**:\n  ros__parameters:\n    registration.cem_preset: paper\n    recovery:\n"
                        "      search: {refine_preset: tracking}\n    preprocess.voxel_size: 0.3\n"
                        "    tracking.centre: identity\n    registration.weights: ''\n    input_topic: points\n")
    config = build_config(load_params(cfg_file))
    assert config.registration.cem_preset == "paper" and config.recovery.search.refine_preset == "tracking"
    assert config.preprocess.voxel_size == 0.3 and config.tracking.centre == "identity"
    assert config.registration.weights == ""
    with pytest.raises(ValueError, match="tracking.centre must be one of"):
        build_config({"tracking.centre": "nonsense"})
    with pytest.raises(ValueError, match="unknown parameter"):
        build_config({"n_candidates": 5})  # flat names of the old front ends are refused, not ignored


def test_repo_node_config_loads():
    path = REPO / "config" / "align_node.yaml"
    if not path.exists():
        pytest.skip("config/align_node.yaml not present")
    config = build_config(load_params(path))
    assert config.registration.n_points >= 32
