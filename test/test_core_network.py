import numpy as np
import torch

from cemnet_ros.core.checkpoint import load_network
from cemnet_ros.core.geometry import euler_to_matrix_np
from cemnet_ros.core.network import SamplingNetwork, edge_features


def test_edge_features_are_neighbour_then_centre():
    pts = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [3, 0, 0]]])
    feats = edge_features(pts, k=2)  # (1, 6, k=2, n=3)
    # Point 2's neighbours are itself and point 1.
    neighbours = feats[0, :3, :, 2].T
    centres = feats[0, 3:, :, 2].T
    assert {tuple(v) for v in neighbours.tolist()} == {(3.0, 0, 0), (1.0, 0, 0)}
    assert (centres == torch.tensor([3.0, 0, 0])).all()


def test_output_shapes_and_sigma_range():
    net = SamplingNetwork().eval()
    mu0, sigma0 = net(torch.randn(2, 64, 3), torch.randn(2, 80, 3))
    assert mu0.shape == (2, 6) and sigma0.shape == (2, 6)
    assert ((sigma0 > 0) & (sigma0 < 1)).all()


def test_batchnorm_modes_at_inference():
    net = SamplingNetwork().eval()
    x = torch.randn(1, 64, 3)
    running = net(x, x)[0]
    net.batch_stats_at_inference = True
    batch = net(x, x)[0]
    assert not torch.allclose(running, batch)  # the two modes really differ
    net.batch_stats_at_inference = False
    torch.testing.assert_close(net(x, x)[0], running)


def test_bundled_weights_predict_a_useful_prior(bracket):
    net = load_network(None).eval()
    angles = np.array([0.3, 0.2, -0.25])
    rot, trans = euler_to_matrix_np(angles), np.array([0.2, -0.1, 0.15])
    src = bracket[:768]
    tgt = np.random.default_rng(1).permutation(src @ rot.T + trans)
    with torch.no_grad():
        mu0, _ = net(torch.tensor(src, dtype=torch.float32)[None], torch.tensor(tgt, dtype=torch.float32)[None])
    # Far better than the identity (angles ~15 deg, translation ~0.25): within a few degrees / centimetres.
    assert np.degrees(np.abs(mu0[0, :3].numpy() - angles)).max() < 6.0
    assert np.abs(mu0[0, 3:].numpy() - trans).max() < 0.06


def test_folded_batchnorm_equals_the_plain_layers():
    torch.manual_seed(0)
    net = SamplingNetwork().eval()
    for module in net.modules():
        if isinstance(module, (torch.nn.BatchNorm1d, torch.nn.BatchNorm2d)):
            module.running_mean.uniform_(-0.5, 0.5)
            module.running_var.uniform_(0.5, 2.0)
            module.weight.data.uniform_(0.5, 1.5)
            module.bias.data.uniform_(-0.2, 0.2)
    x = torch.randn(1, 64, 3)
    with torch.no_grad():
        folded = net.embedding(x, net._conv_bn_relu)
        plain = net.embedding(x, lambda conv, bn, h: torch.relu(net._norm(bn, conv(h))))
    torch.testing.assert_close(folded, plain, rtol=1e-4, atol=1e-5)
