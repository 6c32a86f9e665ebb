import numpy as np
import pytest
import torch

from cemnet_ros.core import CEMConfig, RegistrationConfig, register
from cemnet_ros.core.engine import CEMNet
from cemnet_ros.core.geometry import euler_to_matrix_np, rotation_angle_deg


def _pair(bracket, angles, trans, seed=0):
    rng = np.random.default_rng(seed)
    src = bracket[:768]
    tgt = rng.permutation(bracket[256:1024] @ euler_to_matrix_np(angles).T + trans)
    return src, tgt


def test_cem_without_network_recovers_known_transform(bracket):
    """The paper's no-network ablation: prior N(0, I), paper settings otherwise."""
    angles, trans = np.radians([20.0, -15.0, 10.0]), np.array([0.2, -0.1, 0.3])
    src, tgt = _pair(bracket, angles, trans)
    res = register(src, tgt, RegistrationConfig(prior="identity"))
    assert rotation_angle_deg(res.rotation.T @ euler_to_matrix_np(angles)) < 0.5
    assert np.linalg.norm(res.translation - trans) < 0.01
    assert res.fitness > 0.5
    assert (res.sigma < 0.05).all()  # the final spread has shrunk: a confident answer


def test_gradients_reach_the_prior_through_reparameterised_candidates(bracket):
    src = torch.tensor(bracket[:200], dtype=torch.float32)[None]
    tgt = src + torch.tensor([0.05, 0.0, 0.0])
    engine = CEMNet(CEMConfig(n_candidates=64, n_iters=3, n_fused_iters=0, exploration_weight=0.0))
    mu0 = torch.zeros(1, 6, requires_grad=True)
    sigma0 = torch.full((1, 6), 0.1, requires_grad=True)
    out = engine(src, tgt, mu0, sigma0, generator=torch.Generator().manual_seed(0))
    out.mu[:, 3].sum().backward()
    assert mu0.grad is not None and mu0.grad.abs().sum() > 0
    assert sigma0.grad is not None and torch.isfinite(sigma0.grad).all()


def test_fused_reward_is_used_in_first_iterations(monkeypatch, bracket):
    from cemnet_ros.core import scoring
    calls = []
    original = scoring.CandidateScorer.cost

    def spy(self, candidates, fused):
        calls.append(fused)
        return original(self, candidates, fused)

    monkeypatch.setattr(scoring.CandidateScorer, "cost", spy)
    src = torch.tensor(bracket[:128], dtype=torch.float32)[None]
    CEMNet(CEMConfig(n_candidates=16, n_iters=5, n_fused_iters=2))(src, src)
    assert calls == [True, True, False, False, False, False]  # the last call scores mu_T for the fitness


def test_seeded_runs_are_reproducible(bracket):
    src, tgt = _pair(bracket, np.radians([5.0, 5.0, 5.0]), np.array([0.05, 0.0, 0.0]))
    cfg = RegistrationConfig(prior="identity", cem=CEMConfig(n_candidates=200, n_iters=4))
    a, b = register(src, tgt, cfg), register(src, tgt, cfg)
    np.testing.assert_array_equal(a.transform, b.transform)


@pytest.mark.parametrize("bad", [dict(n_candidates=1), dict(n_iters=0), dict(n_fused_iters=11), dict(epsilon=0),
                                 dict(alpha=1.5), dict(exploration_weight=-0.1)])
def test_invalid_config_is_rejected(bad):
    with pytest.raises(ValueError):
        CEMConfig(**bad)


def test_exploration_blend_applies_to_the_network_prior_only(monkeypatch, bracket):
    from cemnet_ros.core import engine as engine_module
    seen = []
    original = engine_module.CandidateScorer.cost

    def spy(self, candidates, fused):
        seen.append(candidates.detach().clone())
        return original(self, candidates, fused)

    monkeypatch.setattr(engine_module.CandidateScorer, "cost", spy)
    src = torch.tensor(bracket[:128], dtype=torch.float32)[None]
    cem = CEMConfig(n_candidates=4000, n_iters=1, n_fused_iters=0, exploration_weight=0.5)
    given_mu, given_sigma = torch.full((1, 6), 0.2), torch.full((1, 6), 0.01)
    CEMNet(cem)(src, src, given_mu, given_sigma)
    torch.testing.assert_close(seen[0].mean(1), given_mu, atol=2e-3, rtol=0)  # used as given
    torch.testing.assert_close(seen[0].std(1), given_sigma, atol=2e-3, rtol=0)
    seen.clear()

    class FixedNetwork(torch.nn.Module):
        def forward(self, source, target):
            return given_mu.clone(), given_sigma.clone()

    CEMNet(cem, FixedNetwork())(src, src)
    torch.testing.assert_close(seen[0].mean(1), 0.5 * given_mu, atol=0.05, rtol=0)  # blended
    expected_sigma = 0.5 * given_sigma + 0.5 * torch.tensor(cem.exploration_sigma)
    torch.testing.assert_close(seen[0].std(1), expected_sigma, atol=0.05, rtol=0)
