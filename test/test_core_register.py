import warnings

import numpy as np
import pytest

from cemnet_ros.core import CEMConfig, RegistrationConfig, register
from cemnet_ros.core.checkpoint import CheckpointError
from cemnet_ros.core.geometry import euler_to_matrix_np, rotation_angle_deg

FAST = RegistrationConfig(cem=CEMConfig(n_candidates=200, n_iters=5, n_fused_iters=1))


def test_default_register_with_bundled_network(bracket):
    angles, trans = np.radians([30.0, 10.0, -20.0]), np.array([0.3, -0.2, 0.1])
    tgt = bracket @ euler_to_matrix_np(angles).T + trans
    res = register(bracket, tgt)  # 1024 points: sub-sampled to 768
    assert rotation_angle_deg(res.rotation.T @ euler_to_matrix_np(angles)) < 0.5
    assert np.linalg.norm(res.translation - trans) < 0.01
    assert res.transform.shape == (4, 4) and 0.0 <= res.fitness <= 1.0


def test_prior_pose_replaces_the_network(bracket):
    angles, trans = np.radians([3.0, -2.0, 1.0]), np.array([0.02, 0.01, -0.03])
    tgt = bracket @ euler_to_matrix_np(angles).T + trans
    prior = np.eye(4)
    res = register(bracket, tgt, FAST, prior_pose=prior, prior_sigma=np.full(6, 0.05))
    np.testing.assert_allclose(res.mu0, 0.0)
    np.testing.assert_allclose(res.sigma0, 0.05, rtol=1e-6)
    assert rotation_angle_deg(res.rotation.T @ euler_to_matrix_np(angles)) < 0.5


def test_nan_rows_are_dropped_with_a_warning(bracket):
    src = bracket.copy()
    src[::10] = np.nan
    with pytest.warns(UserWarning, match="non-finite"):
        res = register(src, bracket, FAST)
    assert np.isfinite(res.transform).all()


@pytest.mark.parametrize("source, message", [
    (np.zeros((0, 3)), "at least"),
    (np.full((50, 3), np.nan), "at least"),
    (np.zeros((5, 3)), "at least"),
    (np.zeros((100, 2)), r"\(n, 3\)"),
    (np.zeros(300), r"\(n, 3\)"),
    (np.array([["a", "b", "c"]] * 40), "numeric"),
])
def test_bad_input_raises_clear_errors(bracket, source, message):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ValueError, match=message):
            register(source, bracket, FAST)


def test_bad_prior_pose_is_rejected(bracket):
    with pytest.raises(ValueError, match="prior_pose"):
        register(bracket, bracket, FAST, prior_pose=np.eye(3))


def test_missing_weights_raise_checkpoint_error(bracket, tmp_path):
    with pytest.raises(CheckpointError):
        register(bracket, bracket, RegistrationConfig(weights=str(tmp_path / "nope.npz")))


def test_invalid_registration_config():
    with pytest.raises(ValueError):
        RegistrationConfig(prior="magic")
    with pytest.raises(ValueError):
        RegistrationConfig(n_points=8)


def test_register_keeps_the_engines_of_the_most_recent_configs_only(bracket):
    from cemnet_ros.core import registration

    registration._DEFAULT_REGISTRARS.clear()
    configs = [RegistrationConfig(n_points=64 + k, cem=CEMConfig(n_candidates=20, n_iters=1, n_fused_iters=0, seed=0))
               for k in range(registration.REGISTRARS_KEPT + 2)]
    for config in configs:
        register(bracket, bracket, config)
    register(bracket, bracket, configs[2])  # used again: becomes the most recent
    kept = list(registration._DEFAULT_REGISTRARS)
    assert len(kept) == registration.REGISTRARS_KEPT
    assert kept[-1] == repr(configs[2]) and repr(configs[0]) not in kept and repr(configs[1]) not in kept
