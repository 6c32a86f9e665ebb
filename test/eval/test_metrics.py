"""Registration metrics on hand-made cases."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cemnet_ros.eval.metrics import aggregate, euler_error_deg, pair_metrics


def _rot(z, y, x):
    return Rotation.from_euler("zyx", [z, y, x], degrees=True).as_matrix()


def test_perfect_prediction_is_zero():
    r, t = _rot(30, 10, 5), np.array([0.1, -0.2, 0.3])
    m = pair_metrics(r, t, r, t)
    assert m.r_mae_deg == pytest.approx(0, abs=1e-6) and m.rot_err_deg == pytest.approx(0, abs=1e-5)
    assert m.t_mae == 0 and m.trans_err == 0


def test_euler_error_per_axis_matches_hand_values():
    np.testing.assert_allclose(euler_error_deg(_rot(12, 5, 40), _rot(10, 8, 41)), [2, -3, -1], atol=1e-9)
    m = pair_metrics(_rot(12, 5, 40), np.zeros(3), _rot(10, 8, 41), np.zeros(3))
    assert m.r_mae_deg == pytest.approx(2.0)  # (2 + 3 + 1) / 3
    assert m.r_mse_deg2 == pytest.approx(14.0 / 3.0)  # (4 + 9 + 1) / 3


def test_euler_convention_is_rx_ry_rz():
    z, y, x = np.radians([20.0, -15.0, 35.0])
    rz = np.array([[np.cos(z), -np.sin(z), 0], [np.sin(z), np.cos(z), 0], [0, 0, 1]])
    ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    rx = np.array([[1, 0, 0], [0, np.cos(x), -np.sin(x)], [0, np.sin(x), np.cos(x)]])
    np.testing.assert_allclose(euler_error_deg(rx @ ry @ rz, np.eye(3)), [20, -15, 35], atol=1e-9)


def test_wrapped_euler_difference():
    np.testing.assert_allclose(euler_error_deg(_rot(179, 0, 0), _rot(-179, 0, 0)), [-2, 0, 0], atol=1e-9)


def test_isotropic_errors():
    assert pair_metrics(_rot(0, 0, 30), np.zeros(3), np.eye(3), np.zeros(3)).rot_err_deg == pytest.approx(30.0)
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    r = Rotation.from_rotvec(np.radians(7.0) * axis).as_matrix()
    m = pair_metrics(r @ _rot(10, 20, 30), np.array([3.0, 4.0, 0.0]), _rot(10, 20, 30), np.zeros(3))
    assert m.rot_err_deg == pytest.approx(7.0)
    assert m.trans_err == pytest.approx(5.0)
    assert m.t_mae == pytest.approx(7.0 / 3.0) and m.t_mse == pytest.approx(25.0 / 3.0)


def test_aggregate_rmse_mae_and_recall():
    gt = _rot(10, 10, 10)
    good = pair_metrics(gt, np.array([0.005, 0, 0]), gt, np.zeros(3))  # t err 0.005: success
    off_t = pair_metrics(gt, np.array([0.02, 0, 0]), gt, np.zeros(3))  # t err 0.02: failure
    off_r = pair_metrics(_rot(11.5, 10, 10), np.zeros(3), gt, np.zeros(3))  # 1.5 deg: failure
    agg = aggregate([good, off_t, off_r])
    assert agg["n_pairs"] == 3
    assert agg["recall"] == pytest.approx(1 / 3)
    assert agg["r_mae_deg"] == pytest.approx(0.5 / 3, rel=1e-6)  # only off_r: 1.5 / 3 per pair
    assert agg["r_rmse_deg"] == pytest.approx(np.sqrt((1.5 ** 2 / 3) / 3), rel=1e-6)
    assert agg["t_mae"] == pytest.approx((0.005 / 3 + 0.02 / 3) / 3)
    assert agg["t_rmse"] == pytest.approx(np.sqrt((0.005 ** 2 / 3 + 0.02 ** 2 / 3) / 3))
    assert agg["trans_err_mean"] == pytest.approx(0.025 / 3)
    assert aggregate([good, off_t, off_r], trans_thresh=0.05)["recall"] == pytest.approx(2 / 3)


def test_bad_inputs():
    with pytest.raises(ValueError, match="zero pairs"):
        aggregate([])
    with pytest.raises(ValueError, match=r"\(3, 3\)"):
        pair_metrics(np.eye(4), np.zeros(3), np.eye(3), np.zeros(3))
    with pytest.raises(ValueError, match=r"\(3,\)"):
        pair_metrics(np.eye(3), np.zeros(2), np.eye(3), np.zeros(3))
    with pytest.raises(ValueError, match="non-finite"):
        pair_metrics(np.full((3, 3), np.nan), np.zeros(3), np.eye(3), np.zeros(3))
