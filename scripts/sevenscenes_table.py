#!/usr/bin/env python3
"""The paper's indoor protocol (Table 3, 7Scene row) on real 7-Scenes depth frames, every method on the same pairs.

For each perturbation seed it runs :func:`cemnet_ros.eval.runner.run` on the RGB-D clouds
(:mod:`cemnet_ros.eval.sevenscenes`): CEMNet with the official 7Scene checkpoint, ICP and FPFH + RANSAC + ICP
(when Open3D imports) in one run, then on the same pairs the 7Scene checkpoint with the reference's BatchNorm
(batch statistics, batches of 35) and CEMNet with the package's default weights; it writes one markdown table
(per seed and all seeds pooled, the paper's row beside them) and the raw aggregates with the failed pairs.

    python scripts/sevenscenes_table.py --data ../shared/data/rgbd_7scenes \\
        --official-dir ../shared/reference/cemnet_official --seeds 0,1000,2000 --out results/sevenscenes
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from cemnet_ros.core.config import RegistrationConfig  # noqa: E402
from cemnet_ros.eval.baselines import open3d_available  # noqa: E402
from cemnet_ros.eval.runner import EvalConfig, run  # noqa: E402
from cemnet_ros.eval.sevenscenes import SevenScenesConfig  # noqa: E402
from cemnet_ros.io.atomic import atomic_write_text, jsonable  # noqa: E402

SCENE7 = "scene7_n768_unseen0_noise0_seed123.pth"
REFERENCE_BATCH = 35  # the reference's test batch size: its BatchNorm normalises with each batch's statistics
PAPER = {"r_rmse_deg": 0.1768, "t_rmse": 0.0012, "r_mae_deg": 0.0434, "t_mae": 0.0002}  # CEMNet, Table 3, 7Scene
ROW_NAMES = {"cemnet": "CEMNet, official 7Scene checkpoint",
             "cemnet_batchnorm": f"CEMNet, official 7Scene checkpoint, batch statistics (batches of {REFERENCE_BATCH})",
             "cemnet_package": "CEMNet, package default weights",
             "icp": "ICP (identity start)", "fpfh": "FPFH + RANSAC + ICP (Open3D)"}
KEYS = ("r_mae_deg", "r_rmse_deg", "t_mae", "t_rmse", "rot_err_deg_median", "recall", "median_ms_per_pair")


def _runs(data: str, official: Path, seed: int, limit: int | None, frames_per_cloud: int) -> dict[str, EvalConfig]:
    """The runs of one seed by row-key suffix; the first holds the baselines, all see the same pairs."""
    scene7 = RegistrationConfig(weights=str(official), allow_pickle=True)
    base = EvalConfig(data=data, source="rgbd", methods=("cemnet",), seed_offset=seed, limit=limit,
                      registration=scene7, rgbd=SevenScenesConfig(frames_per_cloud=frames_per_cloud))
    baselines = ("icp",) + (("fpfh",) if open3d_available() else ())
    return {"": replace(base, methods=("cemnet",) + baselines),
            "_batchnorm": replace(base, batch_size=REFERENCE_BATCH, registration=replace(scene7, batchnorm="batch")),
            "_package": replace(base, registration=RegistrationConfig())}


def measure(data: str, official: Path, seed: int, limit: int | None, frames_per_cloud: int) -> dict[str, dict]:
    """Aggregates by row for the pairs of one perturbation seed (seed offset), with every pair's rotation
    error and the pairs outside the recall thresholds."""
    rows = {}
    for suffix, config in _runs(data, official, seed, limit, frames_per_cloud).items():
        report = run(config)
        for method, agg in report.aggregates.items():
            pairs = report.per_pair[method]
            rot_limit, trans_limit = agg["recall_rot_thresh_deg"], agg["recall_trans_thresh"]
            failed = [f"{p['label']}: {p['rot_err_deg']:.2f} deg, {p['trans_err']:.4f}" for p in pairs
                      if p["rot_err_deg"] >= rot_limit or p["trans_err"] >= trans_limit]
            rows[method + suffix] = {**agg, "rot_err_deg": [p["rot_err_deg"] for p in pairs], "failed_pairs": failed}
    return rows


def pooled(results: dict[int, dict[str, dict]], method: str) -> list[float]:
    """``KEYS`` over the pairs of every seed (same number of pairs each): RMSEs from the pooled squares, the
    median over all pairs; the time is the mean of the seeds' medians."""
    columns = {k: np.array([r[method][k] for r in results.values()]) for k in KEYS}
    columns["rot_err_deg_median"] = np.median(np.concatenate([r[method]["rot_err_deg"] for r in results.values()]))
    return [float(np.sqrt(np.mean(columns[k] ** 2)) if "rmse" in k else np.mean(columns[k])) for k in KEYS]


def table(results: dict[int, dict[str, dict]]) -> str:
    """Rows per seed, all seeds pooled, and the paper's row."""
    lines = ["| pairs (seed offset) | method | MAE(R) deg | RMSE(R) deg | MAE(t) | RMSE(t) | median R err deg | recall "
             "| median ms/pair |", "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    row = "| {} | {} | {:.4f} | {:.4f} | {:.6f} | {:.6f} | {:.4f} | {:.3f} | {:.0f} |"
    for seed, aggregates in results.items():
        for method, agg in aggregates.items():
            lines.append(row.format(f"{agg['n_pairs']} ({seed})", ROW_NAMES[method], *(agg[k] for k in KEYS)))
    for method in next(iter(results.values())):
        lines.append(row.format(f"all {len(results)} seeds", ROW_NAMES[method], *pooled(results, method)))
    lines.append("| paper (Table 3, 7Scene, 57 test fragments) | CEMNet | {r_mae_deg} | {r_rmse_deg} | {t_mae} | "
                 "{t_rmse} | - | - | - |".format(**PAPER))
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", required=True, help="7-Scenes folder (camera-intrinsics.txt, rgbd-frames/)")
    parser.add_argument("--official-dir", type=Path, required=True, help=f"folder holding {SCENE7}")
    parser.add_argument("--seeds", default="0,1000,2000", help="comma-separated seed offsets of the pairs")
    parser.add_argument("--limit", type=int, default=None, help="only the first N clouds (quick checks)")
    parser.add_argument("--frames-per-cloud", type=int, default=1, help="depth frames fused per cloud (default 1)")
    parser.add_argument("--out", type=Path, default=Path("results/sevenscenes"))
    args = parser.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    official = args.official_dir / SCENE7
    if not official.is_file():
        parser.error(f"{official} not found")
    results = {seed: measure(args.data, official, seed, args.limit, args.frames_per_cloud) for seed in seeds}
    text = table(results)
    args.out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out / "sevenscenes.md", text)
    atomic_write_text(args.out / "sevenscenes.json", json.dumps(jsonable(results), indent=1) + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
