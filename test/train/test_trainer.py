"""Unsupervised training: data reproducibility, loss decrease, checkpoint/resume, DDP on gloo, CLI smoke test.

Everything runs on tiny synthetic shapes (asymmetric unions of boxes, 160 points, partial crops of 96 points)
made here, with few candidates, so the whole file takes about a minute on 2 cores.
"""
from __future__ import annotations

import csv
import socket
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from shared_data import MODELNET, requires_shared

from cemnet_ros.core.checkpoint import load_network
from cemnet_ros.core.config import UNSEEDED, CEMConfig
from cemnet_ros.eval.protocol import ProtocolConfig
from cemnet_ros.tools import train_cli
from cemnet_ros.train.config import TrainConfig, epoch_learning_rate
from cemnet_ros.train.data import PairDataset, build_datasets, drop_duplicates, load_scan_shapes, split_train_val
from cemnet_ros.train.trainer import Trainer

SUBSET = MODELNET
TINY = ProtocolConfig(n_points=160, n_partial=96)


def box_union_shapes(n_shapes: int, n_points: int, seed: int) -> np.ndarray:
    """Asymmetric shapes: points on the surfaces of 3 random boxes each, shuffled, in the unit sphere."""
    rng = np.random.default_rng(seed)
    shapes = []
    for _ in range(n_shapes):
        parts = []
        for box in range(3):
            size = rng.uniform(0.2, 1.0, 3)
            centre = rng.uniform(-0.6, 0.6, 3)
            pts = rng.uniform(-0.5, 0.5, (n_points, 3))
            axis = rng.integers(0, 3, n_points)
            pts[np.arange(n_points), axis] = rng.choice([-0.5, 0.5], n_points)  # onto a face
            parts.append(pts * size + centre)
        pts = np.concatenate(parts)[rng.permutation(3 * n_points)[:n_points]]
        pts -= pts.mean(0)
        shapes.append(pts / np.linalg.norm(pts, axis=1).max())
    return np.stack(shapes).astype(np.float32)


