"""Adaptive spread, the running level, Hessian covariance and degenerate directions (no engine needed)."""
import numpy as np
import pytest
from street_scene import make_transform

from cemnet_ros.core.geometry import so3_exp, so3_log
from cemnet_ros.pipeline.config import AdaptiveConfig
from cemnet_ros.pipeline.steps.adaptive import AdaptiveSpread
from cemnet_ros.pipeline.steps.covariance import (
    MIN_STD_ROTATION,
    Conditioning,
    carried_into_step,
    covariance_from_hessian,
    flat_covariance,
    keep_prediction_along,
    moved_by,
)
from cemnet_ros.pipeline.steps.health import Level, RunningLevel, Signals

GOOD = Signals(fitness=0.8, disagreement_m=0.05, disagreement_rad=0.005, conditioning=0.3, spread_m=0.1)


def with_(**changes):
    return Signals(**{**vars(GOOD), **changes})


def test_spread_starts_at_the_initial_values_then_follows_the_prediction_errors():
    spread = AdaptiveSpread(AdaptiveConfig(initial_rotation=0.05, initial_translation=0.5, factor=3.0))
    assert spread.spread() == (0.05, 0.5)
    for _ in range(10):
        spread.update(make_transform(yaw=0.01, t=(0.2, 0.0, 0.0)))
    rotation, translation = spread.spread()
    assert rotation == pytest.approx(0.03) and translation == pytest.approx(0.6)
    assert spread.spread(dt_ratio=2.0) == pytest.approx((0.06, 1.2))  # a dropped scan widens the search
    spread.reset()
    assert spread.spread() == (0.05, 0.5)


def test_spread_is_clipped():
    config = AdaptiveConfig(min_rotation=0.01, min_translation=0.1, max_rotation=0.2, max_translation=2.0)
    spread = AdaptiveSpread(config)
    spread.update(np.eye(4))
    assert spread.spread() == (0.01, 0.1)
    spread.update(make_transform(yaw=3.0, t=(50.0, 0, 0)))
    assert spread.spread() == (0.2, 2.0)
    with pytest.raises(ValueError):
        AdaptiveConfig(min_rotation=0.5, max_rotation=0.1)


def test_the_running_level_follows_the_vouched_fitness_and_coverage_until_reset():
    level = RunningLevel(memory=0.5)
    assert level.level is None
    level.accept(Signals(0.8, 0.0, 0.0, 0.1, 0.0, coverage=1.0))
    assert level.level == Level(pytest.approx(0.8), pytest.approx(1.0))
    level.accept(Signals(0.4, 0.0, 0.0, 0.1, 0.0, coverage=0.8))
    assert level.level == Level(pytest.approx(0.6), pytest.approx(0.9))
    level.reset()
    assert level.level is None


def test_consistency_is_the_share_on_surfaces_less_the_share_off_the_map():
    assert with_(fitness=0.6, coverage=0.99).consistency == pytest.approx(0.59)
    assert with_(fitness=0.65, coverage=0.85).consistency == pytest.approx(0.5)


def corridor_hessian(length=10.0):
    """Point-to-plane Hessian of a corridor along x: normals +-y (walls) and +-z (floor, ceiling) only."""
    rng = np.random.default_rng(0)
    rows = []
    for normal in ([0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]):
        n = np.array(normal, float)
        for _ in range(200):
            p = np.r_[rng.uniform(-length, length), rng.uniform(-1.5, 1.5, 2)]
            p[np.argmax(np.abs(n))] = 1.5 * n[np.argmax(np.abs(n))]
            rows.append(np.r_[np.cross(p, n), n])
    jacobian = np.array(rows)
    return jacobian.T @ jacobian


def test_corridor_is_degenerate_along_its_axis_and_the_covariance_grows_there():
    conditioning = Conditioning.of(corridor_hessian(), length=5.0)
    assert conditioning.ratio < 1e-6
    basis = conditioning.degenerate_basis(0.02)
    assert basis.shape[1] == 1 and abs(basis[3, 0]) > 0.99  # translation along x
    cov = covariance_from_hessian(conditioning, 1e-4, degenerate_variance=0.5 ** 2, min_ratio=0.02)
    np.testing.assert_allclose(cov, cov.T)
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    assert cov[0, 0] > 100 * cov[1, 1] and cov[0, 0] == pytest.approx(0.25, rel=0.01)


