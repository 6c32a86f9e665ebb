"""cemnet-replay: run the scan pipeline (ScanAligner, sequential mode) over a rosbag2 bag offline, no DDS.

Reads PointCloud2 scans (and ``/ground_truth`` PoseStamped/Odometry when present), aligns them at full speed and
writes into ``--out``: ``replay.mcap`` with what align_node (default node name) would have published:
/align_node/odometry (odom_frame -> base_frame, twist, covariances), /align_node/pose, /tf and, with
publish_aligned_cloud, /align_node/aligned_cloud; plus the input's ground truth and /tf_static, copied unchanged,
so that ``evo_ape bag2 replay.mcap /ground_truth /align_node/odometry -a`` scores it on its own. Also
``trajectory_tum.txt`` (+ ``ground_truth_tum.txt``), ``summary.json`` and ``replay.png``. Prints ATE/RPE of the
base frame against the ground truth, per-pair errors, latency and throughput.

    cemnet-replay bags/kitti_00_6scans.mcap --out results/replay/kitti
    cemnet-replay bags/synthetic_lidar.mcap --registration.cem.n_candidates 300 --limit 8
"""
from __future__ import annotations

import argparse
import heapq
import json
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np
import yaml
from tqdm import tqdm

from cemnet_ros.io.atomic import atomic_write_text
from cemnet_ros.pipeline.config import DERIVED, AlignerConfig
from cemnet_ros.pipeline.extrinsic import BaseFrame, pose_from_xyz_rpy
from cemnet_ros.pipeline.odometry_output import odometry_output
from cemnet_ros.replay.bag_io import (
    ODOMETRY,
    POINTCLOUD2,
    POSE_STAMPED,
    TF_MESSAGE,
    TF_STATIC_TOPIC,
    TF_TOPIC,
    BagError,
    BagReader,
    BagWriter,
)
from cemnet_ros.replay.trajectory import absolute_trajectory_error, associate, relative_pose_errors, write_tum
from cemnet_ros.ros.node_config import NodeConfig
from cemnet_ros.schema import add_arguments, build, flatten_mapping, parameters, parsed_overrides

NODE_NAME = "align_node"  # the node's default name: replay.mcap carries its topics, as a live run would
POSE_TOPIC, ODOM_TOPIC, CLOUD_TOPIC = (f"/{NODE_NAME}/{name}" for name in ("pose", "odometry", "aligned_cloud"))

PIPELINE = parameters(AlignerConfig(), exclude=DERIVED)  # the flags and params-file names it accepts
# The node's own parameters that shape its outputs offline (frames, extrinsic, covariances, TF, cloud); the
# others (topics, QoS, queue) mean nothing without DDS. Flags as for the pipeline; --config gives them too.
NODE = {name: p for name, p in parameters(NodeConfig()).items() if name in (
    "odom_frame", "base_frame", "base_to_sensor", "covariance_mode", "fixed_position_variance",
    "fixed_orientation_variance", "publish_tf", "invert_tf", "publish_aligned_cloud", "aligned_cloud_voxel")}


# ---------------------------------------------------------------------------------------------- config
def _read_params(path: Optional[Path]) -> dict[str, Any]:
    """Every parameter (dotted names) of a YAML file: ROS style ``<node or /**>: {ros__parameters: ...}`` or a
    plain mapping, nested or dotted."""
    if path is None:
        return {}
    data = yaml.safe_load(Path(path).read_text()) or {}
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a mapping of parameters")
    for value in data.values():  # ROS 2 parameter file: the first node's ros__parameters
        if isinstance(value, dict) and "ros__parameters" in value:
            data = value["ros__parameters"]
            break
    return flatten_mapping(data)


def load_params(path: Optional[Path]) -> dict[str, Any]:
    """Pipeline parameters (dotted names) from a YAML file (see :func:`_read_params`); the node's own
    parameters are left out (:func:`load_node_params` reads them)."""
    node_only = set(parameters(NodeConfig()))
    return {k: v for k, v in _read_params(path).items() if k not in node_only}


