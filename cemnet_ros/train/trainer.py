"""The training loop: loss of the objective, Adam step; validate, log, checkpoint.

Objective ``paper`` (no labels): GM(R_T src + t_T, tgt) + prior_loss_weight * GM(R_0 src + t_0, tgt), with
(R_T, t_T) the CEM's final mean and (R_0, t_0) the sampling network's prior mean. Gradients reach the
network through the reparameterised candidates of the CEM (the sparsemax weights see detached scores).
Objective ``known_motion``: the sampling network alone, taught the random motions the pairs were made with
(:mod:`.known_motion`).
Only rank 0 writes files: ``last.npz`` (+ ``last_optim.npz``), ``best.npz``, ``log.csv``, ``curves.png``
and ``config.json`` in ``config.out_dir``.
"""
from __future__ import annotations

import csv
import json
import time
import warnings
from dataclasses import asdict
from pathlib import Path
from typing import Any, Optional

import numba
import numpy as np
import torch
from torch.utils.data import DataLoader
from tqdm import tqdm

from cemnet_ros.core.checkpoint import load_network
from cemnet_ros.core.engine import CEMNet
from cemnet_ros.core.geometry_torch import action_to_rt, transform_points
from cemnet_ros.core.losses import geman_mcclure_loss
from cemnet_ros.core.network import SamplingNetwork
from cemnet_ros.eval.metrics import aggregate, pair_metrics
from cemnet_ros.io.atomic import atomic_write_text

from . import distributed as ddp
from .checkpoints import load_checkpoint, save_checkpoint
from .config import TrainConfig, epoch_learning_rate
from .data import build_datasets
from .known_motion import known_motion_losses
from .outputs import CSV_FIELDS, fmt, write_curves, write_log

CHECKPOINT_FORMAT = "cemnet_ros.train/1"
# Each objective's loss terms and the log.csv columns they are averaged into.
LOSS_TERMS = {"paper": {"total": "train_loss", "final": "train_loss_final", "prior": "train_loss_prior"},
              "known_motion": {"total": "train_loss", "match": "train_loss_match", "pose": "train_loss_prior",
                               "sigma": "train_loss_sigma"}}


def derived_seed(*words: int) -> int:
    """A 63-bit seed from integers (reproducible; distinct for distinct word tuples)."""
    return int(np.random.SeedSequence([int(w) for w in words]).generate_state(2, np.uint64)[0] >> np.uint64(1))


