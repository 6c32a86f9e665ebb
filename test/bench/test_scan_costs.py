"""The scan-cost benchmark (benchmarks.scan_costs): stage timers that nest, undo, and add up on a real pipeline."""
import time

import numpy as np
import pytest
from street_scene import make_transform, make_world, street_scan

from benchmarks.real import Sequence
from benchmarks.scan_costs import STAGES, StageTimer, pipeline_costs, summary, timed_stages
from cemnet_ros.pipeline.aligner import AlignerConfig, ScanAligner
from cemnet_ros.pipeline.steps.polish import Polisher


def test_a_recursive_call_counts_once_and_take_starts_afresh():
    timer = StageTimer()

    def nested(depth):
        time.sleep(0.01)
        return nested(depth - 1) if depth else "done"

    nested = timer.wrap("nested", nested)
    assert nested(2) == "done"
    spent = timer.take()
    assert 0.03 <= spent["nested"] < 0.3  # three sleeps, timed once, not 1 + 2 + 3 times
    assert timer.take() == {}


def test_the_stages_are_wrapped_inside_the_block_only():
    original = Polisher.__dict__["fine"]
    with timed_stages(StageTimer()):
        assert Polisher.__dict__["fine"] is not original
    assert Polisher.__dict__["fine"] is original


def test_a_street_drive_is_split_into_its_stages_and_the_rest():
    world, rng = make_world(), np.random.default_rng(0)
    poses = [make_transform(yaw=0.02 * k, t=(0.5 * k, 0.0, 0.0)) for k in range(8)]
    sequence = Sequence("street", [street_scan(world, p, rng) for p in poses], poses,
                        [k * 100_000_000 for k in range(8)], max_range=50.0)
    costs = pipeline_costs(sequence, lambda: ScanAligner(AlignerConfig()), warmup=2)
    tracked = costs["tracked"]
    assert tracked["scans"] + costs["searched"]["scans"] == 6
    stages = tracked["stages_ms"]
    assert set(stages) == {s.label for s in STAGES}
    assert stages["polish, fine: point-to-plane ICP"] > 0 and stages["map update: insert, normals, prune"] > 0
    kernel = stages["  of which its correspondence kernel (numba)"]
    assert 0 < kernel < stages["polish, fine: point-to-plane ICP"]  # nested in the fine polish
    top_level = sum(ms for label, ms in stages.items() if not label.startswith(" "))
    assert top_level + tracked["rest_ms"] == pytest.approx(tracked["mean_ms"]) and tracked["rest_ms"] >= 0


def test_no_scans_summarise_to_a_count_of_zero():
    assert summary([]) == {"scans": 0}