def load_node_params(path: Optional[Path]) -> dict[str, Any]:
    """The node's own parameters (NodeConfig names: frames, extrinsic, covariance mode, ...) from the same file."""
    node_only = set(parameters(NodeConfig()))
    return {k: v for k, v in _read_params(path).items() if k in node_only}


def tf_parent_child(node: NodeConfig, T_odom_base: np.ndarray) -> tuple[str, str, np.ndarray]:
    """(parent, child, transform) of the /tf message, as align_node publishes it (invert_tf: base -> odom)."""
    if node.invert_tf:
        return node.base_frame, node.odom_frame, np.linalg.inv(T_odom_base)
    return node.odom_frame, node.base_frame, T_odom_base


# ---------------------------------------------------------------------------------------------- replay
@dataclass
class ReplayResult:
    """Everything the report and the JSON summary need."""

    stamps_ns: list[int] = field(default_factory=list)
    poses: list[np.ndarray] = field(default_factory=list)
    steps: list[dict] = field(default_factory=list)  # per processed scan: fitness, accepted, reason, ...
    rejected: list[dict] = field(default_factory=list)  # scans the pipeline refused (ScanRejected)
    wall_s: float = 0.0


def output_topics(node: NodeConfig) -> dict[str, str]:
    """Topic -> message type that align_node publishes per scan with these parameters (and replay.mcap holds)."""
    topics = {ODOM_TOPIC: ODOMETRY, POSE_TOPIC: POSE_STAMPED}
    if node.publish_tf:
        topics[TF_TOPIC] = TF_MESSAGE
    if node.publish_aligned_cloud:
        topics[CLOUD_TOPIC] = POINTCLOUD2
    return topics


def copied_topics(reader: BagReader, node: NodeConfig) -> list[str]:
    """The input's topics copied unchanged into replay.mcap: the ground truth and /tf_static (when present)."""
    copies = [t for t in (reader.info.gt_topic, TF_STATIC_TOPIC) if t is not None and t in reader.info.topics]
    clash = sorted(set(copies) & set(output_topics(node)))
    if clash:
        raise BagError(f"input topic(s) {clash} would be overwritten by the replay's outputs")
    return copies


