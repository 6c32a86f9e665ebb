"""The global CEM search finds motions that a local search around the identity cannot."""
import numpy as np
import pytest

from cemnet_ros.core import CEMConfig
from cemnet_ros.core.geometry import euler_to_matrix_np, rotation_angle_deg
from cemnet_ros.core.global_search import GlobalSearchConfig, distinct_best, global_search, scatter

SMALL = GlobalSearchConfig(n_scatter=1000, refine=CEMConfig(n_candidates=100, n_iters=4, n_fused_iters=2))


def moved(points, yaw, t):
    rotation = euler_to_matrix_np(np.array([yaw, 0.0, 0.0]))
    return points @ rotation.T + t, rotation


@pytest.mark.parametrize("yaw_deg", [150.0, -100.0])
def test_global_search_recovers_a_large_yaw_and_translation(bracket, yaw_deg):
    source = bracket[::2]
    target, rotation = moved(source, np.radians(yaw_deg), np.array([0.3, -0.2, 0.0]))
    best = global_search(source, target, np.zeros(6), radius=0.5, config=SMALL)[0]
    assert rotation_angle_deg(best.T_target_source[:3, :3].T @ rotation) < 3.0
    assert np.linalg.norm(best.T_target_source[:3, 3] - [0.3, -0.2, 0.0]) < 0.05
    assert best.fitness > 0.8


def test_hypotheses_are_ranked_and_distinct(bracket):
    source = bracket[::2]
    target, _ = moved(source, np.radians(60.0), np.zeros(3))
    hypotheses = global_search(source, target, np.zeros(6), radius=0.2, config=SMALL)
    fitness = [h.fitness for h in hypotheses]
    assert fitness == sorted(fitness, reverse=True) and 1 <= len(hypotheses) <= SMALL.n_hypotheses


def test_scatter_covers_the_circle_and_the_disc():
    actions = scatter(np.array([0, 0, 0, 1.0, 2.0, 0]), 0.5, GlobalSearchConfig(n_scatter=4000),
                      np.random.default_rng(0))
    assert actions[:, 0].min() < -3.0 and actions[:, 0].max() > 3.0
    radii = np.linalg.norm(actions[:, 3:5] - [1.0, 2.0], axis=1)
    assert radii.max() <= 0.5 + 1e-12 and np.median(radii) > 0.3  # uniform on the disc: median r = 0.35
    assert np.abs(actions[:, 1:3]).max() < 0.2


def test_distinct_best_suppresses_neighbours():
    actions = np.zeros((4, 6))
    actions[1, 0] = 0.1  # same basin as 0
    actions[2, 0] = 2.0
    actions[3, 3] = 0.5
    kept = distinct_best(actions, np.array([0.0, 0.1, 0.2, 0.3]), GlobalSearchConfig(), 4)
    np.testing.assert_array_equal(kept, actions[[0, 2, 3]])


def test_config_is_validated():
    with pytest.raises(ValueError):
        GlobalSearchConfig(n_scatter=2, n_hypotheses=4)
    with pytest.raises(ValueError):
        GlobalSearchConfig(time_budget_s=0.0)
