"""Every piece of the library benchmark on one sequence: voxel grid, map update, nearest points, polish."""
from __future__ import annotations

from functools import partial
from types import ModuleType
from typing import Any, Optional

import numba
import numpy as np

from benchmarks.libraries.inputs import (
    FINE_DISTANCE_VOXELS,
    OFFSETS,
    Step,
    orthonormal,
    perturbed,
    polish_stages,
    polish_steps,
    sequence_frames,
)
from benchmarks.libraries.local_maps import agreement, downsample_calls, filled_maps, local_maps, nearest_calls
from benchmarks.libraries.peers import OURS, THREADS
from benchmarks.libraries.timing import interleaved, timing_summary
from benchmarks.metrics import percentile, relative_error
from benchmarks.real import OFF_DEG, OFF_M, Sequence
from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.io.console import progress
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.steps.frame import Frame, cropped


def bench_downsample(sequence: Sequence, frames: list[Frame], config: AlignerConfig, peers: dict[str, ModuleType],
                     n_scans: int, rounds: int) -> dict:
    """ms per full cropped scan of each voxel grid at the frame voxel, and the points each keeps."""
    times: dict[str, list[float]] = {}
    kept: dict[str, list[int]] = {}
    for points in progress(sequence.scans[:n_scans], desc=f"{sequence.name}: downsample"):
        scan = cropped(points, config.preprocess)
        kept.setdefault("in", []).append(len(scan))
        outputs = interleaved(downsample_calls(scan, frames[0].voxel, peers), rounds, times)
        for name, out in outputs.items():
            kept.setdefault(name, []).append(len(out))
    counts = {name: int(np.mean(n)) for name, n in kept.items()}
    return {"ms": timing_summary(times), "points_in": counts.pop("in"), "points_out": counts}


def bench_map_update(frames: list[Frame], poses: list[np.ndarray], config: AlignerConfig,
                     peers: dict[str, ModuleType], max_range: float, n_scans: int, rounds: int) -> dict:
    """ms per scan inserted into each method's growing local map (a fresh stream of ``n_scans`` per round; the
    first insertion, into an empty map, is left out)."""
    times: dict[str, list[float]] = {}
    T_first_world = np.linalg.inv(poses[0])
    for _ in progress(range(rounds), desc="map update"):
        maps = local_maps(peers, config, frames[0].voxel, max_range)
        for k in range(n_scans):
            calls = {name: partial(m.insert, frames[k].dense, T_first_world @ poses[k]) for name, m in maps.items()}
            interleaved(calls, 1, {} if k == 0 else times)
    return {"ms": timing_summary(times), "scans": n_scans}


def bench_nearest(steps: list[Step], frames: list[Frame], config: AlignerConfig, peers: dict[str, ModuleType],
                  max_range: float, rounds: int) -> dict:
    """ms per query of a whole voxel cloud against the step's map, at the fine pairing distance; the k-d trees'
    build ms; how often each method agrees with ours."""
    voxel = frames[0].voxel
    max_distance = FINE_DISTANCE_VOXELS * voxel
    times: dict[str, list[float]] = {}
    build_times: dict[str, list[float]] = {}
    same: dict[str, list[float]] = {}
    for step in progress(steps, desc="nearest"):
        ours = filled_maps(step, {}, config, voxel, max_range)[OURS]
        query = apply_transform(step.T_target_source, step.dense)
        outputs = interleaved(nearest_calls(ours.map, query, max_distance, peers, build_times), rounds, times)
        for name, dist in outputs.items():
            same.setdefault(name, []).append(agreement(outputs[OURS], dist))
    return {"ms": timing_summary(times), "build_ms": timing_summary(build_times), "max_distance_m": max_distance,
            "agreement": {name: float(np.mean(v)) for name, v in same.items()}}


def bench_polish(steps: list[Step], frames: list[Frame], config: AlignerConfig, peers: dict[str, ModuleType],
                 max_range: float, seeds: int, rounds: int) -> tuple[dict, list[dict]]:
    """Each step polished by every method from the truth perturbed by each of :data:`OFFSETS` (``seeds`` random
    directions each): ms per polish, steps taken and errors, per offset; and every trial's record."""
    stages = polish_stages(config, frames[0].voxel)
    times: dict[str, dict[str, list[float]]] = {}
    trials = []
    for step in progress(steps, desc="polish"):
        maps = filled_maps(step, peers, config, frames[0].voxel, max_range)
        for metres, degrees in OFFSETS:
            offset = f"{metres:g} m / {degrees:g} deg"
            for seed in range(seeds):
                initial = perturbed(step.T_target_source, metres, degrees, np.random.default_rng([seed, step.index]))
                calls = {name: partial(m.polish, step, initial, stages) for name, m in maps.items()}
                for name, (T_target_source, steps_taken) in interleaved(calls, rounds,
                                                                        times.setdefault(offset, {})).items():
                    rte, rre = relative_error(T_target_source, step.T_target_source)
                    trials.append({"method": name, "offset": offset, "seed": seed, "index": step.index,
                                   "rte_m": rte, "rre_deg": rre, "iterations": steps_taken})
    summary = {offset: polish_summary(t, [r for r in trials if r["offset"] == offset]) for offset, t in times.items()}
    return summary, trials


def polish_summary(times: dict[str, list[float]], trials: list[dict]) -> dict[str, dict]:
    """:func:`timing_summary` with each method's median steps, median errors and success rate (within
    OFF_M and OFF_DEG of the truth)."""
    out = timing_summary(times)
    for name, row in out.items():
        mine = [r for r in trials if r["method"] == name]
        iterations = [r["iterations"] for r in mine if r["iterations"] is not None]
        row.update(trials=len(mine), iterations_median=percentile(iterations, 50),
                   rte_median_m=percentile([r["rte_m"] for r in mine], 50),
                   rre_median_deg=percentile([r["rre_deg"] for r in mine], 50),
                   success=float(np.mean([r["rte_m"] <= OFF_M and r["rre_deg"] <= OFF_DEG for r in mine])))
    return out


def bench_sequence(sequence: Sequence, peers: dict[str, ModuleType], pairs: int, map_scans: int, seeds: int,
                   rounds: int, config: Optional[AlignerConfig] = None) -> dict:
    """Every piece on one sequence: downsample, map update, nearest points, polish (1 and ``map_scans`` scans)."""
    config = config or AlignerConfig()
    numba.set_num_threads(THREADS)
    frames = sequence_frames(sequence, config)
    poses = [orthonormal(T_world_sensor) for T_world_sensor in sequence.poses]
    n_scans = min(len(frames), map_scans + pairs)
    out: dict[str, Any] = {
        "voxel_m": frames[0].voxel, "map_voxel_m": frames[0].voxel * config.map.voxel_factor,
        "stages": [vars(s) for s in polish_stages(config, frames[0].voxel)],
        "dense_points": int(np.mean([len(f.dense) for f in frames])),
        "downsample": bench_downsample(sequence, frames, config, peers, n_scans, rounds),
        "map_update": bench_map_update(frames, poses, config, peers, sequence.max_range, n_scans, rounds),
        "nearest": bench_nearest(polish_steps(frames, poses, map_scans, pairs), frames, config, peers,
                                 sequence.max_range, rounds),
        "polish": {}, "trials": {}}
    for n_map in sorted({1, map_scans}):
        label = f"map of {n_map} scan{'s' if n_map > 1 else ''}"
        steps = polish_steps(frames, poses, n_map, pairs)
        out["polish"][label], out["trials"][label] = bench_polish(steps, frames, config, peers, sequence.max_range,
                                                                  seeds, rounds)
    return out
