"""Classical baselines: ICP recovers small motions; FPFH+RANSAC (Open3D, optional) a large one."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cemnet_ros.data.shapes import bracket_shape
from cemnet_ros.eval import baselines
from cemnet_ros.eval.baselines import BaselineUnavailable, ICPConfig, fpfh_ransac, icp, open3d_available
from cemnet_ros.eval.metrics import pair_metrics
from cemnet_ros.eval.protocol import ProtocolConfig, make_pair

SHAPE = bracket_shape(1024, seed=1).astype(np.float64)


def test_icp_recovers_small_known_transform():
    r = Rotation.from_euler("zyx", [4, -3, 5], degrees=True).as_matrix()
    t = np.array([0.03, -0.02, 0.04])
    target = SHAPE[::-1] @ r.T + t  # no index correspondence
    rot, trans = icp(SHAPE, target)
    m = pair_metrics(rot, trans, r, t)
    assert m.rot_err_deg < 0.05 and m.trans_err < 1e-3


def test_icp_iteration_limit_matters():
    r = Rotation.from_euler("zyx", [8, 0, 0], degrees=True).as_matrix()
    target = SHAPE @ r.T
    one = pair_metrics(*icp(SHAPE, target, ICPConfig(max_iterations=1)), r, np.zeros(3))
    full = pair_metrics(*icp(SHAPE, target), r, np.zeros(3))
    assert full.rot_err_deg < one.rot_err_deg


def test_icp_init_and_max_distance():
    r = Rotation.from_euler("zyx", [30, 20, 10], degrees=True).as_matrix()
    t = np.array([0.2, 0.1, -0.1])
    init = np.eye(4)
    init[:3, :3] = Rotation.from_euler("zyx", [28, 21, 9], degrees=True).as_matrix()
    init[:3, 3] = t + 0.01
    rot, trans = icp(SHAPE, SHAPE @ r.T + t, ICPConfig(max_distance=0.2), init=init)
    assert pair_metrics(rot, trans, r, t).rot_err_deg < 0.05


def test_icp_bad_input():
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        icp(np.zeros((10, 2)), SHAPE)
    with pytest.raises(ValueError, match=">= 3 points"):
        icp(SHAPE[:2], SHAPE)
    bad = SHAPE.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        icp(SHAPE, bad)


def test_fpfh_unavailable_message(monkeypatch):
    def broken():
        raise BaselineUnavailable("the FPFH+RANSAC baseline needs Open3D, which cannot be imported (test)")

    monkeypatch.setattr(baselines, "_import_open3d", broken)
    with pytest.raises(BaselineUnavailable, match="Open3D"):
        fpfh_ransac(SHAPE, SHAPE)


@pytest.mark.skipif(not open3d_available(), reason="Open3D (optional extra open3d-cpu) is not importable")
def test_fpfh_ransac_recovers_protocol_pair():
    pair = make_pair(bracket_shape(2048, seed=5), np.random.default_rng(0), ProtocolConfig(partial=False))
    m = pair_metrics(*fpfh_ransac(pair.source, pair.target), pair.rotation, pair.translation)
    assert m.rot_err_deg < 1.0 and m.trans_err < 0.01
    again = pair_metrics(*fpfh_ransac(pair.source, pair.target), pair.rotation, pair.translation)
    assert again.rot_err_deg == pytest.approx(m.rot_err_deg)  # seeded