def aligned_by(source: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
    """(B, n, 3) source moved by the (B, 6) actions."""
    rotation, translation = action_to_rt(action)
    return transform_points(source, rotation, translation)


def unsupervised_loss(source: torch.Tensor, target: torch.Tensor, mu: torch.Tensor, mu0: torch.Tensor,
                      config: TrainConfig) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(total, final, prior) Geman-McClure losses of the final and the prior alignments."""
    final = geman_mcclure_loss(aligned_by(source, mu), target, mu=config.loss_mu)
    prior = geman_mcclure_loss(aligned_by(source, mu0), target, mu=config.loss_mu)
    return final + config.prior_loss_weight * prior, final, prior


def pose_errors(actions: torch.Tensor, rotation: np.ndarray, translation: np.ndarray) -> dict[str, float]:
    """The evaluation's aggregate metrics (MAE(R) in degrees, MAE(t), recall, ...) of (B, 6) predicted actions
    against true (B, 3, 3) rotations and (B, 3) translations. Non-finite predictions count as identity."""
    bad = ~torch.isfinite(actions).all(-1)
    if bad.any():
        warnings.warn(f"{int(bad.sum())} non-finite prediction(s) scored as the identity")
        actions = torch.where(bad.unsqueeze(-1), torch.zeros_like(actions), actions)
    rot, trans = action_to_rt(actions.double())
    return aggregate(pair_metrics(r, t, r_gt, t_gt)
                     for r, t, r_gt, t_gt in zip(rot.numpy(), trans.numpy(), rotation, translation))


class Trainer:
    """Owns the network, optimiser, data and output folder of one training run (one per rank)."""

    def __init__(self, config: TrainConfig, info: Optional[ddp.DistInfo] = None):
        self.config = config
        self.info = info or ddp.DistInfo(device=ddp.resolve_device(config.device))
        if config.objective == "known_motion" and self.info.world_size > 1:
            raise ValueError("objective 'known_motion' trains on one process (DDP wraps the CEM, which it skips)")
        if config.threads > 0:
            torch.set_num_threads(config.threads)
            numba.set_num_threads(min(config.threads, numba.config.NUMBA_NUM_THREADS))
        self.out_dir = Path(config.out_dir)
        self.device = self.info.device
        torch.manual_seed(config.seed)  # the same initial weights on every rank
        self.network = self._initial_network().to(self.device)
        self.model = ddp.wrap_model(CEMNet(config.cem, self.network).to(self.device), self.info)
        self.optimizer = torch.optim.Adam(self.network.parameters(), lr=config.lr, weight_decay=config.weight_decay)
        self.train_set, self.val_set = build_datasets(config)
        self.sampler = ddp.make_sampler(self.train_set, self.info, shuffle=True, seed=config.seed)
        self.train_loader = self._train_loader()
        self.val_loader = DataLoader(self.val_set, batch_size=config.batch_size, shuffle=False,
                                     num_workers=config.num_workers)
        self.epoch = 0  # completed epochs
        self.global_step = 0
        self.best: Optional[dict[str, Any]] = None  # {"epoch", "metric", "value"}
        self.rows: list[dict[str, Any]] = []
        if config.resume:
            self._resume()

    # ----------------------------------------------------------------------------------------- setup
    def _initial_network(self) -> SamplingNetwork:
        if not self.config.init_weights:
            return SamplingNetwork()
        return load_network(self.config.init_weights, allow_pickle=self.config.allow_pickle)

    def _train_loader(self) -> DataLoader:
        per_rank = self.config.batch_size // self.info.world_size
        if self.config.batch_size % self.info.world_size:
            warnings.warn(f"batch size {self.config.batch_size} is not a multiple of the world size "
                          f"{self.info.world_size}: using {per_rank} pairs per rank")
        shard = len(self.sampler)
        batch = min(per_rank, shard)
        if batch < 2:
            raise ValueError(f"{shard} training pairs per rank at batch {per_rank}: BatchNorm needs >= 2 per batch")
        # drop_last: a trailing batch of one pair would break BatchNorm in train mode.
        return DataLoader(self.train_set, batch_size=batch, sampler=self.sampler, drop_last=True,
                          num_workers=self.config.num_workers)

    def _resume(self) -> None:
        path = self.out_dir / "last.npz"
        if not path.is_file():
            raise FileNotFoundError(f"--resume: no checkpoint {path}")
        meta = load_checkpoint(path, self.network, self.optimizer)
        self.epoch, self.global_step = int(meta["epoch"]), int(meta["global_step"])
        self.best = meta.get("best")
        if self.best is not None and self.best.get("metric") != self.config.best_metric:
            self.best = None  # best.npz was chosen by another figure: the next validation starts afresh
        log = self.out_dir / "log.csv"
        if log.is_file():
            with open(log, newline="") as handle:
                self.rows = [row for row in csv.DictReader(handle) if int(row["epoch"]) <= self.epoch]
        if self.info.is_main:
            print(f"resumed from {path} after epoch {self.epoch} (step {self.global_step})", flush=True)

    # -------------------------------------------------------------------------------------- training
    def train_epoch(self, epoch: int) -> dict[str, float]:
        """One pass over this rank's shard; returns the epoch's mean losses over all ranks."""
        self.network.train()  # BatchNorm uses batch statistics while training, as the reference
        self.train_set.set_epoch(epoch)
        self.sampler.set_epoch(epoch)
        torch.manual_seed(derived_seed(self.config.seed, epoch, self.info.rank))  # CEM noise of this epoch
        terms = LOSS_TERMS[self.config.objective]
        sums = np.zeros(len(terms) + 1)  # the terms, then batches
        skipped = 0
        bar = tqdm(self.train_loader, desc=f"epoch {epoch}", disable=not (self.config.progress and self.info.is_main),
                   dynamic_ncols=True)
        for batch in bar:
            losses = self._losses({k: v.to(self.device) for k, v in batch.items()})
            if not self._all_finite(losses["total"]):
                skipped += 1  # every rank skips together (DDP's backward would otherwise hang)
                continue
            self.optimizer.zero_grad(set_to_none=True)
            losses["total"].backward()
            self.optimizer.step()
            self.global_step += 1
            sums += (*(losses[term].item() for term in terms), 1.0)
            bar.set_postfix(loss=f"{sums[0] / sums[-1]:.5f}")
        total = ddp.all_reduce_sum([*sums.tolist(), float(skipped)], self.info)
        if total[-1]:
            warnings.warn(f"epoch {epoch}: skipped {int(total[-1])} batch(es) with a non-finite loss")
        n = max(total[-2], 1.0)
        return {**{column: total[i] / n for i, column in enumerate(terms.values())}, "skipped_batches": int(total[-1])}

    def _losses(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """The objective's loss terms of one batch (``total`` is the one minimised)."""
        source, target = batch["source"], batch["target"]
        if self.config.objective == "known_motion":
            prediction = self.network.predict(source, target)
            return known_motion_losses(source, target, batch["rotation"], batch["translation"],
                                       batch["known_motion"], prediction, self.config.known_motion)
        out = self.model(source, target)
        total, final, prior = unsupervised_loss(source, target, out.mu, out.mu0, self.config)
        return {"total": total, "final": final, "prior": prior}

    def _all_finite(self, loss: torch.Tensor) -> bool:
        bad = 0.0 if torch.isfinite(loss).item() else 1.0
        return ddp.all_reduce_sum([bad], self.info)[0] == 0.0

    # ------------------------------------------------------------------------------------ validation
    def validate(self) -> dict[str, float]:
        """Register the held-out pairs with the CEM at evaluation settings; errors against the known poses."""
        self.network.eval()
        self.network.batch_stats_at_inference = self.config.val_batchnorm == "batch"
        cem = CEMNet(self.config.val_cem, self.network).to(self.device)
        generator = torch.Generator(device=self.device).manual_seed(derived_seed(self.config.seed, 1 << 20))
        preds, priors, truths, losses = [], [], [], []
        with torch.no_grad():
            for batch in tqdm(self.val_loader, desc="validate", leave=False,
                              disable=not (self.config.progress and self.info.is_main), dynamic_ncols=True):
                source, target = batch["source"].to(self.device), batch["target"].to(self.device)
                out = cem(source, target, generator=generator)
                losses.append(geman_mcclure_loss(aligned_by(source, out.mu), target, mu=self.config.loss_mu).item()
                              * len(source))
                preds.append(out.mu.cpu())
                priors.append(out.mu0.cpu())
                truths.append((batch["rotation"], batch["translation"]))
        self.network.train()
        rotation = torch.cat([r for r, _ in truths]).double().numpy()
        translation = torch.cat([t for _, t in truths]).double().numpy()
        final = pose_errors(torch.cat(preds), rotation, translation)
        prior = pose_errors(torch.cat(priors), rotation, translation)
        return {"val_loss": float(np.sum(losses) / len(self.val_set)),
                "val_mae_r_deg": final["r_mae_deg"], "val_mae_t": final["t_mae"], "val_recall": final["recall"],
                "val_prior_mae_r_deg": prior["r_mae_deg"], "val_prior_mae_t": prior["t_mae"]}

    # ------------------------------------------------------------------------------------------- run
    def fit(self) -> list[dict[str, Any]]:
        """Train epochs ``self.epoch + 1 .. config.epochs``; returns the per-epoch log rows."""
        cfg = self.config
        if self.info.is_main:
            self.out_dir.mkdir(parents=True, exist_ok=True)
            atomic_write_text(self.out_dir / "config.json", json.dumps(asdict(cfg), indent=2, default=str) + "\n")
        if self.epoch >= cfg.epochs:
            warnings.warn(f"already trained {self.epoch} epoch(s) >= epochs={cfg.epochs}: nothing to do")
        run_start = time.perf_counter()
        for epoch in range(self.epoch + 1, cfg.epochs + 1):
            start = time.perf_counter()
            for group in self.optimizer.param_groups:
                group["lr"] = epoch_learning_rate(cfg, epoch)
            row: dict[str, Any] = {"epoch": epoch, **self.train_epoch(epoch)}
            train_time = time.perf_counter() - start
            row.update(global_step=self.global_step, lr=self.optimizer.param_groups[0]["lr"],
                       train_time_s=round(train_time, 2))
            self.epoch = epoch
            stop = self._out_of_time(time.perf_counter() - run_start, train_time)
            if self.info.is_main:
                self._end_epoch(row, validate=epoch % cfg.val_every == 0 or epoch == cfg.epochs or stop)
            ddp.barrier(self.info)
            if stop:
                if self.info.is_main:
                    print(f"stopping after epoch {epoch}: another epoch would exceed --max-minutes "
                          f"{cfg.max_minutes:g}", flush=True)
                break
        return self.rows

    def _out_of_time(self, elapsed: float, train_time: float) -> bool:
        """Rank 0 decides (for every rank) whether this epoch's validation plus one more epoch would overrun
        ``config.max_minutes``, estimating both from the last measured durations."""
        if self.config.max_minutes <= 0:
            return False
        val_time = next((float(r["val_time_s"]) for r in reversed(self.rows) if r.get("val_time_s") not in ("", None)),
                        0.0)
        over = elapsed + 2.0 * val_time + train_time > 60.0 * self.config.max_minutes
        return ddp.all_reduce_sum([float(over and self.info.is_main)], self.info)[0] > 0

    def _end_epoch(self, row: dict[str, Any], validate: bool) -> None:
        start = time.perf_counter()
        improved = False
        if validate:
            row.update(self.validate())
            row["val_time_s"] = round(time.perf_counter() - start, 2)
            key = self.config.best_metric
            improved = self.best is None or row[key] < self.best["value"]
            if improved:
                self.best = {"epoch": row["epoch"], "metric": key, "value": row[key]}
        row["best"] = int(improved)
        # Log first: a resume keeps only the rows up to its checkpoint's epoch, so a crash in between is harmless.
        self.rows.append({k: row.get(k, "") for k in CSV_FIELDS})
        write_log(self.out_dir, self.rows)
        write_curves(self.out_dir, self.rows)
        meta = self._meta(row)
        if improved:
            save_checkpoint(self.out_dir / "best.npz", self.network, None, meta)
        save_checkpoint(self.out_dir / "last.npz", self.network, self.optimizer, meta)
        summary = ", ".join(f"{k}={fmt(row[k])}" for k in ("train_loss", "val_mae_r_deg", "val_mae_t", "val_recall",
                                                          "val_prior_mae_r_deg", "train_time_s", "val_time_s")
                            if k in row)
        print(f"epoch {row['epoch']}/{self.config.epochs}: {summary}", flush=True)

    def _meta(self, row: dict[str, Any]) -> dict[str, Any]:
        return {"format": CHECKPOINT_FORMAT, "epoch": self.epoch, "global_step": self.global_step,
                "best": self.best, "metrics": {k: v for k, v in row.items() if k != "epoch"},
                "train_config": json.loads(json.dumps(asdict(self.config), default=str)),
                "torch": torch.__version__, "created_unix": time.time()}
