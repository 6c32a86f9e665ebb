"""One evaluation run: load clouds, make the protocol's pairs, run every method on the same pairs, score them.

``run(EvalConfig(...))`` is what ``cemnet-eval`` does; scripts call it directly for tables of several runs.
Sources: a shape archive (``source="shapes"``, the paper's ModelNet40 protocol) or a 7-Scenes RGB-D folder
(``source="rgbd"``, the paper's indoor protocol, :mod:`cemnet_ros.eval.sevenscenes`).
"""
from __future__ import annotations

import dataclasses
import platform
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch

from cemnet_ros.core.config import RegistrationConfig
from cemnet_ros.core.registration import Registrar
from cemnet_ros.eval.metrics import aggregate, pair_metrics
from cemnet_ros.eval.predictions import Prediction, run_baseline, run_cemnet
from cemnet_ros.eval.protocol import FAR_POINTS, ProtocolConfig, RegistrationPair, load_shapes, protocol_pairs
from cemnet_ros.eval.report import Report
from cemnet_ros.eval.sevenscenes import SevenScenesConfig, sevenscenes_clouds

METHODS = ("cemnet", "icp", "fpfh")
SETTINGS = ("clean", "noisy", "unseen")
SOURCES = ("shapes", "rgbd")
MODES = ("cem", "network")


@dataclass
class EvalConfig:
    """Everything one run depends on (``cemnet-eval``'s flags)."""

    data: str  # shape archive .npz (source "shapes") or 7-Scenes folder (source "rgbd")
    methods: Tuple[str, ...] = ("cemnet", "icp")
    source: str = "shapes"
    split: str = "test"  # shapes only
    setting: str = "clean"
    full: bool = False  # no partial crop
    far_point: str = "reference"
    mode: str = "cem"  # "network": the sampling network's mu0 alone
    batch_size: int = 8
    limit: Optional[int] = None  # only the first N clouds
    seed_offset: int = 0
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    rgbd: SevenScenesConfig = field(default_factory=SevenScenesConfig)

    def __post_init__(self) -> None:
        unknown = sorted(set(self.methods) - set(METHODS))
        if unknown or not self.methods:
            raise ValueError(f"methods: unknown {unknown or 'empty list'}; choose from {', '.join(METHODS)}")
        if self.batch_size < 1 or (self.limit is not None and self.limit < 1):
            raise ValueError("--batch-size and --limit must be >= 1")
        choices = (("source", self.source, SOURCES), ("setting", self.setting, SETTINGS),
                   ("far_point", self.far_point, FAR_POINTS), ("mode", self.mode, MODES))
        for name, value, allowed in choices:
            if value not in allowed:
                raise ValueError(f"{name} must be one of {allowed}, not {value!r}")
        if self.source == "rgbd" and self.setting == "unseen":
            raise ValueError("the unseen-categories setting needs a labelled shape archive, not RGB-D frames")

    @property
    def protocol(self) -> ProtocolConfig:
        return ProtocolConfig(partial=not self.full, noise=self.setting == "noisy", far_point=self.far_point)


def load_clouds(config: EvalConfig) -> Tuple[np.ndarray, Optional[list], str]:
    """``points (S, m, 3)``, one label per cloud (or None) and a phrase naming the data, first ``limit`` only."""
    if config.source == "rgbd":
        points, names = sevenscenes_clouds(config.data, config.rgbd)
        labels: Optional[list] = names
        what = f"7-Scenes frames ({config.rgbd.frames_per_cloud} per cloud)"
    else:
        points, label_array = load_shapes(config.data, config.split, unseen=config.setting == "unseen")
        labels = None if label_array is None else [int(v) for v in label_array]
        what = f"split {config.split}"
    points, labels = points[:config.limit], (labels[:config.limit] if labels is not None else None)
    if len(points) == 0:
        raise ValueError(f"{config.data}: no clouds in split {config.split!r} for setting {config.setting!r}")
    return points, labels, what


def run(config: EvalConfig) -> Report:
    """Every method of ``config`` on the same pairs; raises ValueError / OSError / CheckpointError on bad input."""
    points, labels, what = load_clouds(config)
    pairs = list(protocol_pairs(points, config.protocol, config.seed_offset))
    predictions: Dict[str, List[Prediction]] = {}
    registrar = Registrar(config.registration) if "cemnet" in config.methods else None  # loads the weights
    for method in config.methods:
        if method == "cemnet":
            predictions[method] = run_cemnet(registrar, pairs, config.batch_size, run_cem=config.mode == "cem")
        else:
            predictions[method] = run_baseline(method, pairs)
    aggregates, per_pair = {}, {}
    for method, preds in predictions.items():
        aggregates[method], per_pair[method] = _score(preds, pairs, labels)
    crop = "full" if config.full else f"partial ({config.far_point} far point)"
    weights = config.registration.weights
    title = (f"{config.setting}, {crop}, {what}, {len(pairs)} pairs"
             f" (weights: {Path(weights).name if weights else 'package default'})")
    row_names = {"cemnet": "cemnet (network only)"} if config.mode == "network" else {}
    return Report(title, aggregates, per_pair, _recorded(config), row_names)


def _score(preds: Sequence[Prediction], pairs: Sequence[RegistrationPair], labels: Optional[list]
           ) -> Tuple[Dict[str, float], List[dict]]:
    metrics = [pair_metrics(p.rotation, p.translation, pair.rotation, pair.translation)
               for p, pair in zip(preds, pairs)]
    summary = aggregate(metrics)
    summary["median_ms_per_pair"] = float(np.median([p.seconds for p in preds]) * 1e3)
    rows = [{"pair": i, "label": None if labels is None else labels[i], **m.as_dict(), "time_ms": p.seconds * 1e3,
             "rotation": p.rotation.tolist(), "translation": p.translation.tolist(), **p.extra}
            for i, (m, p) in enumerate(zip(metrics, preds))]
    return summary, rows


def _recorded(config: EvalConfig) -> dict:
    run_fields = {f.name: getattr(config, f.name) for f in dataclasses.fields(config)
                  if f.name not in ("registration", "rgbd")}
    recorded = {"run": run_fields, "protocol": dataclasses.asdict(config.protocol),
                "registration": dataclasses.asdict(config.registration), "methods": list(config.methods),
                "python": platform.python_version(), "torch": torch.__version__,
                "torch_threads": torch.get_num_threads()}
    if config.source == "rgbd":
        recorded["rgbd"] = dataclasses.asdict(config.rgbd)
    return recorded
