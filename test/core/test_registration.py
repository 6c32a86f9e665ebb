import warnings

import numpy as np
import pytest
import torch

from cemnet_ros.core import CEMConfig, Registrar, RegistrationConfig, register
from cemnet_ros.core.checkpoint import CheckpointError
from cemnet_ros.core.geometry import action_to_matrix_np, euler_to_matrix_np, rigid_transform, rotation_angle_deg

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


def test_register_batch_refines_and_scores_every_pair(bracket):
    source = bracket[:512]
    angles = np.radians([[3.0, -2.0, 1.0], [-2.0, 1.0, 2.0]])
    trans = np.array([[0.02, 0.01, -0.03], [-0.01, 0.02, 0.0]])
    targets = np.stack([source @ euler_to_matrix_np(a).T + t for a, t in zip(angles, trans)])
    config = RegistrationConfig(prior="identity", prior_sigma=(0.05,) * 6,
                                cem=CEMConfig(n_candidates=50, n_iters=2, n_fused_iters=0, refine_icp_steps=20))
    registrar = Registrar(config)
    batch = registrar.register_batch(torch.from_numpy(np.stack([source, source])), torch.from_numpy(targets))
    for b in range(2):
        assert rotation_angle_deg(batch.rotation[b].T @ euler_to_matrix_np(angles[b])) < 0.05
        np.testing.assert_allclose(batch.translation[b], trans[b], atol=1e-3)
        np.testing.assert_allclose(action_to_matrix_np(batch.mu[b]),
                                   rigid_transform(batch.rotation[b], batch.translation[b]), atol=1e-12)
        assert batch.fitness[b] > 0.9
    second = batch.pair(1, runtime_s=0.5)
    assert second.runtime_s == 0.5 and second.fitness == batch.fitness[1]
    np.testing.assert_array_equal(second.transform, rigid_transform(batch.rotation[1], batch.translation[1]))
    unmoved = registrar.register_batch(torch.from_numpy(source[None]), torch.from_numpy(source[None]), run_cem=False)
    np.testing.assert_allclose(unmoved.mu0, 0.0)
    assert unmoved.fitness[0] > 0.99
