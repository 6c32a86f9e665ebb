#!/usr/bin/env python3
"""Does a learned prior pay in the recovery's global search? (issue 12)

The robustness benchmark's large-motion pairs (``benchmarks.pairs``: courtyard, yaw any, |t| up to 10 m),
or (``--bag``) such motions between the scans of a bag with ground truth, each through a fresh ``ScanAligner`` per
configuration: the first scan, then the second 0.1 s later (a recovery:
"first pair"). All configurations see the same pairs in the same run, interleaved pair by pair (the order
rotating) so that the machine's load hits them alike: ``uniform-N``, a uniform scatter of N (the default
``recovery.search.n_scatter``, then ``--uniform-fractions`` of it: 1/2, 1/4); ``network+N``, the network's raw
N(mu0, sigma0) (``--weights NAME=PATH ...``, one set of variants per network) drawing ``--n-prior`` candidates on
top of a uniform N (``--prior-fractions``: 1/4, 1/2); ``oracle+N`` (``--oracle``, beside the smallest), a prior at
the true motion: the most a network could give; ``--lean``: each of them again with fewer seeds, resampled
candidates and hypotheses (what a prior that is right could afford).

The search has no time budget: the sizes decide the work, not the machine's load. Issue 12's criterion: a prior
pays if it reaches the default's recall at <= 0.5x its time or a higher recall than a uniform scatter that took at
least as long (by the ratio of medians and the paired ratio both, each against the default).
Timings on a shared machine are noisy.

    python scripts/bench_recovery_prior.py --pairs 2 --seeds 0                  # a smoke run
    python scripts/bench_recovery_prior.py --pairs 20 --seeds 0 1 --weights scan=scan --out results/recovery_prior.json
"""
from __future__ import annotations

import argparse
import dataclasses
import platform
import sys
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Optional

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from benchmarks import metrics  # noqa: E402
from benchmarks.odometry import Output  # noqa: E402
from benchmarks.pairs import bag_pairs, large_motion_pairs, pair_record, read_posed_scans  # noqa: E402
from benchmarks.streams import run_stream  # noqa: E402
from cemnet_ros.core.config import GlobalSearchConfig  # noqa: E402
from cemnet_ros.core.geometry import action_to_matrix_np, matrix_to_action_np  # noqa: E402
from cemnet_ros.io.atomic import json_text, write_report  # noqa: E402
from cemnet_ros.io.console import log  # noqa: E402
from cemnet_ros.pipeline.aligner import ScanAligner  # noqa: E402
from cemnet_ros.pipeline.config import AlignerConfig  # noqa: E402
from cemnet_ros.pipeline.steps.metric_cem import prior_registrar  # noqa: E402

LEAN = {"n_seeds": 4, "n_per_seed": 25, "n_hypotheses": 2}  # vs the defaults 16, 50, 4
NOISE = "timings noisy, machine shared"
DEFINITIONS = "\n".join([
    "Definitions. The step is the pair's second scan (a recovery); RTE / RRE: translation (m) / rotation angle (deg)",
    f"of inv(T_true) @ T_est. recall: RTE < {metrics.RECALL_M} m and RRE < {metrics.RECALL_DEG} deg; precise:",
    f"RTE < {metrics.PRECISE_M} m and RRE < {metrics.PRECISE_DEG} deg; both over all pairs whatever their flag.",
    "accepted wrong: accepted and not precise; flagged: not accepted; failed: an exception.",
    "ms: wall time of the second scan's process() call (the network's prior included); paired / default: the median",
    "over pairs of that time over the default's on the same pair.",
    "prior's mu0 within recall: the prior's mean alone (before any search) within the recall thresholds.",
])


@dataclasses.dataclass(frozen=True)
class Variant:
    """A configuration under test: the uniform scatter's size and where the prior comes from."""

    name: str
    n_scatter: int
    prior: str  # "uniform", "network" or "oracle"
    weights: str = ""  # the network's: a name of --weights
    lean: bool = False  # the later stages cut to LEAN (a prior that is right needs fewer seeds and hypotheses)


def variants(default_scatter: int, uniform: list[float], prior: list[float], oracle: bool,
             weights: dict[str, str], lean: bool) -> list[Variant]:
    """The default uniform scatter first, then those ``uniform`` fractions of it; each network prior beside
    uniform scatters of the ``prior`` fractions; the oracle beside the smallest of them; with ``lean``, each
    but the default again with the later stages cut to :data:`LEAN`."""
    size = {f: max(1, round(default_scatter * f)) for f in uniform + prior}
    out = [Variant(f"uniform-{n}", n, "uniform") for n in dict.fromkeys([default_scatter, *map(size.get, uniform)])]
    beside = list(dict.fromkeys(size[f] for f in prior))
    out += [Variant(f"{name}+{n}", n, "network", name) for name in weights for n in beside]
    out += [Variant(f"oracle+{min(beside)}", min(beside), "oracle")] if oracle else []
    return out + ([dataclasses.replace(v, name=f"lean {v.name}", lean=True) for v in out[1:]] if lean else [])


