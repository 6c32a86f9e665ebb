import numpy as np
import pytest
import torch

from cemnet_ros.core.geometry import euler_to_matrix_np
from cemnet_ros.core.lattice import locality_order
from cemnet_ros.core.lattice_rewards import LATTICE_SPACING, LatticePair
from cemnet_ros.core.losses import geman_mcclure_loss
from cemnet_ros.core.rewards import max_consensus_reward, nearest_sq_distances


def _mc_distance(source, target, eps):
    """The paper's D^mc = 2 - reward: the CEM's cost, 0 for a perfect overlap."""
    return 2.0 - max_consensus_reward(source, target, eps)


def test_lemma_mc_equals_chamfer_over_epsilon_when_epsilon_covers_all_distances(bracket):
    src = torch.tensor(bracket[:300])
    tgt = torch.tensor(bracket[300:600]) + 0.01
    eps = 10.0  # larger than every nearest-neighbour distance
    chamfer = (nearest_sq_distances(src, tgt)[0].sqrt().mean(-1) + nearest_sq_distances(tgt, src)[0].sqrt().mean(-1))
    torch.testing.assert_close(_mc_distance(src, tgt, eps), chamfer / eps)


def test_mc_is_zero_for_identical_and_two_for_far_clouds(bracket):
    pts = torch.tensor(bracket)
    assert _mc_distance(pts, pts, 0.1).item() == pytest.approx(0.0, abs=1e-6)
    assert _mc_distance(pts, pts + 100.0, 0.1).item() == pytest.approx(2.0)


def test_mc_by_hand():
    src = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    tgt = torch.tensor([[0.05, 0.0, 0.0]])
    # src->tgt: d = 0.05 (score 0.5), 0.95 (0); tgt->src: d = 0.05 (0.5). Reward 0.25 + 0.5.
    assert max_consensus_reward(src, tgt, 0.1).item() == pytest.approx(0.75)


def test_cpu_lattice_kernel_matches_brute_force(bracket):
    rng = np.random.default_rng(0)
    src, tgt = bracket[:768], bracket[256:1024]
    eps = 0.1
    rots = euler_to_matrix_np(rng.normal(0, 0.05, (64, 3)))
    trans = rng.normal(0, 0.03, (64, 3))
    fast = LatticePair.build(src, tgt, eps, eps * LATTICE_SPACING).rewards(rots, trans, eps)
    moved = torch.tensor(src) @ torch.tensor(rots).transpose(1, 2) + torch.tensor(trans)[:, None]
    exact = max_consensus_reward(moved, torch.tensor(tgt), eps).numpy()
    np.testing.assert_allclose(fast, exact, atol=2e-3)
    assert np.corrcoef(fast, exact)[0, 1] > 0.999


def test_geman_mcclure_loss_properties(bracket):
    pts = torch.tensor(bracket[:256])
    assert geman_mcclure_loss(pts[None], pts[None]).item() == pytest.approx(0.0)
    moved = (pts + 0.05).requires_grad_()
    loss = geman_mcclure_loss(moved[None], pts[None], mu=0.01)
    loss.backward()
    assert loss.item() > 0 and moved.grad.abs().sum() > 0
    # Bounded by 2 * mu however far apart (robust estimator).
    assert geman_mcclure_loss((pts + 100)[None], pts[None], mu=0.01).item() <= 0.02 + 1e-9


def test_cpu_and_torch_scorers_agree_on_fused_costs(bracket):
    """The numba lattice path and the brute-force torch path (CUDA's) give the same CEM costs."""
    from cemnet_ros.core.config import CEMConfig
    from cemnet_ros.core.scoring import CandidateScorer

    src = torch.tensor(bracket[:400], dtype=torch.float32)[None]
    tgt = torch.tensor(bracket[200:600] @ euler_to_matrix_np([0.05, 0.0, 0.02]).T + 0.02, dtype=torch.float32)[None]
    candidates = torch.randn(1, 48, 6, generator=torch.Generator().manual_seed(0)) * 0.05
    cpu = CandidateScorer(src, tgt, CEMConfig())
    brute = CandidateScorer(src, tgt, CEMConfig())
    brute.on_cpu = False  # the CUDA code path, run on the CPU here
    # Costs span ~0.8-1.7 here; the fused ones inherit the ICP's rare approximate neighbours (measured 0.005).
    for fused, tolerance in ((False, 1e-3), (True, 1e-2)):
        fast, exact = cpu.cost(candidates, fused), brute.cost(candidates, fused)
        torch.testing.assert_close(fast, exact, atol=tolerance, rtol=0)


def test_cpu_costs_do_not_depend_on_the_order_of_the_points(bracket):
    """The scorer reorders clouds along a Z-order curve for speed: a permutation, so the costs stay the same."""
    from cemnet_ros.core.config import CEMConfig
    from cemnet_ros.core.scoring import CandidateScorer

    order = locality_order(bracket)
    assert np.array_equal(np.sort(order), np.arange(len(bracket)))
    src = torch.tensor(bracket[:500], dtype=torch.float32)[None]
    tgt = torch.tensor(bracket[100:600] + 0.01, dtype=torch.float32)[None]
    shuffle = torch.from_numpy(np.random.default_rng(0).permutation(500))
    candidates = torch.randn(1, 32, 6, generator=torch.Generator().manual_seed(0)) * 0.05
    for fused in (False, True):
        torch.testing.assert_close(CandidateScorer(src, tgt, CEMConfig()).cost(candidates, fused),
                                   CandidateScorer(src[:, shuffle], tgt[:, shuffle.flip(0)], CEMConfig()).cost(
                                       candidates, fused), atol=1e-6, rtol=0)


def test_non_finite_candidates_get_the_worst_cost(bracket):
    from cemnet_ros.core.config import CEMConfig
    from cemnet_ros.core.scoring import CandidateScorer

    cloud = torch.tensor(bracket[:300], dtype=torch.float32)[None]
    candidates = torch.zeros(1, 4, 6)
    candidates[0, 1, 0], candidates[0, 2, 4], candidates[0, 3, 5] = float("nan"), float("inf"), -float("inf")
    for fused in (False, True):
        cost = CandidateScorer(cloud, cloud, CEMConfig()).cost(candidates, fused)
        assert cost[0, 0] < 0.01 and torch.equal(cost[0, 1:], torch.full((3,), 2.0))
