"""The covariance benchmark end to end on the bundled synthetic bag (exact ground truth): both modes, one run."""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from benchmarks.covariance_runs import evaluate, nees_table
from benchmarks.live import bag_sequence
from cemnet_ros.ros.node_config import NodeConfig

REPO = Path(__file__).resolve().parents[2]
BAG = REPO / "bags" / "synthetic_lidar.mcap"


def _load_script():
    """scripts/bench_covariance.py as a module (the scripts are not a package)."""
    spec = importlib.util.spec_from_file_location("bench_covariance", REPO / "scripts" / "bench_covariance.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_bench_takes_several_bags_or_none():
    script = _load_script()
    assert script.parse_args(["--bag", "a.mcap", "b.mcap"]).bag == [Path("a.mcap"), Path("b.mcap")]
    assert script.parse_args([]).bag == [script.KITTI_BAG]
    assert script.parse_args(["--bag", "none", "--balm", "dir"]).bag == []
    with pytest.raises(SystemExit):
        script.parse_args(["--bag", "none"])  # no sequence at all


@pytest.mark.slow
def test_both_modes_are_measured_on_the_same_trajectory():
    sequence = bag_sequence(BAG).first(5)
    result = evaluate(sequence)
    registration, fixed = result["modes"]["registration"], result["modes"]["fixed"]
    assert registration["pose"]["steps"] == fixed["pose"]["steps"] == 4
    # one trajectory: the modes differ in their covariances only, so the odometry's ATE is the same
    assert registration["ate_odometry_m"] == fixed["ate_odometry_m"] < 0.05
    steps = [s for s in result["steps"] if "error" in s]
    node = NodeConfig()
    fixed_std = np.sqrt([node.fixed_position_variance] * 3 + [node.fixed_orientation_variance] * 3)
    assert all(np.all(np.asarray(s["std_fixed"]) == fixed_std) for s in steps if s["accepted"])
    assert "| synthetic_lidar | registration | 4 |" in nees_table({"synthetic_lidar": result})