def config_for(variant: Variant, args: argparse.Namespace) -> AlignerConfig:
    """The node's defaults, with this variant's scatter and prior (the oracle plays the network's part)."""
    base = AlignerConfig()
    search = dataclasses.replace(base.recovery.search, n_scatter=variant.n_scatter, n_network=args.n_prior,
                                 network_scale=args.prior_scale, **(LEAN if variant.lean else {}))
    recovery = dataclasses.replace(base.recovery, search=search, weights=args.weights.get(variant.weights, ""),
                                   allow_pickle=args.allow_pickle,
                                   scatter="uniform" if variant.prior == "uniform" else "network")
    return dataclasses.replace(base, recovery=recovery)


class RecordedPrior:
    """The network's registrar, remembering the last mu0 it gave (to measure how far it was from the truth)."""

    def __init__(self, registrar) -> None:
        self.registrar = registrar
        self.mu0: Optional[np.ndarray] = None

    def register_batch(self, source, target, run_cem: bool = False):
        result = self.registrar.register_batch(source, target, run_cem=run_cem)
        self.mu0 = result.mu0[0]
        return result


class OraclePrior:
    """A stand-in for the network: mu0 at the true motion in the recovery's units, spread ``sigma`` (a first
    pair's recovery searches around the first pose, the identity: the truth there is S T_1_2 inv(S), S = 1/scale)."""

    def __init__(self, truth: np.ndarray, sigma: np.ndarray) -> None:
        self.truth, self.sigma = truth, np.asarray(sigma, dtype=np.float64)
        self.aligner, self.mu0 = None, None  # the aligner it serves (set once built), the last mu0 it gave

    def register_batch(self, source, target, run_cem: bool = False):
        assert self.aligner is not None and self.aligner.scale is not None
        to_units = np.diag([1.0 / self.aligner.scale] * 3 + [1.0])
        self.mu0 = matrix_to_action_np(to_units @ self.truth @ np.linalg.inv(to_units))
        return SimpleNamespace(mu0=self.mu0[None], sigma0=self.sigma[None])


class PriorOdometry:
    """A fresh ScanAligner with one variant's config, behind the benchmark's odometry ``process`` interface."""

    def __init__(self, config: AlignerConfig, variant: Variant, network, truth: np.ndarray,
                 oracle_sigma: np.ndarray) -> None:
        self.prior = (OraclePrior(truth, oracle_sigma) if variant.prior == "oracle"
                      else RecordedPrior(network) if variant.prior == "network" else None)
        self.aligner = ScanAligner(config, recovery_prior=self.prior)  # duck-typed: register_batch is all it uses
        if isinstance(self.prior, OraclePrior):
            self.prior.aligner = self.aligner

    def process(self, points: np.ndarray, stamp_ns: int):
        step = self.aligner.process(points, stamp_ns)
        return Output(np.asarray(step.pose), bool(step.accepted), str(step.reason))

    def prior_error(self, truth: np.ndarray) -> tuple[Optional[float], Optional[float]]:
        """(m, deg) of the prior's mu0 against the true motion; None without a prior (or before it ran)."""
        if self.prior is None or self.prior.mu0 is None or self.aligner.scale is None:
            return None, None
        units = np.diag([self.aligner.scale] * 3 + [1.0])  # units -> metres
        return metrics.relative_error(units @ action_to_matrix_np(self.prior.mu0) @ np.linalg.inv(units), truth)


def run_pair(pair, variant: Variant, config: AlignerConfig, networks: dict, oracle_sigma: np.ndarray) -> dict:
    """The pair through a fresh aligner: the second scan's step record, with the prior's own error."""
    built: list[PriorOdometry] = []

    def factory(max_range: float) -> PriorOdometry:
        built.append(PriorOdometry(config, variant, networks.get(variant.weights), pair.truth, oracle_sigma))
        return built[-1]

    record = pair_record(pair, run_stream(factory, 100.0, [pair.first, pair.second], [0, pair.gap]))
    record["prior_rte_m"], record["prior_rre_deg"] = built[0].prior_error(pair.truth) if built else (None, None)
    return record


def run(pairs: list, chosen: list[Variant], configs: dict, networks: dict, args: argparse.Namespace,
        meta: dict) -> dict:
    """Every pair through every variant (order rotating pair by pair); results written after each pair."""
    steps: dict[str, list[dict]] = {v.name: [] for v in chosen}
    for k, pair in enumerate(pairs):
        start = time.perf_counter()
        for v in chosen[k % len(chosen):] + chosen[:k % len(chosen)]:
            steps[v.name].append(run_pair(pair, v, configs[v.name], networks, args.oracle_sigma))
        log(f"pair {k + 1}/{len(pairs)} {pair.name}: {time.perf_counter() - start:.0f} s")
        write_results(args.out, meta, chosen, steps)
    return steps


