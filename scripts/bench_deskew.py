#!/usr/bin/env python3
"""Deskew benchmark: ``ScanAligner`` (default config) on skewed synthetic drives, deskew on vs off.

Each drive (:func:`cemnet_ros.data.skewed.skewed_sequence`, seeds ``--seed + k``) circles a walled plaza at
15 m/s and 30 deg/s yaw; every azimuth column of the 32-beam sweep is ray-cast from the pose at its own time
(0.1 s sweep, stamp at ``--stamp-at`` of it: 0 = start, Ouster-like). Both runs get the same points and the
per-point times; only ``AlignerConfig.deskew`` differs. ``--ideal`` adds the same drives cast instantaneously
(no skew, deskew off): the floor deskewing can reach.

``--layouts`` runs the same drives through ROS 2 drivers' PointCloud2 layouts (``benchmarks/sensor_layouts.py``,
docs/sensors.md): each scan is written as the driver publishes it (its stamp's place in the sweep, its time field,
its no-returns), serialized and decoded by the node's own path (``cemnet_ros.ros.scans.decode``); "off" aligns the
decoded points without deskewing (as with a driver that publishes no times), "on" with the decoded times.

Metrics: ATE = position RMSE with both trajectories expressed in their first pose's frame (as
bench_robustness.py), ATE aligned = after the best rigid alignment, RPE = per-step relative translation (m) and
rotation (deg) error, ms = wall time of ``process`` (median / p90), flagged = steps not accepted.

    python scripts/bench_deskew.py                     # 3 drives x 50 scans
    python scripts/bench_deskew.py --quick             # 1 drive x 12 small scans (smoke run)
    python scripts/bench_deskew.py --drives 5 --scans 60 --out results/deskew_5x60.json
    python scripts/bench_deskew.py --layouts all       # the five drivers' layouts, the plain arrays beside them
"""
from __future__ import annotations

import argparse
import dataclasses
import platform
import sys
import time
from pathlib import Path
from typing import Optional

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from benchmarks.metrics import ate_first_pose, percentile  # noqa: E402
from cemnet_ros.data.scenes import LidarModel  # noqa: E402
from cemnet_ros.data.skewed import SPEED, YAW_RATE_DEG, SkewedSequence, skewed_sequence  # noqa: E402
from cemnet_ros.io.atomic import json_text, write_report  # noqa: E402
from cemnet_ros.io.console import log, progress  # noqa: E402
from cemnet_ros.replay.trajectory import absolute_trajectory_error, relative_pose_errors  # noqa: E402

MODES = ("off", "on")
FULL = {"drives": 3, "scans": 50, "beams": 32, "azimuth": 1000}
QUICK = {"drives": 1, "scans": 12, "beams": 16, "azimuth": 360}


def run_drive(sequence: SkewedSequence, deskew: bool, label: str, with_times: bool = True) -> dict:
    """One fresh ScanAligner (default config, ``deskew`` set) over the drive; metrics of the processed scans."""
    from cemnet_ros.pipeline.aligner import AlignerConfig, ScanAligner

    config = AlignerConfig()
    aligner = ScanAligner(dataclasses.replace(config, preprocess=dataclasses.replace(config.preprocess, deskew=deskew)))
    poses, truth, ms, flagged, errors = [], [], [], 0, []
    steps = list(zip(sequence.scans, sequence.times, sequence.stamps_ns, sequence.poses))
    for k, (points, times, stamp_ns, pose_true) in enumerate(progress(steps, label)):
        start = time.perf_counter()
        try:
            step = aligner.process(points.astype(np.float64), stamp_ns, times if with_times else None)
        except Exception as exc:  # noqa: BLE001 - the benchmark counts every failure
            errors.append(f"scan {k}: {type(exc).__name__}: {exc}")
            continue
        ms.append(1e3 * (time.perf_counter() - start))
        poses.append(np.asarray(step.pose))
        truth.append(pose_true)
        flagged += int(not step.accepted and k > 0)
    out = {"processed": len(poses), "failed": len(errors), "errors": errors, "flagged": flagged,
           "ms_median": percentile(ms[1:], 50), "ms_p90": percentile(ms[1:], 90),
           "ate_m": None, "ate_aligned_m": None, "rpe_trans_mean_m": None, "rpe_rot_mean_deg": None,
           "end_error_m": None, "poses": poses}
    if len(poses) >= 2:
        rpe = relative_pose_errors(poses, truth)
        end = (np.linalg.inv(poses[0]) @ poses[-1])[:3, 3] - (np.linalg.inv(truth[0]) @ truth[-1])[:3, 3]
        out.update(ate_m=ate_first_pose(poses, truth), ate_aligned_m=absolute_trajectory_error(poses, truth).rmse,
                   rpe_trans_mean_m=float(rpe.trans_errors.mean()),
                   rpe_trans_median_m=float(np.median(rpe.trans_errors)),
                   rpe_rot_mean_deg=float(rpe.rot_errors_deg.mean()), end_error_m=float(np.linalg.norm(end)))
    return out


