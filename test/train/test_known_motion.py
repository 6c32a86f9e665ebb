"""The known-motion objective: its terms vanish for a perfect prediction, pairs without a known motion never enter
them, bag pairs say which motions are known, and a few steps on frozen bag pairs lower every term."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch
from tiny_training import bag_config

from cemnet_ros.core.geometry import matrix_to_action_np
from cemnet_ros.core.network import Prediction
from cemnet_ros.train.config import ScanPairConfig
from cemnet_ros.train.data import build_datasets
from cemnet_ros.train.known_motion import KnownMotionConfig, action_error, known_motion_losses
from cemnet_ros.train.trainer import Trainer


def perfect_batch(n_pairs: int = 3, n_points: int = 40) -> tuple:
    """Pairs of a cloud and itself, predicted exactly: one-hot matches, mu0 = 0, sigma0 = 0.5."""
    source = torch.randn(n_pairs, n_points, 3)
    rotation = torch.eye(3, dtype=torch.float64).expand(n_pairs, 3, 3).clone()
    translation = torch.zeros(n_pairs, 3, dtype=torch.float64)
    prediction = Prediction(torch.zeros(n_pairs, 6), torch.full((n_pairs, 6), 0.5),
                            torch.eye(n_points).expand(n_pairs, n_points, n_points).clone())
    return source, source.clone(), rotation, translation, prediction


def test_a_perfect_prediction_has_no_matching_or_pose_loss():
    source, target, rotation, translation, prediction = perfect_batch()
    losses = known_motion_losses(source, target, rotation, translation, torch.ones(3, dtype=torch.bool), prediction,
                                 KnownMotionConfig())
    assert losses["match"].item() == pytest.approx(0.0, abs=1e-6)
    assert losses["pose"].item() == pytest.approx(0.0, abs=1e-5)
    assert losses["sigma"].item() == pytest.approx(6 * np.log(0.5), abs=1e-5)  # error 0: only the log-spread


def test_pairs_without_a_known_motion_are_left_out():
    source, target, rotation, translation, prediction = perfect_batch()
    rotation[1], translation[1] = torch.nan, torch.nan  # a two-scan pair without ground truth
    prediction.match[1] = 1.0 / prediction.match.shape[-1]  # and predicted badly: it must not count
    known = torch.tensor([True, False, True])
    losses = known_motion_losses(source, target, rotation, translation, known, prediction, KnownMotionConfig())
    assert all(torch.isfinite(v) for v in losses.values())
    assert losses["match"].item() == pytest.approx(0.0, abs=1e-6)
    none = known_motion_losses(source, target, rotation, translation, torch.zeros(3, dtype=torch.bool), prediction,
                               KnownMotionConfig())
    assert none["total"].item() == 0.0


def test_angle_errors_wrap_around_the_circle():
    rotation = torch.tensor(np.diag([-1.0, -1.0, 1.0]))[None]  # yaw 180 deg
    mu0 = torch.tensor([[-np.pi + 0.1, 0.0, 0.0, 0.0, 0.0, 0.0]], dtype=torch.float64)
    assert abs(action_error(rotation, torch.zeros(1, 3, dtype=torch.float64), mu0)[0, 0].item()) == pytest.approx(0.1)


def test_bag_pairs_flag_the_motions_they_know(training_bag, tmp_path):
    one_scan, _ = build_datasets(bag_config(training_bag, tmp_path, scans=ScanPairConfig(n_points=64,
                                                                                          consecutive=0.0)))
    two_scans, _ = build_datasets(bag_config(training_bag, tmp_path, scans=ScanPairConfig(n_points=64,
                                                                                           consecutive=1.0)))
    assert all(bool(one_scan[i]["known_motion"]) for i in range(len(one_scan)))
    assert not any(bool(two_scans[i]["known_motion"]) for i in range(len(two_scans)))  # truth from ground truth


@pytest.mark.parametrize("centre", ["sensor", "centroid"])
def test_sensor_centred_pairs_hold_the_recovery_motion(training_bag, tmp_path, centre):
    """Centred on the target's sensor, a one-scan pair's truth is the drawn motion itself: its translation stays
    on the recovery's disc (radius / scale); centred on the centroid, the yaw about the sensor adds a shift."""
    pairs = ScanPairConfig(n_points=64, consecutive=0.0, centre=centre)
    train, _ = build_datasets(bag_config(training_bag, tmp_path, scans=pairs))
    shifts = [np.linalg.norm(matrix_to_action_np(train.pair(i, np.random.default_rng(i)).T_target_source)[3:5])
              for i in range(len(train))]
    on_disc = max(shifts) <= pairs.radius / train.scans.scale + 1e-6
    assert on_disc == (centre == "sensor")


@pytest.mark.slow
def test_training_with_known_motions_lowers_every_term(training_bag, tmp_path):
    config = bag_config(training_bag, tmp_path, objective="known_motion", epochs=20, val_every=20, limit_train=4,
                        scans=ScanPairConfig(n_points=128, consecutive=0.0))
    trainer = Trainer(config)
    trainer.train_set.fixed = True  # frozen pairs: a loop whose gradients are right overfits them
    rows = trainer.fit()
    for key in ("train_loss", "train_loss_match", "train_loss_prior", "train_loss_sigma"):
        series = [float(r[key]) for r in rows]
        print(f"\n{key}: {np.mean(series[:3]):.4f} -> {np.mean(series[-3:]):.4f}")
        assert np.mean(series[-3:]) < np.mean(series[:3]) - 0.05 * abs(np.mean(series[:3])), key
    assert float(rows[-1]["val_prior_mae_r_deg"]) >= 0.0  # validated with the CEM, as the paper objective


def test_known_motion_refuses_several_processes(training_bag, tmp_path):
    from cemnet_ros.train import distributed as ddp
    info = replace(ddp.DistInfo(device=torch.device("cpu")), world_size=2)
    with pytest.raises(ValueError, match="one process"):
        Trainer(bag_config(training_bag, tmp_path, objective="known_motion"), info)