def summaries(chosen: list[Variant], steps: dict) -> dict:
    """Per variant: the benchmark's summary, the prior's own recall, and time ratios against the default."""
    default, out = chosen[0].name, {}
    for variant in chosen:
        own = steps[variant.name]
        summary, base = metrics.summarize(own), metrics.summarize(steps[default])
        paired = [s["ms"] / d["ms"] for s, d in zip(own, steps[default]) if s["ms"] and d["ms"]]
        priors = [s for s in own if s["prior_rte_m"] is not None]
        summary.update({
            "ms_median_ratio": summary["ms_median"] / base["ms_median"],  # every step is timed, failed ones too
            "ms_p90_ratio": summary["ms_p90"] / base["ms_p90"],
            "ms_paired_ratio": float(np.median(paired)) if paired else None,
            "prior_recall": (sum(metrics.within(s["prior_rte_m"], s["prior_rre_deg"], metrics.RECALL_M,
                                                metrics.RECALL_DEG) for s in priors) / len(priors)) if priors else None,
        })
        out[variant.name] = summary
    return out


def verdicts(chosen: list[Variant], summary: dict) -> list[str]:
    """Issue 12's criterion for each prior variant, in words (time: the ratio of medians and the paired ratio)."""
    recall, default = {v.name: summary[v.name]["recall"] for v in chosen}, chosen[0].name
    ratios = {n: (summary[n]["ms_median_ratio"], summary[n]["ms_paired_ratio"] or np.inf) for n in recall}
    uniform, lines = [v.name for v in chosen if v.prior == "uniform"], []
    for name in (v.name for v in chosen if v.prior != "uniform"):
        same_recall_faster = recall[name] >= recall[default] and max(ratios[name]) <= 0.5
        beaten = [u for u in uniform if min(np.subtract(ratios[u], ratios[name])) >= 0 and recall[name] > recall[u]]
        why = ("the default's recall at <= 0.5x its time" if same_recall_faster else
               f"a higher recall than {', '.join(beaten)} (which took at least as long)" if beaten else
               "neither the default's recall at <= 0.5x its time nor a higher recall at the same time")
        lines.append(f"- {name}: {'PAYS' if same_recall_faster or beaten else 'does not pay'}: {why} ({NOISE})")
    return lines


