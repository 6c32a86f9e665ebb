"""The library benchmark (benchmarks.libraries, scripts/bench_libraries.py) on small synthetic scans: its
timing, offsets and steps, ours' side of every piece, and each peer's side where that peer is installed."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from benchmarks.libraries import peers
from benchmarks.libraries.inputs import Stage, Step, box_scan, orthonormal, perturbed, polish_steps
from benchmarks.libraries.local_maps import agreement, downsample_calls, local_maps, nearest_calls
from benchmarks.libraries.peers import OURS, import_peers
from benchmarks.libraries.sequence import bench_sequence
from benchmarks.libraries.startup import first_calls, startup_run
from benchmarks.libraries.table import libraries_table
from benchmarks.libraries.timing import OTHERS, interleaved, timing_summary
from benchmarks.metrics import relative_error
from benchmarks.real import Sequence
from cemnet_ros.core.geometry import apply_transform, rigid_transform
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.steps.frame import Frame
from cemnet_ros.pipeline.steps.preprocess import voxel_downsample

VOXEL = 0.2
STAGES = [Stage(1000, 6 * VOXEL, 30), Stage(3000, 2 * VOXEL, 10)]


def _pose(x=0.0, y=0.0, yaw_deg=0.0):
    return rigid_transform(Rotation.from_euler("z", yaw_deg, degrees=True).as_matrix(), np.array([x, y, 0.0]))


def _step(T_target_source):
    """A box scan against itself seen from ``T_target_source``: the source's voxel cloud and a polish subset."""
    target = voxel_downsample(box_scan(20_000, seed=1), VOXEL)
    source = voxel_downsample(apply_transform(np.linalg.inv(T_target_source), box_scan(20_000, seed=2)), VOXEL)
    polish = source[np.random.default_rng(0).permutation(len(source))[:3000]]
    return Step(1, [target], [np.eye(4)], source, polish, T_target_source)


def _polished(local_map, step, metres=0.3, degrees=3.0):
    for points, pose in zip(step.map_scans, step.T_target_map_scans):
        local_map.insert(points, pose)
    initial = perturbed(step.T_target_source, metres, degrees, np.random.default_rng(0))
    T_target_source, _ = local_map.polish(step, initial, STAGES)
    return relative_error(T_target_source, step.T_target_source)


def test_interleaved_runs_the_methods_in_turn_and_ratios_are_per_round_and_per_quiet_round():
    order = []
    times = {}
    out = interleaved({"ours": lambda: order.append("a") or 1, "peer": lambda: order.append("b") or 2}, 3, times)
    assert order == ["a", "b"] * 3 and out == {"ours": 1, "peer": 2} and len(times[OTHERS]) == 3
    summary = timing_summary({OURS: [2.0, 4.0, 9.0], "peer": [1.0, 1.0, 3.0], OTHERS: [0.0, 1.0, 0.1]})
    assert summary["peer"]["ours_over"] == pytest.approx(3.0)  # median of 2, 4, 3
    assert summary["peer"]["ours_over_quiet"] == pytest.approx(2.5) and summary["peer"]["quiet_rounds"] == 2
    assert summary[OURS]["ms_median"] == 4.0 and "ours_over" not in summary[OURS] and OTHERS not in summary


def test_perturbed_moves_by_exactly_the_offset_and_orthonormal_keeps_the_pose():
    truth = _pose(1.0, 2.0, 30.0)
    for seed in range(3):
        rte, rre = relative_error(perturbed(truth, 0.3, 3.0, np.random.default_rng(seed)), truth)
        assert rte == pytest.approx(0.3) and rre == pytest.approx(3.0)
    skewed = truth.copy()
    skewed[:3, :3] *= 1.0 + 1e-6
    fixed = orthonormal(skewed)
    assert np.allclose(fixed[:3, :3].T @ fixed[:3, :3], np.eye(3), atol=1e-12) and np.allclose(fixed, truth)


def test_a_stage_strides_over_the_polish_points_as_the_wide_polish_does():
    polish = np.arange(3000.0)[:, None]
    assert np.array_equal(Stage(1000, 1.0, 1).subset(polish)[:3, 0], [0.0, 3.0, 6.0])
    assert len(Stage(1000, 1.0, 1).subset(polish)) == 1000 and len(Stage(3000, 1.0, 1).subset(polish)) == 3000
    assert len(Stage(1000, 1.0, 1).subset(polish[:500])) == 500


