"""Training from a bag (``cemnet-train --bag``): pairs prepared as the node prepares scans, with the truth they
claim; training on a tiny ray-cast bag lowers the loss and round-trips its checkpoint; the CLI trains, resumes
and reports. The bag (8 scans of the courtyard, 16 x 360 rays) is written by the conftest, so nothing needs ../shared.
"""
from __future__ import annotations

import csv
import json
from dataclasses import replace

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree
from tiny_training import bag_config

from cemnet_ros.core.checkpoint import load_network
from cemnet_ros.core.geometry import apply_transform, matrix_to_action_np
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.steps.frame import Preprocessor
from cemnet_ros.replay.bag_io import BagReader, BagWriter
from cemnet_ros.tools import train_cli
from cemnet_ros.train.config import ScanPairConfig
from cemnet_ros.train.data import build_datasets
from cemnet_ros.train.run import TrainReport
from cemnet_ros.train.scan_pairs import recovery_motion
from cemnet_ros.train.trainer import Trainer


# ---------------------------------------------------------------------------------------------- pairs
def test_scans_are_prepared_as_the_node_prepares_them(training_bag, scans_and_poses, tmp_path):
    train, val = build_datasets(bag_config(training_bag, tmp_path))
    assert (len(train), len(val)) == (6, 2)  # validation: the last scans
    scans, config = scans_and_poses[0], AlignerConfig()
    preprocessor = Preprocessor(config)  # the aligner's own preparation of its frames
    first = preprocessor.frame(scans[0].astype(np.float64))  # auto scale: measured on the first scan
    assert train.scans.scale == first.scale
    preprocessor.adopt(first)
    frame = preprocessor.frame(scans[1].astype(np.float64))
    np.testing.assert_allclose(train.scans.clouds[1], frame.dense, atol=1e-5)  # float32 storage


def test_pairs_carry_their_truth(training_bag, tmp_path):
    exact = ScanPairConfig(n_points=20_000, crop_deg=0.0, noise=0.0, consecutive=0.0)  # every voxel point, as is
    train, _ = build_datasets(bag_config(training_bag, tmp_path, scans=exact))
    pair = train.pair(2, np.random.default_rng(0))
    moved = apply_transform(pair.T_target_source, pair.source)
    assert cKDTree(pair.target).query(moved)[0].max() < 1e-4 < np.abs(pair.source - pair.target).max()
    two_scans, _ = build_datasets(bag_config(training_bag, tmp_path, scans=replace(exact, consecutive=1.0)))
    pair = two_scans.pair(2, np.random.default_rng(0))
    tree = cKDTree(pair.target)
    before = np.median(tree.query(pair.source)[0])
    after = np.median(tree.query(apply_transform(pair.T_target_source, pair.source))[0])
    print(f"\nconsecutive pair: median neighbour distance {before:.3f} -> {after:.4f} units under the truth")
    assert after < 0.01 and before > 5.0 * after  # the voxel grid is scale / 100 = 0.01 units


def test_motions_span_what_the_recovery_searches():
    rng, scale, radius = np.random.default_rng(1), 20.0, 10.0
    actions = np.array([matrix_to_action_np(recovery_motion(rng, radius, scale)) for _ in range(2000)])
    yaw, distance = np.degrees(actions[:, 0]), np.linalg.norm(actions[:, 3:5], axis=1)
    assert yaw.min() < -170.0 and yaw.max() > 170.0 and abs(np.mean(np.abs(yaw)) - 90.0) < 5.0  # uniform circle
    assert distance.max() <= radius and np.mean(distance < radius / 2) == pytest.approx(0.25, abs=0.04)  # disc
    assert np.degrees(np.abs(actions[:, 1:3])).max() < 10.0  # small roll and pitch