@pytest.fixture(scope="module")
def shapes_npz(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("shapes") / "tiny.npz"
    n = 12
    np.savez(path, points=box_union_shapes(n, TINY.n_points, seed=1), labels=np.arange(n) % 4,
             split=np.array(["train"] * 10 + ["test"] * 2))
    return path


def tiny_config(data: Path, out: Path, **overrides) -> TrainConfig:
    cem = CEMConfig(n_candidates=24, n_iters=3, n_fused_iters=0, exploration_weight=0.0, seed=UNSEEDED)
    val_cem = CEMConfig(n_candidates=24, n_iters=3, n_fused_iters=1)
    base = TrainConfig(data=str(data), out_dir=str(out), batch_size=4, lr=1e-3, epochs=1, cem=cem, val_cem=val_cem,
                       protocol=TINY, val_fraction=0.2, threads=1, progress=False, seed=5)
    return replace(base, **overrides)


# ------------------------------------------------------------------------------------------------ data
def test_pairs_reproducible_per_epoch_and_fixed_for_validation():
    shapes = box_union_shapes(3, TINY.n_points, seed=2)
    train, val = PairDataset(shapes, TINY, seed=9), PairDataset(shapes, TINY, seed=9, fixed=True)
    train.set_epoch(1)
    a = train[1]
    assert a["source"].shape == (TINY.n_partial, 3) and a["rotation"].shape == (3, 3)
    again = PairDataset(shapes, TINY, seed=9)
    again.set_epoch(1)
    assert torch.equal(a["source"], again[1]["source"]) and torch.equal(a["rotation"], again[1]["rotation"])
    train.set_epoch(2)
    assert not torch.equal(a["rotation"], train[1]["rotation"])  # a new pose every epoch
    v1 = val[0]["rotation"]
    val.set_epoch(7)
    assert torch.equal(v1, val[0]["rotation"])  # validation pairs never change
    # target ~= R source + t holds for the full (uncropped, noise-free) protocol
    full = PairDataset(shapes, ProtocolConfig(n_points=TINY.n_points, partial=False), seed=9)[0]
    moved = full["source"].double() @ full["rotation"].double().T + full["translation"].double()
    d = torch.cdist(moved, full["target"].double()).min(1).values
    assert d.max() < 1e-5


def test_duplicate_shapes_are_dropped():
    shapes = box_union_shapes(3, 40, seed=0)
    with pytest.warns(UserWarning, match="1 exact duplicate"):
        kept = drop_duplicates(np.concatenate([shapes, shapes[1:2]]))
    assert np.array_equal(kept, shapes)


def test_split_is_disjoint_and_seeded():
    train, val = split_train_val(50, 0.1, seed=3)
    assert len(val) == 5 and len(train) == 45 and not set(train) & set(val)
    assert np.array_equal(val, split_train_val(50, 0.1, seed=3)[1])
    with pytest.raises(ValueError):
        split_train_val(1, 0.1, seed=3)


def test_scan_folder_is_normalised_and_bad_files_are_skipped(tmp_path):
    rng = np.random.default_rng(0)
    for i in range(3):
        np.save(tmp_path / f"scan{i}.npy", rng.normal(size=(500, 3)) * 20.0 + 100.0)
    np.save(tmp_path / "tiny.npy", rng.normal(size=(10, 3)))
    (tmp_path / "notes.txt").write_text("ignored")
    with pytest.warns(UserWarning, match="tiny.npy"):
        shapes, files = load_scan_shapes(tmp_path, 200, seed=1, progress=False)
    assert shapes.shape == (3, 200, 3) and [f.name for f in files] == ["scan0.npy", "scan1.npy", "scan2.npy"]
    assert np.allclose(shapes.mean(1), 0.0, atol=1e-5)
    assert np.allclose(np.linalg.norm(shapes, axis=2).max(1), 1.0, atol=1e-5)
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no scans"):
        load_scan_shapes(tmp_path / "empty", 200, seed=1, progress=False)


@requires_shared(SUBSET)
def test_real_subset_holds_out_train_shapes_only():
    config = TrainConfig(data=str(SUBSET), progress=False)
    with pytest.warns(UserWarning, match="3 exact duplicate"):  # the subset repeats 3 bench shapes as 'airplane'
        train, val = build_datasets(config)
    assert len(train) + len(val) == 283 and len(val) == 28  # the train split only; test stays untouched
    assert not {s.tobytes() for s in train.shapes} & {s.tobytes() for s in val.shapes}


# ------------------------------------------------------------------------------------- training loop
@pytest.fixture(scope="module")
def trained(shapes_npz, tmp_path_factory):
    """20 epochs x 1 step of tiny training on 4 shapes, validating only at the end.

    The training pairs are frozen (the validation mode of the dataset): 24 steps cannot generalise over new
    poses, but a loop whose gradients are right must overfit a fixed set of pairs.
    """
    out = tmp_path_factory.mktemp("run")
    config = tiny_config(shapes_npz, out, epochs=20, val_every=20, limit_train=4)
    trainer = Trainer(config)
    trainer.train_set.fixed = True
    rows = trainer.fit()
    return config, trainer, rows


def test_loss_decreases(trained):
    _, _, rows = trained
    for key, factor in (("train_loss", 0.8), ("train_loss_prior", 0.7)):
        losses = [float(r[key]) for r in rows]
        assert len(losses) == 20 and all(np.isfinite(losses))
        first, last = np.mean(losses[:3]), np.mean(losses[-3:])
        print(f"\n{key}: first 3 epochs {first:.5f} -> last 3 epochs {last:.5f}")
        assert last < factor * first, key


def test_outputs_written_and_logged(trained):
    config, trainer, rows = trained
    out = Path(config.out_dir)
    for name in ("last.npz", "last_optim.npz", "best.npz", "log.csv", "curves.png", "config.json"):
        assert (out / name).is_file(), name
    assert not list(out.glob("*.tmp"))
    with open(out / "log.csv", newline="") as handle:
        logged = list(csv.DictReader(handle))
    assert [int(r["epoch"]) for r in logged] == list(range(1, 21))
    assert logged[-1]["val_mae_r_deg"] != "" and logged[0]["val_mae_r_deg"] == ""  # val_every=20
    assert int(logged[-1]["global_step"]) == 20 and logged[-1]["best"] == "1"
    assert 0.0 <= float(logged[-1]["val_recall"]) <= 1.0


def test_checkpoint_round_trip(trained):
    config, trainer, _ = trained
    loaded = load_network(Path(config.out_dir) / "last.npz")
    src, tgt = torch.rand(3, 64, 3), torch.rand(3, 64, 3)
    trainer.network.eval()
    loaded.eval()
    with torch.no_grad():
        for a, b in zip(trainer.network(src, tgt), loaded(src, tgt)):
            assert torch.equal(a, b)
    trainer.network.train()


def test_cosine_schedule_decays_from_lr_to_a_hundredth():
    config = TrainConfig(lr=1e-3, epochs=11, lr_schedule="cosine")
    rates = [epoch_learning_rate(config, e) for e in range(1, 12)]
    assert rates[0] == pytest.approx(1e-3) and rates[-1] == pytest.approx(1e-5)
    assert rates[5] == pytest.approx(0.5 * (1e-3 + 1e-5)) and all(np.diff(rates) < 0)
    assert epoch_learning_rate(replace(config, lr_schedule="constant"), 7) == 1e-3


def test_resume_continues_and_matches_an_uninterrupted_run(shapes_npz, tmp_path):
    straight = Trainer(tiny_config(shapes_npz, tmp_path / "straight", epochs=2, lr_schedule="cosine"))
    straight.fit()
    first = Trainer(tiny_config(shapes_npz, tmp_path / "resumed", epochs=1, lr_schedule="cosine"))
    first.fit()
    resumed = Trainer(tiny_config(shapes_npz, tmp_path / "resumed", epochs=2, resume=True, lr_schedule="cosine"))
    assert resumed.epoch == 1 and resumed.global_step == first.global_step
    for key, value in first.optimizer.state_dict()["state"][0].items():
        assert torch.equal(value, resumed.optimizer.state_dict()["state"][0][key]), key
    rows = resumed.fit()
    assert [int(r["epoch"]) for r in rows] == [1, 2] and resumed.global_step == straight.global_step
    for (name, a), b in zip(straight.network.state_dict().items(), resumed.network.state_dict().values()):
        assert torch.equal(a, b), name


def test_resume_without_optimizer_state_warns_and_keeps_the_weights(trained, shapes_npz, tmp_path):
    import shutil

    config, trainer, _ = trained
    shutil.copy(Path(config.out_dir) / "last.npz", tmp_path / "last.npz")  # no last_optim.npz
    with pytest.warns(UserWarning, match="fresh optimiser"):
        resumed = Trainer(tiny_config(shapes_npz, tmp_path, epochs=21, resume=True))
    assert resumed.epoch == 20 and not resumed.optimizer.state
    for a, b in zip(trainer.network.state_dict().values(), resumed.network.state_dict().values()):
        assert torch.equal(a, b)


def test_time_budget_stops_after_a_validated_epoch(shapes_npz, tmp_path):
    trainer = Trainer(tiny_config(shapes_npz, tmp_path / "budget", epochs=5, val_every=5, max_minutes=1e-4,
                                  best_metric="val_prior_mae_r_deg"))
    rows = trainer.fit()
    assert len(rows) == 1 and rows[0]["val_prior_mae_r_deg"] != ""  # validated although val_every=5
    assert trainer.best == {"epoch": 1, "metric": "val_prior_mae_r_deg", "value": rows[0]["val_prior_mae_r_deg"]}


def test_config_rejects_bad_values():
    for bad in (dict(batch_size=1), dict(val_fraction=1.0), dict(best_metric="accuracy"), dict(max_minutes=-1),
                dict(lr_schedule="step")):
        with pytest.raises(ValueError):
            TrainConfig(**bad)


def test_resume_without_checkpoint_is_a_clear_error(shapes_npz, tmp_path):
    with pytest.raises(FileNotFoundError, match="no checkpoint"):
        Trainer(tiny_config(shapes_npz, tmp_path / "nothing", resume=True))


# ---------------------------------------------------------------------------------------------- DDP
def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _ddp_worker(rank: int, world: int, port: int, data: str, root: str) -> None:
    import os

    from cemnet_ros.train import distributed as ddp

    os.environ.update(RANK=str(rank), LOCAL_RANK=str(rank), WORLD_SIZE=str(world), MASTER_ADDR="127.0.0.1",
                      MASTER_PORT=str(port))
    info = ddp.init_distributed("cpu")
    try:
        config = tiny_config(Path(data), Path(root) / f"out_rank{rank}", epochs=1, val_every=1,
                             limit_train=8)  # global batch 4 -> 2 per rank -> 2 steps each
        trainer = Trainer(config, info)
        trainer.fit()
        arrays = {f"param/{k}": v.detach().numpy() for k, v in trainer.network.named_parameters()}
        arrays.update({f"grad/{k}": v.grad.numpy() for k, v in trainer.network.named_parameters()})
        arrays["indices"] = np.array(list(trainer.sampler))
        np.savez(Path(root) / f"rank{rank}.npz", steps=trainer.global_step, **arrays)
    finally:
        ddp.shutdown(info)


@pytest.mark.slow
def test_ddp_two_cpu_ranks_stay_in_sync(shapes_npz, tmp_path):
    import torch.multiprocessing as mp

    mp.spawn(_ddp_worker, args=(2, _free_port(), str(shapes_npz), str(tmp_path)), nprocs=2, join=True)
    r0, r1 = np.load(tmp_path / "rank0.npz"), np.load(tmp_path / "rank1.npz")
    assert int(r0["steps"]) == int(r1["steps"]) == 2
    assert not set(r0["indices"].tolist()) & set(r1["indices"].tolist())  # disjoint shards
    grads = [k for k in r0.files if k.startswith("grad/")]
    assert grads and any(np.abs(r0[k]).max() > 0 for k in grads)
    for key in r0.files:
        if key.startswith(("param/", "grad/")):
            np.testing.assert_allclose(r0[key], r1[key], rtol=1e-5, atol=1e-7, err_msg=key)
    assert (tmp_path / "out_rank0" / "last.npz").is_file()
    assert not (tmp_path / "out_rank1").exists()  # only rank 0 writes


# ---------------------------------------------------------------------------------------------- CLI
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
