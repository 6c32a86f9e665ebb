"""cemnet-train: a smoke run on shapes and a scan folder, bad input, flags from the schema."""
from __future__ import annotations

import csv

import numpy as np
import pytest
from tiny_training import box_union_shapes

from cemnet_ros.core.checkpoint import load_network
from cemnet_ros.core.config import UNSEEDED
from cemnet_ros.tools import train_cli
from cemnet_ros.train.config import TrainConfig


def test_cli_smoke_npz_and_scan_folder(shapes_npz, tmp_path):
    common = ["--epochs", "1", "--batch-size", "4", "--cem.n-candidates", "16", "--cem.n_iters", "2",
              "--val_cem.n_candidates", "16", "--threads", "1", "--no-progress", "--protocol.n-points", "160",
              "--protocol.n_partial", "96"]
    out = tmp_path / "cli"
    assert train_cli.main(["--data", str(shapes_npz), "--out", str(out), *common]) == 0
    with open(out / "log.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 1 and np.isfinite(float(rows[0]["val_mae_r_deg"]))
    assert load_network(out / "best.npz") is not None
    assert train_cli.main(["--data", str(shapes_npz), "--out", str(out), "--resume",
                           *[a if a != "1" else "2" for a in common[:2]], *common[2:]]) == 0
    with open(out / "log.csv", newline="") as handle:
        assert [r["epoch"] for r in csv.DictReader(handle)] == ["1", "2"]

    scans = tmp_path / "scans"
    scans.mkdir()
    for i, shape in enumerate(box_union_shapes(6, 400, seed=4)):
        np.save(scans / f"{i:06d}.npy", shape * 30.0 + 5.0)  # scanner units, off-centre
    assert train_cli.main(["--data", str(scans), "--out", str(tmp_path / "cli_scans"), *common]) == 0
    assert (tmp_path / "cli_scans" / "last.npz").is_file()


def test_cli_rejects_bad_input(tmp_path, capsys):
    assert train_cli.main(["--data", str(tmp_path / "missing.npz"), "--out", str(tmp_path / "o"),
                           "--no-progress"]) == 2
    assert "missing.npz" in capsys.readouterr().err
    assert train_cli.main(["--out", str(tmp_path), "--no-progress"]) == 2  # neither --data nor --bag
    assert "--bag" in capsys.readouterr().err


def test_cli_flags_come_from_the_schema_and_override_the_preset(tmp_path):
    parser = train_cli.build_parser()
    base = ["--data", "d.npz", "--out", str(tmp_path)]
    cpu = train_cli.config_from_args(parser.parse_args([*base, "--preset", "cpu"]), "cpu")
    assert (cpu.batch_size, cpu.lr, cpu.cem.n_candidates, cpu.val_cem.n_candidates) == (8, 1e-3, 300, 300)
    assert cpu.cem.n_fused_iters == 0 and cpu.cem.seed == UNSEEDED  # the training CEM's other settings stay
    args = parser.parse_args([*base, "--preset", "auto", "--cem.n-candidates", "40", "--val_cem.n_candidates", "50",
                              "--batch_size", "6", "--protocol.partial", "false", "--protocol.noise",
                              "--allow-pickle", "--init-weights", "w.pth", "--limit-train", "3"])
    config = train_cli.config_from_args(args, "cpu")
    assert (config.cem.n_candidates, config.val_cem.n_candidates, config.batch_size, config.lr) == (40, 50, 6, 1e-3)
    assert not config.protocol.partial and config.protocol.noise and config.allow_pickle
    assert (config.init_weights, config.limit_train, config.limit_val, config.max_minutes) == ("w.pth", 3, 0, 0.0)
    paper = train_cli.config_from_args(parser.parse_args(base), "cuda")
    assert paper == TrainConfig(data="d.npz", out_dir=str(tmp_path))
    with pytest.raises(SystemExit):
        parser.parse_args([*base, "--n-candidates", "40"])  # the old flag names are gone
    assert train_cli.main([*base, "--protocol.n_points", "2", "--no-progress"]) == 2  # out of range
