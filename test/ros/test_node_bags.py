"""The bundled bags replayed through align_node over DDS, against their ground truth."""
from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # read when the DDS participant is created

from node_harness import FIRST_TIMEOUT, pose_of, read_bag  # noqa: E402

from benchmarks.metrics import relative_error  # noqa: E402

BAGS = sorted((Path(__file__).resolve().parents[2] / "bags").glob("*.mcap"))
FLOORS = {"kitti": ("pair", 0.05, 0.2), "synthetic": ("pair", 0.02, 0.1), "rgbd": ("ate", 0.02, None),
          "7scenes": ("ate", 0.02, None), "scenes": ("ate", 0.02, None)}


@pytest.mark.skipif(not BAGS, reason="bags/ has no .mcap yet")
@pytest.mark.parametrize("bag", BAGS, ids=[b.stem for b in BAGS])
def test_replay_bag_over_dds(harness_factory, bag):
    from cemnet_ros.replay.trajectory import absolute_trajectory_error

    clouds, truth = read_bag(bag)
    h = harness_factory({})  # the node's default CEMs
    estimates, started = [], time.monotonic()
    for k, (ns, raw) in enumerate(clouds):
        odom = h.send(raw, timeout=FIRST_TIMEOUT if k < 2 else 120.0)
        out_ns = odom.header.stamp.sec * 1_000_000_000 + odom.header.stamp.nanosec
        assert out_ns == ns
        estimates.append(pose_of(odom))
    elapsed = time.monotonic() - started
    gt = [truth[ns] for ns, _ in clouds]
    gt = [np.linalg.inv(gt[0]) @ g for g in gt]
    pair_errors = [relative_error(np.linalg.inv(estimates[k - 1]) @ estimates[k], np.linalg.inv(gt[k - 1]) @ gt[k])
                   for k in range(1, len(gt))]
    ate = absolute_trajectory_error(estimates, gt)
    worst_t, worst_r = (max(e[i] for e in pair_errors) for i in (0, 1))
    print(f"\n{bag.name}: {len(clouds)} scans in {elapsed:.1f} s ({elapsed / len(clouds):.2f} s/scan incl. JIT); "
          f"per pair max {worst_t * 100:.2f} cm / {worst_r:.3f} deg, mean "
          f"{np.mean([e[0] for e in pair_errors]) * 100:.2f} cm / {np.mean([e[1] for e in pair_errors]):.3f} deg; "
          f"ATE rmse {ate.rmse * 100:.2f} cm; diagnostics {h.values()}")
    kind, trans_floor, rot_floor = next((v for k, v in FLOORS.items() if k in bag.stem.lower()), ("pair", 0.05, 0.2))
    if kind == "ate":
        assert ate.rmse <= trans_floor, f"ATE {ate.rmse * 100:.2f} cm > {trans_floor * 100:.0f} cm"
    else:
        assert worst_t <= trans_floor and worst_r <= rot_floor, (worst_t, worst_r)
