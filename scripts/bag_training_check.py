"""Does ``cemnet-train --bag`` help on another bag of the same scene? Two ray-cast bags of the courtyard and the
pose errors of priors (and of the CEM started from them) on the pairs of one bag.

    python scripts/bag_training_check.py bags --out results/bag_check          # east.mcap (train), west.mcap
    cemnet-train --bag results/bag_check/east.mcap --out results/bag_check/train ...
    python scripts/bag_training_check.py evaluate --bag results/bag_check/west.mcap \
        --weights trained=results/bag_check/train/best.npz --out results/bag_check/eval

The two trajectories are loops through different halves of the courtyard (east: x 24..45 m, west: x -15..12 m;
0.7 m per scan, heading along the path, small roll/pitch/height oscillations). The evaluation pairs are those
``cemnet-train`` makes (:class:`cemnet_ros.train.scan_pairs.ScanPairDataset`, fixed seed, truth from the bag's
ground truth): scans prepared as the node prepares them, the source moved as the recovery searches (yaw over the
full circle, up to ``scans.radius`` m). Rows: each network's prior mu0 alone (``run_cem=False``) and the CEM
from it, the untrained network (the training run's initial weights) and the identity prior N(0, I).
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from cemnet_ros.core import Registrar, RegistrationConfig  # noqa: E402
from cemnet_ros.core.checkpoint import save_weights  # noqa: E402
from cemnet_ros.core.network import SamplingNetwork  # noqa: E402
from cemnet_ros.data.scenes import LidarModel, courtyard_scene, inside_obstacle, lidar_scan  # noqa: E402
from cemnet_ros.eval.metrics import pair_metrics  # noqa: E402
from cemnet_ros.io.atomic import atomic_write_text  # noqa: E402
from cemnet_ros.pipeline.cem_presets import cem_preset  # noqa: E402
from cemnet_ros.replay.bag_io import BagWriter  # noqa: E402
from cemnet_ros.train.bag_scans import read_bag_scans  # noqa: E402
from cemnet_ros.train.config import TrainConfig  # noqa: E402
from cemnet_ros.train.scan_pairs import ScanPairDataset  # noqa: E402

LOOPS = {"east": [(24, -1), (34, -1), (44, -2), (45, 8), (44, 17), (37, 18), (34, 12), (26, 12), (24, 5)],
         "west": [(-15, -2), (-3, -2.5), (10, -1.5), (12, -9), (12, -11.5), (9, -12.8), (4, -12.8), (-2, -12.8),
                  (-8, -12.8), (-10, -10), (-15, -7)]}
START_NS, PERIOD_NS = 1_700_000_000_000_000_000, 100_000_000
CEMS = {"node tracking CEM (N 100, T 2)": cem_preset("tracking", 0),
        "paper CEM (N 1000, T 10, M 3)": cem_preset("paper", 0)}


def loop_poses(waypoints: list[tuple[float, float]], step: float = 0.7) -> list[np.ndarray]:
    """T_world_sensor every ``step`` m along a periodic spline through ``waypoints``, heading along the path."""
    corners = np.asarray(waypoints + waypoints[:1], dtype=float)
    knots = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(corners, axis=0), axis=1))]
    spline = CubicSpline(knots, corners, bc_type="periodic")
    params = np.linspace(0.0, knots[-1], 20000)
    fine = spline(params)
    arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(fine, axis=0), axis=1))]
    poses = []
    for i, param in enumerate(np.interp(np.arange(0.0, arc[-1], step), arc, params)):
        (x, y), (dx, dy) = spline(param), spline(param, 1)
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_euler("zyx", [np.arctan2(dy, dx), 0.02 * np.sin(0.5 * i),
                                                    0.015 * np.cos(0.4 * i)]).as_matrix()
        pose[:3, 3] = (x, y, 1.8 + 0.05 * np.sin(0.6 * i))
        poses.append(pose)
    return poses


def make_bags(out: Path) -> None:
    """``out/east.mcap`` and ``out/west.mcap``: /points + /ground_truth, as bags/synthetic_lidar.mcap."""
    scene, lidar = courtyard_scene(), LidarModel()
    for name, waypoints in LOOPS.items():
        poses = loop_poses(waypoints)
        if inside_obstacle(scene, np.array([p[:3, 3] for p in poses]), 1.0).any():
            raise ValueError(f"the {name} loop passes within 1 m of an obstacle")
        rng = np.random.default_rng(0)
        with BagWriter(out / f"{name}.mcap", overwrite=True) as bag:
            for i, pose in enumerate(poses):
                bag.write_cloud("/points", lidar_scan(scene, pose, lidar, rng), "lidar", START_NS + i * PERIOD_NS)
                bag.write_pose("/ground_truth", pose, "world", START_NS + i * PERIOD_NS)
        print(f"{out / f'{name}.mcap'}: {len(poses)} scans", flush=True)


def evaluation_pairs(bag: Path, seed: int) -> tuple[torch.Tensor, torch.Tensor, np.ndarray, float]:
    """(sources, targets, T_target_source in units, scale): one pair per scan of ``bag``, as ``cemnet-train``
    makes its validation pairs (defaults of the scans section, seed ``seed``)."""
    config = TrainConfig(bag=str(bag), seed=seed, progress=False)
    scans = read_bag_scans(bag, "", config.preprocess, progress=False)
    if scans.poses is None:
        raise ValueError(f"{bag} has no ground truth for every scan")
    dataset = ScanPairDataset(scans, config.preprocess, config.scans, seed, fixed=True)
    items = [dataset[i] for i in range(len(dataset))]
    truth = np.zeros((len(items), 4, 4))
    truth[:, 3, 3] = 1.0
    truth[:, :3, :3] = np.stack([item["rotation"].numpy() for item in items])
    truth[:, :3, 3] = np.stack([item["translation"].numpy() for item in items])
    return (torch.stack([item["source"] for item in items]), torch.stack([item["target"] for item in items]), truth,
            scans.scale)


def untrained_weights(path: Path, seed: int) -> Path:
    """The initial weights of a ``cemnet-train --seed seed`` run (the trainer seeds torch, then builds the net)."""
    torch.manual_seed(seed)
    return save_weights(path, SamplingNetwork().state_dict(), {"note": f"untrained: random init, seed {seed}"})


def errors(result: dict, truth: np.ndarray, scale: float) -> dict[str, float]:
    """Geodesic rotation (deg) and translation (m) errors of a register_batch result against the truth."""
    per_pair = [pair_metrics(r, t, T[:3, :3], T[:3, 3]) for r, t, T in zip(result["rotation"], result["translation"],
                                                                          truth)]
    rotation = np.array([m.rot_err_deg for m in per_pair])
    translation = np.array([m.trans_err for m in per_pair]) * scale
    return {"median_rot_deg": float(np.median(rotation)), "mean_rot_deg": float(np.mean(rotation)),
            "median_trans_m": float(np.median(translation)), "mean_trans_m": float(np.mean(translation)),
            "within_5deg_1m": float(np.mean((rotation < 5.0) & (translation < 1.0)))}


def registered(registration: RegistrationConfig, sources: torch.Tensor, targets: torch.Tensor, run_cem: bool,
               chunk: int = 16) -> dict:
    """``Registrar.register_batch`` over all pairs, ``chunk`` at a time (the network's edge tensors are large)."""
    registrar = Registrar(registration)
    parts = [registrar.register_batch(sources[i:i + chunk], targets[i:i + chunk], run_cem=run_cem)
             for i in range(0, len(sources), chunk)]
    return {key: np.concatenate([getattr(part, key) for part in parts]) for key in ("rotation", "translation")}


def evaluate(priors: dict[str, RegistrationConfig], bag: Path, seed: int, cems: dict) -> list[dict]:
    """One row per (prior, method): the prior alone, then each CEM of ``cems`` started from it."""
    sources, targets, truth, scale = evaluation_pairs(bag, seed)
    print(f"{bag}: {len(sources)} pairs, scale {scale:.2f} m per unit", flush=True)
    rows = []
    for name, registration in priors.items():
        if registration.prior == "network":
            alone = registered(registration, sources, targets, run_cem=False)
        else:  # N(0, I): its mean is the identity
            alone = {"rotation": np.repeat(np.eye(3)[None], len(truth), 0), "translation": np.zeros((len(truth), 3))}
        rows.append({"prior": name, "method": "prior mu0 alone", **errors(alone, truth, scale)})
        for method, cem in cems.items():
            result = registered(replace(registration, cem=cem), sources, targets, run_cem=True)
            rows.append({"prior": name, "method": method, **errors(result, truth, scale)})
            print(rows[-1], flush=True)
    return rows


def markdown(rows: list[dict]) -> str:
    lines = ["| prior | method | median rot deg | mean rot deg | median trans m | mean trans m | within 5 deg, 1 m |",
             "|---|---|---:|---:|---:|---:|---:|"]
    lines += [f"| {r['prior']} | {r['method']} | {r['median_rot_deg']:.2f} | {r['mean_rot_deg']:.2f} | "
              f"{r['median_trans_m']:.2f} | {r['mean_trans_m']:.2f} | {r['within_5deg_1m']:.3f} |" for r in rows]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("what", choices=("bags", "evaluate"))
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--bag", type=Path, help="evaluate: the bag whose pairs are registered")
    parser.add_argument("--weights", nargs="*", default=[], help="evaluate: NAME=PATH of trained networks")
    parser.add_argument("--seed", type=int, default=123, help="the training run's seed (untrained weights) and "
                                                              "the pairs' seed")
    parser.add_argument("--cems", action=argparse.BooleanOptionalAction, default=True,
                        help="evaluate: also the CEMs started from each prior (--no-cems: the priors alone)")
    parser.add_argument("--baselines", action=argparse.BooleanOptionalAction, default=True,
                        help="evaluate: also the untrained network, the package weights and the identity prior")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.what == "bags":
        make_bags(args.out)
        return 0
    torch.set_num_threads(1)
    priors = {name: RegistrationConfig(weights=path) for name, path in (w.split("=", 1) for w in args.weights)}
    if args.baselines:
        untrained = untrained_weights(args.out / "untrained.npz", args.seed)
        priors.update({"untrained network": RegistrationConfig(weights=str(untrained)),
                       "package weights (ModelNet40)": RegistrationConfig(),
                       "identity N(0, I)": RegistrationConfig(prior="identity")})
    rows = evaluate(priors, args.bag, args.seed, CEMS if args.cems else {})
    atomic_write_text(args.out / "priors.json", json.dumps(rows, indent=2) + "\n")
    atomic_write_text(args.out / "priors.md", markdown(rows))
    print(markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
