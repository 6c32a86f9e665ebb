"""Unsupervised training: loss decrease, outputs, checkpoint/resume, the schedule, DDP on gloo.

Everything runs on the tiny synthetic shapes of tiny_training.py, with few candidates: the whole file takes about a
minute on 2 cores.
"""
from __future__ import annotations

import csv
import socket
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from tiny_training import tiny_config

from cemnet_ros.core.checkpoint import load_network
from cemnet_ros.train.config import TrainConfig, epoch_learning_rate
from cemnet_ros.train.trainer import Trainer


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


