"""The step that ends a run of degenerate steps is tied to the last vouched pose only through the map as last vouched
(pipeline/degenerate_stretch.py, its wiring in pipeline/trajectory.py)."""
from __future__ import annotations

import dataclasses

import numpy as np

from benchmarks.metrics import relative_error
from cemnet_ros.pipeline.aligner import ScanAligner
from cemnet_ros.pipeline.config import AlignerConfig, PreprocessConfig
from cemnet_ros.pipeline.degenerate_stretch import DegenerateStretch
from cemnet_ros.pipeline.steps.frame import Preprocessor

PERIOD = 100_000_000
SIGHT = 6.0  # m: the sensor's range in the corridor


def corridor_with_pillars(rng, sensor_x, n=12000):
    """Points within :data:`SIGHT` of a sensor at ``sensor_x`` in a corridor along x (walls y = +-1.5, floor and
    ceiling) closed at x = -4, with a pair of pillars at x = 20: in between nothing varies along x."""
    x = rng.uniform(-4.0, 40.0, n)
    side, across = rng.integers(0, 4, n), rng.uniform(-1.5, 1.5, n)
    y = np.where(side == 0, 1.5, np.where(side == 1, -1.5, across))
    z = np.where(side == 2, -1.2, np.where(side == 3, 1.8, rng.uniform(-1.2, 1.8, n)))
    m = n // 8
    end = np.c_[np.full(m, -4.0), rng.uniform(-1.5, 1.5, m), rng.uniform(-1.2, 1.8, m)]
    face, along = rng.integers(0, 3, m), rng.uniform(0.0, 0.5, m)
    pillar_x = np.where(face == 0, 20.0, np.where(face == 1, 20.5, 20.0 + along))
    pillar_y = np.where(face == 2, 1.1, 1.1 + 0.4 * rng.uniform(0.0, 1.0, m))
    pillar_y *= np.where(rng.uniform(size=m) < 0.5, 1.0, -1.0)
    points = np.vstack([np.c_[x, y, z], end, np.c_[pillar_x, pillar_y, rng.uniform(-1.2, 1.8, m)]])
    points -= (sensor_x, 0.0, 0.0)
    return points[np.linalg.norm(points, axis=1) < SIGHT]


def test_the_step_after_a_drifted_degenerate_run_is_flagged_and_anchors_a_restarted_map():
    config = dataclasses.replace(AlignerConfig(), preprocess=PreprocessConfig(max_range=SIGHT))
    aligner, rng = ScanAligner(config), np.random.default_rng(0)
    truth = [0.5 * k for k in range(34)]
    steps = [aligner.process(corridor_with_pillars(rng, x), k * PERIOD) for k, x in enumerate(truth)]
    assert any(s.outcome == "degenerate" for s in steps)  # the corridor's run
    ended = next(s for s in steps if "map as last vouched" in s.reason)
    assert not ended.accepted and ended.map_restarted and ended.outcome == "degenerate", ended.reason
    anchor = 0
    for k, step in enumerate(steps[1:], start=1):  # every vouched step is right from the last vouched one
        if step.accepted:
            moved = np.linalg.inv(steps[anchor].pose) @ step.pose
            true_moved = np.eye(4)
            true_moved[0, 3] = truth[k] - truth[anchor]
            assert relative_error(moved, true_moved)[0] < 0.1, (k, anchor, step.reason)
        if step.accepted or step.map_restarted:
            anchor = k
    assert steps[-1].accepted  # the restarted map tracks on


def test_an_answer_ends_a_stretch_tied_only_where_the_map_as_last_vouched_sees_it():
    rng = np.random.default_rng(1)
    config = AlignerConfig()
    preprocessor = Preprocessor(config)
    first = corridor_with_pillars(rng, 0.0)
    frame = preprocessor.frame(first)
    preprocessor.adopt(frame)
    vouched = preprocessor.new_map()
    vouched.update(first, np.zeros(3))
    stretch = DegenerateStretch()
    assert stretch.untied(config, frame, np.eye(4), 0.5) == ""  # no stretch runs
    stretch.entering(vouched)
    vouched.update(first + (30.0, 0.0, 0.0), np.array([30.0, 0.0, 0.0]))  # the live map grows on; the kept one not
    assert stretch.untied(config, frame, np.eye(4), 0.5) == ""  # seen by the map as last vouched
    far = np.eye(4)
    far[0, 3] = 30.0
    assert "restarts" in stretch.untied(config, frame, far, 0.5)  # its fit is on the stretch's scans alone
    stretch.clear()
    assert stretch.untied(config, frame, far, 0.5) == ""
