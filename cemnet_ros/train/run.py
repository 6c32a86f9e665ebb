"""One training run as a function: :func:`run` trains as a :class:`TrainConfig` says and returns a
:class:`TrainReport` (Markdown for a terminal, JSON for a machine); ``cemnet-train`` is a thin shell around it."""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from typing import Any, Optional

from cemnet_ros.io.atomic import jsonable

from . import distributed as ddp
from .config import TrainConfig
from .outputs import fmt
from .trainer import Trainer

_SHOWN = (("epoch", "epoch"), ("train_loss", "train loss"), ("val_mae_r_deg", "val MAE(R) deg"),
          ("val_mae_t", "val MAE(t) units"), ("val_recall", "val recall"),
          ("val_prior_mae_r_deg", "val prior MAE(R) deg"), ("val_prior_mae_t", "val prior MAE(t) units"))


@dataclass
class TrainReport:
    """What a run logged and saved: the last epoch's row, the best epoch and the output files."""

    out_dir: str
    data: str  # the shapes, folder of scans or bag trained on
    device: str
    world_size: int
    epochs_planned: int
    global_step: int
    rows: list[dict[str, Any]] = field(default_factory=list)  # log.csv (with the epochs of a resumed run)
    best: Optional[dict[str, Any]] = None  # {"epoch", "metric", "value"} of best.npz
    files: tuple[str, ...] = ("last.npz", "last_optim.npz", "best.npz", "log.csv", "curves.png", "config.json")

    @property
    def last(self) -> dict[str, Any]:
        return self.rows[-1] if self.rows else {}

    def to_json(self) -> str:
        return json.dumps(jsonable(asdict(self)), indent=2) + "\n"

    def to_markdown(self) -> str:
        """A heading, the last epoch's figures (and the best epoch's, when validated) and where the files are."""
        epochs = int(self.last.get("epoch", 0))
        lines = [f"## cemnet-train: {self.data}", "",
                 f"{epochs} of {self.epochs_planned} epoch(s), {self.global_step} step(s) on {self.device} "
                 f"(world size {self.world_size}); outputs in `{self.out_dir}/`: {', '.join(self.files)}", ""]
        if not self.rows:
            return "\n".join(lines + ["nothing trained (the run had reached its epochs already)"]) + "\n"
        lines += ["| | " + " | ".join(label for _, label in _SHOWN) + " |", "|---|" + "---:|" * len(_SHOWN)]
        shown = [("last", self.last)]
        if self.best is not None:
            row = next((r for r in self.rows if int(r["epoch"]) == int(self.best["epoch"])), None)
            shown += [(f"best ({self.best['metric']})", row)] if row is not None else []
        for name, row in shown:
            lines.append(f"| {name} | " + " | ".join(str(fmt(row.get(key, ""))) for key, _ in _SHOWN) + " |")
        return "\n".join(lines) + "\n"


def run(config: TrainConfig, info: Optional[ddp.DistInfo] = None) -> TrainReport:
    """Train (or resume) as ``config`` says; every rank trains, rank 0 alone writes the files."""
    trainer = Trainer(config, info)
    rows = trainer.fit()
    return TrainReport(out_dir=config.out_dir, data=config.bag or config.data, device=str(trainer.device),
                       world_size=trainer.info.world_size, epochs_planned=config.epochs,
                       global_step=trainer.global_step, rows=list(rows), best=trainer.best)