def test_polish_steps_place_the_map_in_the_last_map_scan_frame():
    poses = [_pose(k, 0.0, 10.0 * k) for k in range(5)]
    frames = [Frame(np.full((4, 3), k), np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 3)), 1.0, 0.1)
              for k in range(5)]
    steps = polish_steps(frames, poses, map_scans=3, pairs=10)
    assert [s.index for s in steps] == [3, 4]
    assert np.allclose(steps[0].T_target_map_scans[-1], np.eye(4))
    assert np.allclose(steps[0].T_target_source, np.linalg.inv(poses[2]) @ poses[3])
    assert [s.dense[0, 0] for s in steps] == [3.0, 4.0] and len(steps[0].map_scans) == 3


def test_ours_downsample_and_nearest_agree_with_plain_numpy_and_scipy():
    scan = box_scan(5000)
    calls = downsample_calls(scan, VOXEL, {})
    assert list(calls) == [OURS]
    assert len(calls[OURS]()) == len(np.unique(np.floor(scan / VOXEL), axis=0))
    ours = local_maps({}, AlignerConfig(), VOXEL, 100.0)[OURS]
    ours.insert(scan, np.eye(4))
    build_times = {}
    query = box_scan(2000, seed=5)
    distances = {name: call() for name, call in nearest_calls(ours.map, query, 0.3, {}, build_times).items()}
    assert set(distances) == {OURS, "scipy"} and set(build_times) == {"scipy", OTHERS}
    assert agreement(distances[OURS], distances["scipy"]) == 1.0


def test_ours_polish_finds_the_true_motion():
    rte, rre = _polished(local_maps({}, AlignerConfig(), VOXEL, 100.0)[OURS], _step(_pose(0.5, 0.2, 5.0)))
    assert rte < 0.05 and rre < 0.5


def test_a_missing_peer_is_left_out(monkeypatch):
    monkeypatch.setitem(peers.PEER_MODULES, "absent_peer", ("no_such_module_for_this_test",))
    assert import_peers(("absent_peer",)) == {}


def test_bench_sequence_and_its_table_with_ours_alone():
    world = box_scan(30_000, seed=3)
    poses = [_pose(0.3 * k, 0.0, 2.0 * k) for k in range(4)]
    scans = [apply_transform(np.linalg.inv(T_world_sensor), world) for T_world_sensor in poses]
    sequence = Sequence("box", scans, poses, [k * 100_000_000 for k in range(4)], max_range=100.0)
    result = bench_sequence(sequence, {}, pairs=1, map_scans=2, seeds=1, rounds=1)
    assert set(result["polish"]) == {"map of 1 scan", "map of 2 scans"}
    for offsets in result["polish"].values():
        assert offsets["0.3 m / 3 deg"][OURS]["success"] == 1.0
    table = libraries_table({"sequences": {"box": result}, "startup": {OURS: first_calls(OURS)}})
    assert "| downsample | box | ours |" in table and "| box | map of 2 scans | 1 m / 10 deg | ours |" in table


def test_startup_run_measures_ours_in_a_fresh_process():
    figures = startup_run(OURS)
    assert {"import_ms", "downsample_first_ms", "map_update_second_ms", "nearest_first_ms", "polish_first_ms"} \
        <= set(figures)
    assert all(value > 0.0 for value in figures.values())


@pytest.mark.parametrize("name", ["small_gicp plane", "small_gicp gicp", "small_gicp vgicp"])
def test_small_gicp_methods_find_the_true_motion(name):
    peers = {"small_gicp": pytest.importorskip("small_gicp")}
    rte, rre = _polished(local_maps(peers, AlignerConfig(), VOXEL, 100.0)[name], _step(_pose(0.5, 0.2, 5.0)))
    assert rte < 0.05 and rre < 0.5


def test_small_gicp_downsample_and_nearest_match_ours():
    peers = {"small_gicp": pytest.importorskip("small_gicp")}
    scan = box_scan(5000)
    grids = {name: call() for name, call in downsample_calls(scan, VOXEL, peers).items()}
    assert abs(len(grids["small_gicp"]) - len(grids[OURS])) <= 0.1 * len(grids[OURS])  # threads may split a voxel
    ours = local_maps({}, AlignerConfig(), VOXEL, 100.0)[OURS]
    ours.insert(scan, np.eye(4))
    calls = nearest_calls(ours.map, box_scan(2000, seed=5), 0.3, peers, {})
    assert agreement(calls[OURS](), calls["small_gicp"]()) == 1.0


def test_kiss_icp_method_finds_the_true_motion():
    pytest.importorskip("kiss_icp.registration")
    peers = import_peers(("kiss_icp",))
    grid = downsample_calls(box_scan(5000), VOXEL, peers)["kiss_icp"]()
    assert grid.shape[1] == 3 and 0 < len(grid) <= 5000
    rte, rre = _polished(local_maps(peers, AlignerConfig(), VOXEL, 100.0)["kiss_icp p2p"],
                         _step(_pose(0.5, 0.2, 5.0)))
    assert rte < 0.05 and rre < 0.5
