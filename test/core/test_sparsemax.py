import torch

from cemnet_ros.core.sparsemax import sparsemax


def test_hand_computed_cases():
    torch.testing.assert_close(sparsemax(torch.tensor([1.0, 0.0, -1.0])), torch.tensor([1.0, 0.0, 0.0]))
    torch.testing.assert_close(sparsemax(torch.tensor([0.5, 0.3, -1.0])), torch.tensor([0.6, 0.4, 0.0]))
    torch.testing.assert_close(sparsemax(torch.tensor([2.0, 2.0, 2.0, 2.0])), torch.full((4,), 0.25))


def test_projection_onto_simplex_along_dim():
    z = torch.randn(5, 7, 3)
    p = sparsemax(z, dim=1)
    assert (p >= 0).all()
    torch.testing.assert_close(p.sum(1), torch.ones(5, 3))


def test_exact_jacobian_matches_finite_differences():
    torch.manual_seed(0)
    z = torch.randn(4, 6, dtype=torch.float64) * 0.5
    assert torch.autograd.gradcheck(lambda x: sparsemax(x, dim=1), (z.requires_grad_(),), eps=1e-6, atol=1e-5)


def test_hand_computed_jacobian():
    # Support {0, 1}: J = diag(1,1,0) - [[.5,.5,0],[.5,.5,0],[0,0,0]].
    z = torch.tensor([0.5, 0.3, -1.0], requires_grad=True)
    jac = torch.autograd.functional.jacobian(sparsemax, z)
    expected = torch.tensor([[0.5, -0.5, 0.0], [-0.5, 0.5, 0.0], [0.0, 0.0, 0.0]])
    torch.testing.assert_close(jac, expected)