def run_replay(reader: BagReader, aligner, out_bag: Path, limit: Optional[int], progress: bool,
               node: Optional[NodeConfig] = None) -> ReplayResult:
    """Feed every scan to the aligner and write the result bag (atomically): what align_node publishes with
    ``node``'s parameters (pipeline/odometry_output.py: the same numbers), plus the ground truth and /tf_static
    of the input copied unchanged (same topics, types, header stamps and bag times), in bag-time order."""
    node = node or NodeConfig()
    base = BaseFrame(pose_from_xyz_rpy(node.base_to_sensor))
    inflation = aligner.config.health.covariance_inflation
    copies = copied_topics(reader, node)
    pending = list(heapq.merge(*([(ns, k, topic, typ, msg) for k, (ns, typ, msg) in enumerate(reader.messages(topic))]
                                 for topic in copies)))
    pending.reverse()  # popped from the end, earliest first
    total = reader.info.n_clouds if limit is None else min(limit, reader.info.n_clouds)
    result = ReplayResult()
    last_stamp_ns: Optional[int] = None
    start = time.perf_counter()
    with BagWriter(out_bag, overwrite=True) as bag, tqdm(total=total, unit="scan", disable=not progress,
                                                          desc="replay") as bar:

        def copy_until(stamp_ns: Optional[int]) -> None:
            while pending and (stamp_ns is None or pending[-1][0] <= stamp_ns):
                bag_ns, _, topic, msgtype, msg = pending.pop()
                bag.write_message(topic, msgtype, msg, bag_ns)

        for i, frame in enumerate(reader.clouds(limit)):
            try:
                step = aligner.process(frame.points, frame.stamp_ns, frame.times)
            except ValueError as err:  # ScanRejected (too few points, ...) or a cloud the core refuses
                result.rejected.append({"index": i, "stamp_ns": frame.stamp_ns, "reason": str(err)})
                bar.update()
                continue
            # As align_node._process/_publish: dt since the previous processed scan, then the shared numbers.
            dt_s = None if last_stamp_ns is None else (step.stamp_ns - last_stamp_ns) * 1e-9
            last_stamp_ns = step.stamp_ns
            out = odometry_output(step, base, dt_s, node, inflation)
            copy_until(step.stamp_ns)
            bag.write_pose(POSE_TOPIC, out.T_odom_base, node.odom_frame, step.stamp_ns)
            bag.write_odometry(ODOM_TOPIC, out.T_odom_base, out.pose_covariance, node.odom_frame, node.base_frame,
                               step.stamp_ns, linear=out.linear, angular=out.angular,
                               twist_covariance=out.twist_covariance)
            if node.publish_aligned_cloud:
                T_odom_sensor = out.T_odom_base @ base.T_base_sensor
                aligned = frame.points @ T_odom_sensor[:3, :3].T + T_odom_sensor[:3, 3]
                if node.aligned_cloud_voxel > 0:
                    from cemnet_ros.pipeline.preprocess import voxel_downsample

                    aligned = voxel_downsample(aligned, node.aligned_cloud_voxel)
                bag.write_cloud(CLOUD_TOPIC, aligned, node.odom_frame, step.stamp_ns)
            if node.publish_tf:
                parent, child, T = tf_parent_child(node, out.T_odom_base)
                bag.write_transform(TF_TOPIC, T, parent, child, step.stamp_ns)
            result.stamps_ns.append(step.stamp_ns)
            result.poses.append(out.T_odom_base)
            result.steps.append({"index": i, "stamp_ns": step.stamp_ns, "fitness": step.fitness,
                                 "accepted": step.accepted, "reason": step.reason, "latency_s": step.latency_s,
                                 "n_points": step.n_points, "first": step.relative is None,
                                 "recovered": step.recovered, "recovery_reason": step.recovery_reason,
                                 "degenerate": step.degenerate, "signals": step.signals,
                                 "twist_known": out.twist_known,
                                 "linear_m_s": out.linear.tolist(), "angular_rad_s": out.angular.tolist()})
            bar.update()
        copy_until(None)
    result.wall_s = time.perf_counter() - start
    return result


def evaluate(result: ReplayResult, gt_stamps: np.ndarray, gt_poses: np.ndarray) -> Optional[dict]:
    """ATE/RPE of the estimate against the ground truth at matching stamps (None without ground truth)."""
    if len(gt_stamps) == 0 or not result.poses:
        return None
    period = np.median(np.diff(gt_stamps)) if len(gt_stamps) > 1 else 1e8
    match = associate(result.stamps_ns, gt_stamps, max_dt_ns=int(max(period * 0.25, 1e6)))
    pairs = [(k, j) for k, j in enumerate(match) if j is not None]
    if len(pairs) < 1:
        return {"matched": 0, "error": "no scan stamp matches a ground-truth stamp"}
    est = np.stack([result.poses[k] for k, _ in pairs])
    gt = np.stack([gt_poses[j] for _, j in pairs])
    ate = absolute_trajectory_error(est, gt)
    rpe = relative_pose_errors(est, gt)
    per_pair = [{"pair": f"{result.steps[pairs[p][0]]['index']}->{result.steps[pairs[p + 1][0]]['index']}",
                 "trans_m": float(rpe.trans_errors[p]), "rot_deg": float(rpe.rot_errors_deg[p]),
                 "fitness": result.steps[pairs[p + 1][0]]["fitness"],
                 "accepted": result.steps[pairs[p + 1][0]]["accepted"]}
                for p in range(len(pairs) - 1)]
    return {"matched": len(pairs), "ate": {"rmse_m": ate.rmse, "mean_m": ate.mean, "median_m": ate.median,
                                           "max_m": ate.max},
            "rpe": rpe.stats(), "per_pair": per_pair, "_aligned": ate.alignment, "_est": est, "_gt": gt,
            "_rpe": rpe}


