"""The global CEM search finds motions that a local search around the identity cannot."""
import numpy as np
import pytest
from courtyard_pair import courtyard_pair

from cemnet_ros.core import CEMConfig
from cemnet_ros.core.geometry import euler_to_matrix_np, matrix_to_action_np, rotation_angle_deg
from cemnet_ros.core.global_search import GlobalSearchConfig, SearchPrior, distinct_best, global_search, scatter

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
    with pytest.raises(ValueError, match="n_network"):
        GlobalSearchConfig(n_network=-1)
    with pytest.raises(ValueError, match="network_scale"):
        GlobalSearchConfig(network_scale=0.0)
    GlobalSearchConfig(n_scatter=100, n_network=5000)  # the prior's draws come on top of the uniform scatter


def scatter_before_the_prior(centre, radius, config, rng):
    """The scatter as it was before the prior existed (frozen copy): without a prior nothing may change."""
    n = config.n_scatter
    r, angle = radius * np.sqrt(rng.uniform(0.0, 1.0, n)), rng.uniform(-np.pi, np.pi, n)
    actions = np.empty((n, 6))
    actions[:, 0] = centre[0] + rng.uniform(-np.pi, np.pi, n)
    actions[:, 1] = centre[1] + rng.normal(0.0, config.tilt_sigma, n)
    actions[:, 2] = centre[2] + rng.normal(0.0, config.tilt_sigma, n)
    actions[:, 3] = centre[3] + r * np.cos(angle)
    actions[:, 4] = centre[4] + r * np.sin(angle)
    actions[:, 5] = centre[5] + rng.normal(0.0, config.height_sigma, n)
    return actions


def test_without_a_prior_the_scatter_and_the_search_are_unchanged(bracket):
    centre = np.array([0.2, 0.0, 0.0, 1.0, 2.0, 0.1])
    for config in (GlobalSearchConfig(), GlobalSearchConfig(n_scatter=300, n_network=7, network_scale=3.0)):
        np.testing.assert_array_equal(scatter(centre, 0.5, config, np.random.default_rng(5)),
                                      scatter_before_the_prior(centre, 0.5, config, np.random.default_rng(5)))
    with_prior = scatter(centre, 0.5, GlobalSearchConfig(n_network=7), np.random.default_rng(5),
                         SearchPrior(np.ones(6), np.full(6, 0.1)))
    assert with_prior.shape == (2007, 6)  # the prior's draws first, then the same uniform scatter
    np.testing.assert_array_equal(with_prior[7:], scatter_before_the_prior(centre, 0.5, GlobalSearchConfig(),
                                                                           np.random.default_rng(5)))
    source = bracket[::2]
    target, _ = moved(source, np.radians(150.0), np.array([0.3, -0.2, 0.0]))
    plain, inert = (global_search(source, target, np.zeros(6), 0.5, GlobalSearchConfig(
        n_scatter=1000, n_network=n_network, network_scale=scale, refine=SMALL.refine), seed=3)
        for n_network, scale in ((500, 1.0), (20, 4.0)))
    for a, b in zip(plain, inert):  # the prior's settings are inert without a prior: bit for bit
        np.testing.assert_array_equal(a.T_target_source, b.T_target_source)
        assert a.fitness == b.fitness and np.array_equal(a.sigma, b.sigma)


COURTYARD_SCALE = 15.0  # metres per unit (the pipeline measures a scan's robust radius instead)


def courtyard_pair_in_units():
    """A courtyard pair 140 deg and 3.6 m apart: (source, target) 512 points each in units, and the true
    T_target_source in units."""
    target, source, motion = courtyard_pair()
    rng = np.random.default_rng(0)

    def within(points, radius_m):
        points = points[np.linalg.norm(points, axis=1) < radius_m]
        return points[rng.choice(len(points), 512, replace=False)] / COURTYARD_SCALE

    to_units = np.diag([1.0 / COURTYARD_SCALE] * 3 + [1.0])
    return within(source, 22.0), within(target, 32.0), to_units @ motion @ np.linalg.inv(to_units)


@pytest.mark.parametrize("seed", [0, 3])
def test_a_prior_at_the_true_motion_finds_what_a_tiny_scatter_misses(seed):
    source, target, truth = courtyard_pair_in_units()
    tiny = GlobalSearchConfig(n_scatter=8, n_seeds=2, n_per_seed=0, n_hypotheses=2, n_network=8,
                              refine=CEMConfig(n_candidates=50, n_iters=3, n_fused_iters=1))
    prior = SearchPrior(matrix_to_action_np(truth), np.array([0.05, 0.02, 0.02, 0.05, 0.05, 0.01]))
    radius = 10.0 / COURTYARD_SCALE

    def error(hypothesis):  # (metres, degrees)
        offset = np.linalg.inv(truth) @ hypothesis.T_target_source
        return np.linalg.norm(offset[:3, 3]) * COURTYARD_SCALE, rotation_angle_deg(offset[:3, :3])

    metres, degrees = error(global_search(source, target, np.zeros(6), radius, tiny, seed=seed)[0])
    assert metres > 2.0 or degrees > 5.0  # 8 uniform candidates miss the basin
    metres, degrees = error(global_search(source, target, np.zeros(6), radius, tiny, seed=seed, prior=prior)[0])
    assert metres < 0.5 and degrees < 3.0