# ------------------------------------------------------------------------------------------- training
@pytest.mark.slow
def test_training_on_a_bag_lowers_the_loss_and_round_trips_the_checkpoint(training_bag, tmp_path):
    """12 steps on 4 frozen pairs (a loop whose gradients are right overfits them), then the checkpoint.

    Most points of a pair start beyond the Geman-McClure scale (yaw over the full circle), so the loss falls
    slowly; without a working step the prior's loss would not move at all (the pairs are frozen)."""
    trainer = Trainer(bag_config(training_bag, tmp_path, epochs=12, val_every=12, limit_train=4, lr=1e-2))
    trainer.train_set.fixed = True
    rows = trainer.fit()
    assert len(rows) == 12
    for key in ("train_loss", "train_loss_prior"):
        losses = [float(r[key]) for r in rows]
        first, last = np.mean(losses[:3]), np.mean(losses[-3:])
        print(f"\n{key}: first 3 epochs {first:.5f} -> last 3 epochs {last:.5f}")
        assert last < 0.95 * first, key
    with np.load(tmp_path / "last.npz", allow_pickle=False) as archive:
        assert archive.files  # the safe format: no pickle needed
    loaded = load_network(tmp_path / "last.npz")
    batch = next(iter(trainer.val_loader))
    trainer.network.eval()
    loaded.eval()
    with torch.no_grad():
        for a, b in zip(trainer.network(batch["source"], batch["target"]), loaded(batch["source"], batch["target"])):
            assert torch.equal(a, b)


@pytest.mark.slow
def test_cli_trains_from_a_bag_resumes_and_reports(training_bag, tmp_path, capsys):
    flags = ["--bag", str(training_bag), "--topic", "/points", "--out", str(tmp_path), "--batch-size", "4",
             "--cem.n_candidates", "16", "--cem.n_iters", "2", "--val_cem.n_candidates", "16",
             "--val_cem.n_fused_iters", "0", "--threads", "1", "--scans.n_points", "96", "--val_fraction", "0.25",
             "--no-progress"]
    assert train_cli.main([*flags, "--epochs", "1"]) == 0
    assert train_cli.main([*flags, "--epochs", "2", "--resume"]) == 0
    with open(tmp_path / "log.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["epoch"] for r in rows] == ["1", "2"] and np.isfinite(float(rows[-1]["val_prior_mae_r_deg"]))
    assert "## cemnet-train" in capsys.readouterr().out
    assert train_cli.main([*flags, "--topic", "/nothing"]) == 2
    assert "/nothing" in capsys.readouterr().err
    assert train_cli.main(["--out", str(tmp_path), "--no-progress"]) == 2
    assert "--bag" in capsys.readouterr().err


def test_report_as_markdown_and_json(tmp_path):
    rows = [{"epoch": 1, "train_loss": 0.5, "val_mae_r_deg": 20.0}, {"epoch": 2, "train_loss": 0.4,
                                                                         "val_mae_r_deg": 30.0}]
    report = TrainReport(str(tmp_path), "run.mcap", "cpu", 1, 5, 8, rows,
                         {"epoch": 1, "metric": "val_mae_r_deg", "value": 20.0})
    text = report.to_markdown()
    assert "2 of 5 epoch(s), 8 step(s)" in text and "| best (val_mae_r_deg) | 1 | 0.5 | 20 |" in text
    assert json.loads(report.to_json())["rows"][1]["val_mae_r_deg"] == 30.0


def test_several_bags_train_together_each_in_its_own_units(training_bag, tmp_path):
    """Two bags (comma-separated): their pairs one after the other, validation from both, each bag's own scale."""
    shrunk = tmp_path / "shrunk.mcap"  # the same scans at half the size: another scale
    with BagReader(training_bag) as reader, BagWriter(shrunk) as bag:
        for scan in reader.scans():
            bag.write_cloud("/points", 0.5 * scan.points, "lidar", scan.stamp_ns)
    train, val = build_datasets(bag_config(f"{training_bag},{shrunk}", tmp_path))
    assert (len(train), len(val)) == (12, 4)
    assert train.parts[1].scans.scale == pytest.approx(0.5 * train.parts[0].scans.scale)
    train.set_epoch(3)
    first, second = train[0], train[6]  # scan 0 of each bag: same cloud in units, other draws (seed + 1)
    assert first["source"].shape == second["source"].shape
    assert not torch.allclose(first["source"], second["source"])
    assert all(part.epoch == 3 for part in train.parts)