def warm_up() -> None:
    """A short small drive through one aligner, so that no timed scan pays for loading or JIT compiling."""
    lidar = LidarModel(n_beams=8, n_azimuth=180)
    run_drive(skewed_sequence(3, seed=999, lidar=lidar), True, "warm-up")


def _f(value, fmt: str = ".3f") -> str:
    return "-" if value is None else format(value, fmt)


def table(drives: list[dict]) -> str:
    """One row per (drive, mode), then the means over drives and the ATE ratios."""
    lines = ["| drive | seed | deskew | scans | flagged | ATE (m) | ATE aligned (m) | RPE mean (m) | RPE mean (deg) | "
             "end error (m) | ms med | ms p90 |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    modes = [m for m in ("off", "on", "ideal") if m in drives[0]["modes"]]
    for d in drives:
        for mode in modes:
            r = d["modes"][mode]
            lines.append(f"| {d['index']} | {d['seed']} | {mode} | {r['processed']} | {r['flagged']} | "
                         f"{_f(r['ate_m'])} | {_f(r['ate_aligned_m'])} | {_f(r['rpe_trans_mean_m'])} | "
                         f"{_f(r['rpe_rot_mean_deg'], '.3f')} | {_f(r['end_error_m'])} | "
                         f"{_f(r['ms_median'], '.0f')} | {_f(r['ms_p90'], '.0f')} |")
    summary = summarize(drives)
    for mode in modes:
        s = summary[mode]
        lines.append(f"| mean | - | {mode} | - | {s['flagged']} | {_f(s['ate_m'])} | {_f(s['ate_aligned_m'])} | "
                     f"{_f(s['rpe_trans_mean_m'])} | {_f(s['rpe_rot_mean_deg'])} | {_f(s['end_error_m'])} | "
                     f"{_f(s['ms_median'], '.0f')} | - |")
    ratios = ", ".join(f"seed {d['seed']}: {_f(d['ate_ratio_on_off'])}" for d in drives)
    lines += ["", f"ATE_on / ATE_off: mean ATE {_f(summary['ate_ratio_on_off'])} (per drive: {ratios}; "
                  f"worst {_f(summary['ate_ratio_worst'])})"]
    return "\n".join(lines)


def summarize(drives: list[dict]) -> dict:
    """Means over drives per mode, and ATE_on / ATE_off of those means (and the worst drive's)."""
    out = {}
    for mode in drives[0]["modes"]:
        runs = [d["modes"][mode] for d in drives]

        def mean(key):
            vals = [r[key] for r in runs if r[key] is not None]
            return float(np.mean(vals)) if vals else None

        out[mode] = {k: mean(k) for k in ("ate_m", "ate_aligned_m", "rpe_trans_mean_m", "rpe_rot_mean_deg",
                                          "end_error_m", "ms_median")}
        out[mode]["flagged"] = sum(r["flagged"] for r in runs)
    on, off = out["on"]["ate_m"], out["off"]["ate_m"]
    out["ate_ratio_on_off"] = on / off if on is not None and off else None
    ratios = [d["ate_ratio_on_off"] for d in drives if d["ate_ratio_on_off"] is not None]
    out["ate_ratio_worst"] = max(ratios) if ratios else None
    return out


def write_json(path: Path, meta: dict, drives: list[dict]) -> None:
    """Atomic JSON of everything measured so far."""
    write_report(path, json_text({"meta": meta, "drives": drives, "summary": summarize(drives) if drives else {}}))


def layout_sequence(sequence: SkewedSequence, layout_name: str, lidar: LidarModel) -> SkewedSequence:
    """``sequence`` as the node decodes it from the driver layout ``layout_name``: its points (no-returns dropped)
    and their times, read back from CDR bytes by :func:`cemnet_ros.ros.scans.decode`."""
    from benchmarks.sensor_layouts import LAYOUTS, decoded, driver_clouds

    scans = [decoded(cloud) for cloud in driver_clouds(LAYOUTS[layout_name], sequence, lidar)]
    unusable = [scan.warnings for scan in scans if scan.times is None or scan.warnings]
    if unusable:
        raise RuntimeError(f"{layout_name}: the node could not use the time field: {unusable[0]}")
    return SkewedSequence([s.points for s in scans], [s.times for s in scans], sequence.poses,
                          [s.stamp_ns for s in scans], {**sequence.info, "layout": layout_name})


def run_layouts(args: argparse.Namespace, lidar: LidarModel, seeds: list[int]) -> dict:
    """Every drive in every layout of ``args.layouts`` (and as plain arrays, per stamp placement): off and on."""
    from benchmarks.sensor_layouts import LAYOUTS

    results: dict = {}
    for k, seed in enumerate(seeds):
        for stamp_at in sorted({LAYOUTS[name].stamp_at for name in args.layouts}):
            sequence = skewed_sequence(args.scans, seed=seed, lidar=lidar, stamp_at=stamp_at,
                                       progress=lambda it: progress(it, f"drive {k}: ray-cast"))
            names = [f"arrays, stamp at {stamp_at:g}"] + [n for n in args.layouts if LAYOUTS[n].stamp_at == stamp_at]
            for name in names:
                seq = sequence if name.startswith("arrays") else layout_sequence(sequence, name, lidar)
                modes = {mode: run_drive(seq, mode == "on", f"{name}, drive {k}: deskew {mode}") for mode in MODES}
                on, off = modes["on"]["ate_m"], modes["off"]["ate_m"]
                results.setdefault(name, []).append({"index": k, "seed": seed, **seq.info, "truth": seq.poses,
                                                     "modes": modes,
                                                     "ate_ratio_on_off": on / off if on is not None and off else None})
                log(f"{name}, drive {k} (seed {seed}): ATE off {_f(off)} m, on {_f(on)} m")
    return results


def layouts_table(results: dict) -> str:
    """One row per layout: the means over its drives, off and on."""
    lines = ["| layout | drives | ATE off (m) | ATE on (m) | on / off | worst drive on / off | RPE on (m, deg) | "
             "flagged off / on |", "|---|---|---|---|---|---|---|---|"]
    for name, drives in results.items():
        s = summarize(drives)
        lines.append(f"| {name} | {len(drives)} | {_f(s['off']['ate_m'])} | {_f(s['on']['ate_m'])} | "
                     f"{_f(s['ate_ratio_on_off'], '.2f')} | {_f(s['ate_ratio_worst'], '.2f')} | "
                     f"{_f(s['on']['rpe_trans_mean_m'], '.4f')}, {_f(s['on']['rpe_rot_mean_deg'])} | "
                     f"{s['off']['flagged']} / {s['on']['flagged']} |")
    return "\n".join(lines)


def parse_args(argv: Optional[list[str]]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help=f"tiny sizes for a smoke run: {QUICK}")
    parser.add_argument("--drives", type=int, help=f"drives (default {FULL['drives']})")
    parser.add_argument("--scans", type=int, help=f"scans per drive at 10 Hz (default {FULL['scans']})")
    parser.add_argument("--beams", type=int, help=f"LiDAR beams (default {FULL['beams']})")
    parser.add_argument("--azimuth", type=int, help=f"azimuth columns per sweep (default {FULL['azimuth']})")
    parser.add_argument("--seed", type=int, default=0, help="drive k uses seed + k (scene layout, start, turn side)")
    parser.add_argument("--stamp-at", type=float, default=0.0,
                        help="where the stamp lies in the sweep: 0 = start (Ouster), 1 = end (Velodyne)")
    parser.add_argument("--ideal", action="store_true", help="also run unskewed (instantaneous) scans")
    parser.add_argument("--layouts", nargs="+", metavar="NAME",
                        help="run the drives through these drivers' PointCloud2 layouts (ouster velodyne hesai livox "
                             "robosense, or all); each uses its driver's stamp placement (--stamp-at is ignored)")
    parser.add_argument("--out", type=Path, default=REPO / "results" / "bench_deskew.json", help="JSON output")
    args = parser.parse_args(argv)
    if args.layouts:
        from benchmarks.sensor_layouts import LAYOUTS

        args.layouts = list(LAYOUTS) if args.layouts == ["all"] else args.layouts
        unknown = sorted(set(args.layouts) - set(LAYOUTS))
        if unknown:
            parser.error(f"unknown layouts {unknown} (choose from {sorted(LAYOUTS)} or all)")
        if args.ideal:
            parser.error("--ideal is not run with --layouts")
    sizes = QUICK if args.quick else FULL
    for key, value in sizes.items():
        if getattr(args, key) is None:
            setattr(args, key, value)
        if getattr(args, key) < (3 if key == "scans" else 1):
            parser.error(f"--{key} must be >= {3 if key == 'scans' else 1}")
    if not 0.0 <= args.stamp_at <= 1.0:
        parser.error("--stamp-at must lie in [0, 1]")
    return args


def main(argv: Optional[list[str]] = None) -> int:
    args = parse_args(argv)
    lidar = LidarModel(n_beams=args.beams, n_azimuth=args.azimuth)
    seeds = [args.seed + k for k in range(args.drives)]
    meta = {"argv": sys.argv[1:] if argv is None else list(argv), "seeds": seeds, "scans": args.scans,
            "lidar": {"beams": args.beams, "azimuth": args.azimuth}, "speed_mps": SPEED,
            "yaw_rate_deg": YAW_RATE_DEG, "stamp_at": args.stamp_at, "config": "AlignerConfig() defaults",
            "python": platform.python_version(), "machine": platform.machine(),
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    log(f"seeds: {seeds}; {args.scans} scans per drive, {args.beams} x {args.azimuth} LiDAR")
    warm_up()
    if args.layouts:
        results = run_layouts(args, lidar, seeds)
        for name, drives in results.items():
            print(f"\n{name}\n\n{table(drives)}")
        print(f"\n{layouts_table(results)}")
        write_report(args.out, json_text({"meta": {**meta, "layouts": args.layouts}, "layouts": {
            name: {"drives": drives, "summary": summarize(drives)} for name, drives in results.items()}}))
        print(f"\nwrote {args.out}")
        return 0
    drives = []
    for k, seed in enumerate(seeds):
        sequence = skewed_sequence(args.scans, seed=seed, lidar=lidar, stamp_at=args.stamp_at,
                                   progress=lambda it: progress(it, f"drive {k}: ray-cast"))
        modes = {mode: run_drive(sequence, mode == "on", f"drive {k}: deskew {mode}") for mode in MODES}
        if args.ideal:
            ideal = skewed_sequence(args.scans, seed=seed, lidar=lidar, stamp_at=args.stamp_at, skew=False,
                                    progress=lambda it: progress(it, f"drive {k}: ray-cast ideal"))
            modes["ideal"] = run_drive(ideal, False, f"drive {k}: ideal")
        on, off = modes["on"]["ate_m"], modes["off"]["ate_m"]
        drives.append({"index": k, "seed": seed, **sequence.info, "truth": sequence.poses, "modes": modes,
                       "ate_ratio_on_off": on / off if on is not None and off else None})
        log(f"drive {k} (seed {seed}): ATE off {_f(off)} m, on {_f(on)} m")
        write_json(args.out, meta, drives)
    print(table(drives))
    write_json(args.out, meta, drives)
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