def speed(result: ReplayResult) -> dict:
    lat = np.array([s["latency_s"] for s in result.steps], dtype=np.float64)
    # The first scan only sets the reference (no registration): keep it out of the latency figures.
    reg = np.array([s["latency_s"] for s in result.steps if not s["first"]], dtype=np.float64)
    busy = float(lat.sum())
    return {"latency_p50_s": float(np.percentile(reg, 50)) if reg.size else float("nan"),
            "latency_p95_s": float(np.percentile(reg, 95)) if reg.size else float("nan"),
            "latency_max_s": float(reg.max()) if reg.size else float("nan"),
            "throughput_scans_per_s": len(lat) / busy if busy > 0 else float("nan"),
            "wall_s": result.wall_s}


def format_report(bag: str, summary: dict, max_pairs: int = 20, worst: int = 10) -> str:
    lines = [f"bag: {bag}  ({summary['cloud_topic']}, {summary['scans']} scans, "
             f"scale {summary['scale_m_per_unit']:.3f} m/unit)"]
    acc = summary.get("accuracy")
    if acc and "ate" in acc:
        ate, rpe = acc["ate"], acc["rpe"]
        lines.append(f"ATE RMSE: {ate['rmse_m'] * 100:.2f} cm (max {ate['max_m'] * 100:.2f} cm, "
                     f"{acc['matched']} poses matched to ground truth)")
        lines.append(f"RPE translation: mean {rpe['trans_mean_m'] * 100:.2f} cm, "
                     f"median {rpe['trans_median_m'] * 100:.2f} cm, max {rpe['trans_max_m'] * 100:.2f} cm")
        lines.append(f"RPE rotation:    mean {rpe['rot_mean_deg']:.3f} deg, median {rpe['rot_median_deg']:.3f} deg, "
                     f"max {rpe['rot_max_deg']:.3f} deg")
        pairs = acc["per_pair"]
        shown = pairs if len(pairs) <= max_pairs else sorted(pairs, key=lambda p: -p["trans_m"])[:worst]
        lines.append("per-pair errors" + ("" if len(pairs) <= max_pairs else f" ({worst} worst of {len(pairs)})")
                     + ": pair  trans[cm]  rot[deg]  fitness")
        lines += [f"  {p['pair']:>7}  {p['trans_m'] * 100:8.2f}  {p['rot_deg']:8.3f}  {p['fitness']:.3f}"
                  + ("" if p["accepted"] else "  FLAGGED") for p in shown]
    elif acc:
        lines.append(f"ground truth present but unusable: {acc['error']}")
    else:
        lines.append("no ground truth in the bag: speed only")
    sp = summary["speed"]
    lines.append(f"latency p50 {sp['latency_p50_s'] * 1e3:.0f} ms, p95 {sp['latency_p95_s'] * 1e3:.0f} ms; "
                 f"throughput {sp['throughput_scans_per_s']:.2f} scans/s (wall {sp['wall_s']:.1f} s)")
    lines.append(f"rejected scans: {len(summary['rejected'])}; flagged steps: {len(summary['flagged'])}")
    lines += [f"  scan {r['index']}: {r['reason']}" for r in summary["rejected"] + summary["flagged"]]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------- CLI
def parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="cemnet-replay", description=__doc__.splitlines()[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bag", type=Path, help="rosbag2 directory or .mcap/.db3 file")
    p.add_argument("--out", type=Path, default=None, help="output directory (default: results/replay/<bag name>)")
    p.add_argument("--topic", default=None, help="PointCloud2 topic (default: the bag's only PointCloud2 topic)")
    p.add_argument("--gt-topic", default=None, help="ground-truth PoseStamped/Odometry topic (default: "
                                                    "/ground_truth when present)")
    p.add_argument("--config", type=Path, default=None, help="parameter YAML (e.g. config/align_node.yaml); "
                                                             "the options below override it")
    p.add_argument("--limit", type=int, default=None, help="process only the first N scans")
    p.add_argument("--no-plot", action="store_true", help="skip the PNG")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_arguments(p, NODE, "align_node's output parameters (frames, extrinsic, covariances, /tf, aligned cloud; "
                           "docs/node.md; they override --config)")
    add_arguments(p, PIPELINE, "pipeline parameters (docs/node.md; they override --config)")
    args = p.parse_args(argv)
    if args.limit is not None and args.limit < 1:
        p.error("--limit must be >= 1")
    return args


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = parse_args(argv)
    try:
        params = {**load_params(args.config), **parsed_overrides(args, PIPELINE)}
        config = build(AlignerConfig(), params, exclude=DERIVED)
        node = build(NodeConfig(), {**load_node_params(args.config), **parsed_overrides(args, NODE)})
    except (OSError, ValueError, TypeError, yaml.YAMLError) as err:
        print(f"cemnet-replay: bad configuration: {err}", file=sys.stderr)
        return 2
    out = args.out or Path("results") / "replay" / args.bag.name.split(".")[0]
    try:
        reader = BagReader(args.bag, topic=args.topic, gt_topic=args.gt_topic)
    except BagError as err:
        print(f"cemnet-replay: {err}", file=sys.stderr)
        return 2
    from cemnet_ros.pipeline.aligner import ScanAligner

    out.mkdir(parents=True, exist_ok=True)
    with reader:
        try:
            copies = copied_topics(reader, node)
            gt_stamps, gt_poses, gt_frame = reader.ground_truth()
            aligner = ScanAligner(config)
            result = run_replay(reader, aligner, out / "replay.mcap", args.limit, progress=not args.quiet, node=node)
        except BagError as err:
            print(f"cemnet-replay: {err}", file=sys.stderr)
            return 2
        info = reader.info
    if not result.poses:
        print(f"cemnet-replay: no scan could be processed ({len(result.rejected)} rejected)", file=sys.stderr)
        return 1
    acc = evaluate(result, gt_stamps, gt_poses)
    files = {"bag": str(out / "replay.mcap"), "tum": str(write_tum(out / "trajectory_tum.txt",
                                                                  result.stamps_ns, result.poses))}
    if len(gt_stamps):
        files["ground_truth_tum"] = str(write_tum(out / "ground_truth_tum.txt", gt_stamps, gt_poses))
    if not args.no_plot:
        from cemnet_ros.replay.plot import save_replay_plot

        if acc and "ate" in acc:
            est = np.einsum("ij,njk->nik", acc["_aligned"], acc["_est"])
            save_replay_plot(out / "replay.png", est, acc["_gt"], acc["_rpe"], title=args.bag.name)
        else:
            save_replay_plot(out / "replay.png", np.stack(result.poses), title=args.bag.name)
        files["plot"] = str(out / "replay.png")
    summary = {
        "bag": str(args.bag), "cloud_topic": info.cloud_topic, "gt_topic": info.gt_topic, "gt_frame": gt_frame,
        "frames": {"odom_frame": node.odom_frame, "base_frame": node.base_frame,
                   "base_to_sensor": list(node.base_to_sensor)},
        "replay_topics": {**output_topics(node), **{t: info.topics[t] for t in copies}},
        "scans": len(result.steps), "scale_m_per_unit": float(aligner.scale or float("nan")),
        "accuracy": None if acc is None else {k: v for k, v in acc.items() if not k.startswith("_")},
        "speed": speed(result), "rejected": result.rejected,
        "flagged": [{"index": s["index"], "reason": s["reason"]} for s in result.steps
                    if not s["accepted"] or s["reason"]],
        "steps": result.steps, "config": asdict(config), "node_config": {k: getattr(node, k) for k in NODE},
        "outputs": files,
    }
    files["summary"] = str(out / "summary.json")
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2, default=float) + "\n")
    print(format_report(str(args.bag), summary))
    print(f"outputs: {out}/  (replay.mcap: {', '.join(summary['replay_topics'])})")
    if info.gt_topic is not None:
        print(f"score it with evo: evo_ape bag2 {out / 'replay.mcap'} {info.gt_topic} {ODOM_TOPIC} -a")
    return 0


if __name__ == "__main__":
    sys.exit(main())