def table(chosen: list[Variant], summary: dict, n_prior: int) -> str:
    """The markdown table of the variants."""
    lines = ["| config | prior draws | recall | precise | accepted wrong | flagged | failed | ms med | ms p90 | "
             "med / default | p90 / default | paired / default | prior's mu0 within recall |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for variant in chosen:
        s = summary[variant.name]
        lines.append(f"| {variant.name} | {0 if variant.prior == 'uniform' else n_prior} | {_pct(s['recall'])} | "
                     f"{_pct(s['precise'])} | {s['accepted_wrong']} | {s['flagged']} | {s['failed']} | "
                     f"{_num(s['ms_median'], '.0f')} | {_num(s['ms_p90'], '.0f')} | {_num(s['ms_median_ratio'])} | "
                     f"{_num(s['ms_p90_ratio'])} | {_num(s['ms_paired_ratio'])} | {_pct(s['prior_recall'])} |")
    return "\n".join(lines)


def _num(value: Optional[float], fmt: str = ".2f") -> str:
    return "-" if value is None else format(value, fmt)


def _pct(value: Optional[float]) -> str:
    return _num(None if value is None else 100 * value, ".0f") + ("" if value is None else "%")


def write_results(out: Path, meta: dict, chosen: list[Variant], steps: dict) -> str:
    """JSON (everything) and markdown (the table and the verdicts) beside it, both atomically; the markdown."""
    summary = summaries(chosen, steps)
    lines = verdicts(chosen, summary) if all(steps.values()) else []
    weights = ", ".join(f"{name} = {path or 'the ModelNet40 weights'}" for name, path in meta["weights"].items())
    markdown = "\n\n".join([f"{len(steps[chosen[0].name])} pairs ({meta['pairs_from']}), seeds {meta['seeds']}; "
                            f"weights: {weights}; {NOISE}",
                            table(chosen, summary, meta["n_prior"]), "\n".join(lines), DEFINITIONS]) + "\n"
    configs = {v.name: {"variant": dataclasses.asdict(v), "summary": summary[v.name], "steps": steps[v.name]}
               for v in chosen}
    write_report(out, json_text({"meta": meta, "configs": configs, "verdicts": lines}))
    write_report(out.with_suffix(".md"), markdown)
    return markdown


def parse_args(argv: Optional[list[str]]) -> argparse.Namespace:
    search = GlobalSearchConfig()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=20, help="large-motion pairs per seed (default 20)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1], help="pair seeds (default 0 1)")
    parser.add_argument("--uniform-fractions", type=float, nargs="+", default=[0.5, 0.25],
                        help="uniform scatters besides the default, as fractions of it (default 0.5 0.25)")
    parser.add_argument("--prior-fractions", type=float, nargs="+", default=[0.25, 0.5],
                        help="the uniform scatters beside the prior, as fractions of the default (default 0.25 0.5)")
    parser.add_argument("--weights", nargs="+", default=["scan=scan"], metavar="NAME=PATH",
                        help="the networks compared, each NAME=PATH (PATH 'scan' = the package's LiDAR scan weights, "
                        "'' = its ModelNet40 weights, 'official', or a file; default: scan=scan)")
    parser.add_argument("--bag", type=Path, help="pairs from this bag's scans (it needs ground truth) instead of the "
                        "ray-cast large-motion pairs: --pairs per seed, as benchmarks.pairs.bag_pairs makes them")
    parser.add_argument("--allow-pickle", action="store_true", help="allow pickled (.pth) weights you trust")
    parser.add_argument("--n-prior", type=int, default=search.n_network,
                        help=f"prior draws: recovery.search.n_network (default {search.n_network})")
    parser.add_argument("--prior-scale", type=float, default=search.network_scale,
                        help="k: sigma0's widening (recovery.search.network_scale)")
    parser.add_argument("--oracle", action=argparse.BooleanOptionalAction, default=True,
                        help="add a prior at the true motion (default: on)")
    parser.add_argument("--oracle-sigma", type=float, nargs=6, default=[0.05, 0.02, 0.02, 0.05, 0.05, 0.01],
                        help="its spread [euler z, y, x (rad), tx, ty, tz (units)]")
    parser.add_argument("--lean", action="store_true", help=f"also each variant but the default with {LEAN}")
    parser.add_argument("--out", type=Path, default=REPO / "results" / "bench_recovery_prior.json",
                        help="JSON output (the markdown goes beside it, .md)")
    args = parser.parse_args(argv)
    if args.pairs < 1 or args.n_prior < 0 or min(args.prior_scale, *args.uniform_fractions, *args.prior_fractions) <= 0:
        parser.error("--pairs must be >= 1, --n-prior >= 0, --prior-scale and the fractions > 0")
    args.oracle_sigma = np.asarray(args.oracle_sigma, dtype=np.float64)
    if not all("=" in w for w in args.weights):
        parser.error("--weights takes NAME=PATH entries")
    args.weights = dict(w.split("=", 1) for w in args.weights)
    return args


def main(argv: Optional[list[str]] = None) -> int:
    args = parse_args(argv)
    chosen = variants(GlobalSearchConfig().n_scatter, args.uniform_fractions, args.prior_fractions, args.oracle,
                      args.weights, args.lean)
    configs = {v.name: config_for(v, args) for v in chosen}
    one_variant = {v.weights: v.name for v in chosen if v.prior == "network"}  # per network: its variants share it
    networks = {name: prior_registrar(configs[variant]) for name, variant in one_variant.items()}  # loaded once
    meta = {"argv": sys.argv[1:] if argv is None else list(argv), "seeds": args.seeds, "pairs_per_seed": args.pairs,
            "weights": args.weights, "pairs_from": str(args.bag or "ray-cast large-motion pairs"),
            "n_prior": args.n_prior, "prior_scale": args.prior_scale,
            "oracle_sigma": args.oracle_sigma, "timings": NOISE,
            "variants": [dataclasses.asdict(v) for v in chosen], "python": platform.python_version(),
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    log(f"variants: {', '.join(v.name for v in chosen)}; {args.pairs} pairs per seed {args.seeds} from "
        f"{args.bag or 'ray-casting'}")

    posed = read_posed_scans(args.bag) if args.bag else None

    def make_pairs(n: int, seed: int) -> list:
        return bag_pairs(*posed, n, seed) if posed else large_motion_pairs(n, seed)

    pairs = [dataclasses.replace(pair, name=f"s{seed}/{pair.name}")
             for seed in args.seeds for pair in make_pairs(args.pairs, seed)]
    warm = make_pairs(1, max(args.seeds) + 1000)[0]
    for variant in chosen:  # untimed: kernels compiled, the network's first call paid
        run_pair(warm, variant, configs[variant.name], networks, args.oracle_sigma)
    steps = run(pairs, chosen, configs, networks, args, meta)
    print(write_results(args.out, meta, chosen, steps))
    print(f"wrote {args.out} and {args.out.with_suffix('.md')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
