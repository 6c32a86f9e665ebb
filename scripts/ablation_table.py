"""The paper's Table 2 ablation on the ModelNet40 protocol, measured with cemnet-eval on the same pairs.

For each setting (partial clean, partial noisy, unseen category) it evaluates: CEMNet with the project's
weights and with the official checkpoint of that setting, no sampling network (prior N(0, I)), the sampling
network alone (mu0, no CEM) and the CEM without the future reward (M = 0), and writes one markdown table and
the raw aggregates (JSON) into --out, atomically.

    python scripts/ablation_table.py --data ../shared/data/modelnet40_subset.npz \
        --official-dir ../shared/reference/cemnet_official --out results/ablation
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

from cemnet_ros.io.atomic import write_report
from cemnet_ros.tools import eval_cli

# Official checkpoint per setting (file names of the CEMNet release).
OFFICIAL = {"clean": "modelnet40_n768_unseen0_noise0_seed123.pth",
            "noisy": "modelnet40_n768_unseen0_noise1_seed123.pth",
            "unseen": "modelnet40_n768_unseen1_noise0_seed123.pth"}


def variants(own: str | None, official: Path | None) -> list[tuple[str, list[str]]]:
    """(row name, cemnet-eval flags) of every ablation row; weights None = the package default."""
    weight_sets = [("project weights", ["--weights", own] if own else [])]
    if official is not None:
        weight_sets.append(("official checkpoint", ["--weights", str(official), "--allow-pickle"]))
    rows = [(f"CEMNet, {name}", flags) for name, flags in weight_sets]
    rows.append(("no sampling network, prior N(0, I)", ["--prior", "identity"]))
    rows += [(f"sampling network alone (mu0), {name}", flags + ["--mode", "network"]) for name, flags in weight_sets]
    rows += [(f"CEM without future reward (M = 0), {name}", flags + ["--cem.n_fused_iters", "0"])
             for name, flags in weight_sets]
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", required=True, help="shape archive .npz (e.g. modelnet40_subset.npz)")
    parser.add_argument("--weights", default=None, help="the project's weights (.npz); default: the package's")
    parser.add_argument("--official-dir", type=Path, default=None, help="folder of the official .pth checkpoints")
    parser.add_argument("--settings", default="clean,noisy,unseen", help="comma-separated subset")
    parser.add_argument("--limit", type=int, default=None, help="evaluate only the first N shapes (quick checks)")
    parser.add_argument("--out", type=Path, default=Path("results/ablation"))
    args = parser.parse_args(argv)
    settings = [s for s in args.settings.split(",") if s]
    if not set(settings) <= set(OFFICIAL):
        parser.error(f"--settings must be a subset of {sorted(OFFICIAL)}")
    results: dict[str, dict[str, dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for setting in settings:
            official = args.official_dir / OFFICIAL[setting] if args.official_dir else None
            if official is not None and not official.is_file():
                print(f"ablation: {official} not found", file=sys.stderr)
                return 2
            for i, (name, flags) in enumerate(variants(args.weights, official)):
                out_json = Path(tmp) / f"{setting}_{i}.json"
                print(f"[{setting}] {name}", flush=True)
                code = eval_cli.main(["--data", args.data, "--setting", setting, "--methods", "cemnet",
                                      "--out-json", str(out_json), *flags,
                                      *(["--limit", str(args.limit)] if args.limit else [])])
                if code != 0:
                    return code
                results.setdefault(setting, {})[name] = json.loads(out_json.read_text())["aggregates"]["cemnet"]
    lines = ["| setting | variant | MAE(R) deg | MAE(t) | recall | pairs |", "|---|---|---:|---:|---:|---:|"]
    for setting, rows in results.items():
        for name, agg in rows.items():
            lines.append(f"| {setting} | {name} | {agg['r_mae_deg']:.4f} | {agg['t_mae']:.6f} | {agg['recall']:.3f} "
                         f"| {agg['n_pairs']} |")
    table = "\n".join(lines) + "\n"
    write_report(args.out / "ablation.md", table)
    write_report(args.out / "ablation.json", json.dumps(results, indent=2) + "\n")
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