def test_well_constrained_covariance_is_sigma_squared_h_inverse():
    rng = np.random.default_rng(1)
    jacobian = rng.normal(size=(500, 6))
    hessian = jacobian.T @ jacobian
    cov = covariance_from_hessian(Conditioning.of(hessian, 1.0), 0.01, degenerate_variance=1.0, min_ratio=1e-6)
    expected = 0.01 * np.linalg.inv(hessian)
    order = [3, 4, 5, 0, 1, 2]
    np.testing.assert_allclose(cov - np.diag(np.r_[np.full(3, 1e-6), np.full(3, MIN_STD_ROTATION ** 2)]),
                               expected[np.ix_(order, order)], rtol=1e-6, atol=1e-12)
    inflated = covariance_from_hessian(Conditioning.of(hessian, 1.0), 0.01, 1.0, 1e-6, inflate=100.0)
    assert np.all(np.diag(inflated) > 50 * np.diag(cov))


def test_keep_prediction_along_replaces_only_the_free_direction():
    conditioning = Conditioning.of(corridor_hessian(), length=5.0)
    predicted = make_transform(yaw=0.1, t=(1.0, 0.0, 0.0))
    registered = make_transform(yaw=0.12, t=(0.2, 0.05, 0.01))  # along x the registration is arbitrary
    kept = keep_prediction_along(conditioning.degenerate_basis(0.02), 5.0, predicted, registered)
    np.testing.assert_allclose(kept[:3, 3], [1.0, 0.05, 0.01], atol=1e-9)
    np.testing.assert_allclose(kept[:3, :3], registered[:3, :3], atol=1e-9)


def test_flat_covariance_is_floored():
    cov = flat_covariance(0.0, 0.0)
    assert np.linalg.matrix_rank(cov) == 6 and np.all(np.diag(cov) > 0)


def perturbed(T_odom_sensor: np.ndarray, error: np.ndarray) -> np.ndarray:
    """``T_odom_sensor`` with a ROS-order error [v, w]: R <- exp([w]x) R, t <- t + v."""
    out = T_odom_sensor.copy()
    out[:3, :3] = so3_exp(error[3:]) @ T_odom_sensor[:3, :3]
    out[:3, 3] += error[:3]
    return out


def test_a_pose_error_moved_by_the_step_is_the_error_it_makes_at_the_next_pose():
    """Errors drawn at the previous pose, carried through the step's motion: their spread at the current pose
    (the same parameterisation: rotation about the current position) is :func:`moved_by` the step's lever."""
    rng = np.random.default_rng(4)
    T_odom_previous, T_previous_current = make_transform(yaw=0.4, t=(1.0, 2.0, 0.5)), make_transform(
        yaw=0.1, t=(3.0, -1.0, 0.2))
    T_odom_current = T_odom_previous @ T_previous_current
    covariance = np.diag([1e-6, 4e-6, 1e-6, 1e-6, 4e-6, 9e-6])
    errors = []
    for e in rng.multivariate_normal(np.zeros(6), covariance, size=4000):
        moved = perturbed(T_odom_previous, e) @ T_previous_current
        errors.append(np.r_[moved[:3, 3] - T_odom_current[:3, 3],
                            so3_log(moved[:3, :3] @ T_odom_current[:3, :3].T)])
    lever = T_odom_current[:3, 3] - T_odom_previous[:3, 3]
    expected = moved_by(covariance, lever)
    np.testing.assert_allclose(np.cov(np.array(errors).T), expected, atol=0.1 * np.max(np.diag(expected)))
    assert expected[1, 1] > 2 * covariance[1, 1]  # the yaw error moved the current position sideways


def test_a_step_carries_the_previous_pose_error_against_the_map():
    """The step's covariance adds the previous pose's error (moved to the current position) to the
    registration's; a previous pose the map was started from adds nothing."""
    T_odom_previous, T_odom_current = np.eye(4), make_transform(t=(2.0, 0.0, 0.0))
    assert not carried_into_step(np.zeros((6, 6)), T_odom_previous, T_odom_current).any()
    yaw_only = np.diag([0.0, 0.0, 0.0, 0.0, 0.0, 1e-6])  # 1 mrad of yaw, 2 m behind: 2 mm sideways
    carried = carried_into_step(yaw_only, T_odom_previous, T_odom_current)
    np.testing.assert_allclose(np.diag(carried), [0.0, 4e-6, 0.0, 0.0, 0.0, 1e-6])
    assert carried[1, 5] == pytest.approx(2e-6)  # sideways error and yaw error go together
