"""cemnet-replay: run the scan pipeline (ScanAligner, sequential mode) over a rosbag2 bag offline, no DDS.

Reads PointCloud2 scans (and ``/ground_truth`` PoseStamped/Odometry when present), aligns them at full speed and
writes into ``--out``: ``replay.mcap`` with what align_node (default node name) would have published:
/align_node/odometry (odom_frame -> base_frame, twist, covariances), /align_node/pose, /tf and, with
publish_aligned_cloud, /align_node/aligned_cloud; plus the input's ground truth and /tf_static, copied unchanged,
so that ``evo_ape bag2 replay.mcap /ground_truth /align_node/odometry -a`` scores it on its own. Also
``trajectory_tum.txt`` (+ ``ground_truth_tum.txt``), ``summary.json`` and ``replay.png``. Prints ATE/RPE of the
base frame against the ground truth, per-pair errors, latency and throughput. A cloud message that gives no
pose (truncated, wrong layout, undecodable, too few points, rejected by the aligner, ...) is skipped with a
warning (the first of each kind) and counted: a line ``skipped 1 of 120 messages: 1 truncated (t=12.300 s)``
and summary.json's ``skipped`` / ``skipped_count`` list them; the other scans are processed as without it.

    cemnet-replay bags/kitti_00_6scans.mcap --out results/replay/kitti
    cemnet-replay bags/synthetic_lidar.mcap --registration.cem_preset refine --limit 8
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np
import yaml

from cemnet_ros.io.atomic import write_report
from cemnet_ros.io.optional import MissingOptional
from cemnet_ros.io.report import Report
from cemnet_ros.io.trajectory_files import write_tum
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.replay.bag_io import BagError, BagReader
from cemnet_ros.replay.realtime import live_summary
from cemnet_ros.replay.report import evaluate, format_report, skipped_line, speed
from cemnet_ros.replay.runner import ODOM_TOPIC, ReplayResult, copied_topics, output_topics, run_replay
from cemnet_ros.ros.node_config import NodeConfig
from cemnet_ros.schema import add_arguments, build, flatten_mapping, parameters, parsed_overrides
from cemnet_ros.tools.cli_errors import reported_errors

PROG = "cemnet-replay"

PIPELINE = parameters(AlignerConfig())  # the flags and params-file names it accepts
# The node's own parameters that shape its outputs offline (frames, extrinsic, covariances, TF, cloud); the
# others (topics, QoS, queue) mean nothing without DDS. Flags as for the pipeline; --config gives them too.
NODE = {name: p for name, p in parameters(NodeConfig()).items() if name in (
    "odom_frame", "base_frame", "base_to_sensor", "covariance_mode", "fixed_position_variance",
    "fixed_orientation_variance", "publish_tf", "invert_tf", "publish_aligned_cloud", "aligned_cloud_voxel",
    "queue_size", "behind_effort", "scan_budget")}  # the last three: the live node's, with --realtime


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


# ---------------------------------------------------------------------------------------------- CLI
def parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__.splitlines()[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bag", type=Path, help="rosbag2 directory or .mcap/.db3 file")
    p.add_argument("--out", type=Path, default=None, help="output directory (default: results/replay/<bag name>)")
    p.add_argument("--topic", default=None, help="PointCloud2 topic (default: the bag's only PointCloud2 topic)")
    p.add_argument("--gt-topic", default=None, help="ground-truth PoseStamped/Odometry topic (default: "
                                                    "/ground_truth when present)")
    p.add_argument("--config", type=Path, default=None, help="parameter YAML (e.g. config/align_node.yaml); "
                                                             "the options below override it")
    p.add_argument("--limit", type=int, default=None, help="process only the first N scans")
    p.add_argument("--realtime", type=float, default=None, metavar="RATE",
                   help="play the scans into the node's queue at RATE x the bag's timing, as a live node would "
                        "receive them (drops, latency, behind_effort, scan_budget); default: every scan, its "
                        "whole plan, full effort")
    p.add_argument("--no-plot", action="store_true", help="skip the PNG")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_arguments(p, NODE, "align_node's output parameters (frames, extrinsic, covariances, /tf, aligned cloud; "
                           "docs/node.md; they override --config)")
    add_arguments(p, PIPELINE, "pipeline parameters (docs/node.md; they override --config)")
    args = p.parse_args(argv)
    if args.limit is not None and args.limit < 1:
        p.error("--limit must be >= 1")
    if args.realtime is not None and not args.realtime > 0:
        p.error("--realtime must be > 0")
    return args


@dataclass(frozen=True)
class ReplayConfig:
    """One replay: the bag, where its outputs go, the topics (None: found in the bag) and the configurations."""

    bag: Path
    out: Path
    pipeline: AlignerConfig
    node: NodeConfig
    topic: Optional[str] = None
    gt_topic: Optional[str] = None
    limit: Optional[int] = None
    plot: bool = True
    progress: bool = True
    realtime: Optional[float] = None  # RATE: played into the node's queue at RATE x the bag's timing


@dataclass
class ReplayReport(Report):
    """summary.json's content (None: no scan gave a pose, ``skipped`` says why) and where the outputs are."""

    bag: str
    out: Path
    summary: Optional[dict[str, Any]]
    skipped: str = ""

    def to_markdown(self) -> str:
        if self.summary is None:
            return f"no scan could be processed ({self.skipped})"
        lines = [format_report(self.bag, self.summary),
                 f"outputs: {self.out}/  (replay.mcap: {', '.join(self.summary['replay_topics'])})"]
        if self.summary["gt_topic"] is not None:
            lines.append(f"score it with evo: evo_ape bag2 {self.out / 'replay.mcap'} {self.summary['gt_topic']} "
                         f"{ODOM_TOPIC} -a")
        return "\n".join(lines)

    def to_json(self) -> str:
        return json.dumps(self.summary, indent=2, default=float) + "\n"


def configure(args: argparse.Namespace) -> ReplayConfig:
    """The replay's configuration: --config, then the flags. A bad value is a ValueError "bad configuration: ..."."""
    try:
        params = {**load_params(args.config), **parsed_overrides(args, PIPELINE)}
        pipeline = build(AlignerConfig(), params)
        node = build(NodeConfig(), {**load_node_params(args.config), **parsed_overrides(args, NODE)})
    except (OSError, ValueError, TypeError, yaml.YAMLError) as err:
        raise ValueError(f"bad configuration: {err}") from err
    out = args.out or Path("results") / "replay" / args.bag.name.split(".")[0]
    return ReplayConfig(args.bag, out, pipeline, node, args.topic, args.gt_topic, args.limit, not args.no_plot,
                        not args.quiet, args.realtime)


def write_outputs(config: ReplayConfig, result: ReplayResult, acc: Optional[dict],
                  gt: tuple[np.ndarray, np.ndarray]) -> dict[str, str]:
    """trajectory_tum.txt, ground_truth_tum.txt (with ground truth) and replay.png (with ``plot``)."""
    out = config.out
    files = {"bag": str(out / "replay.mcap"), "tum": str(write_tum(out / "trajectory_tum.txt",
                                                                  result.stamps_ns, result.poses))}
    if len(gt[0]):
        files["ground_truth_tum"] = str(write_tum(out / "ground_truth_tum.txt", *gt))
    if config.plot:
        try:
            files["plot"] = str(_plot(out / "replay.png", config, result, acc))
        except MissingOptional as exc:  # the figure only: the trajectory, report and bag are written
            print(f"{PROG}: warning: replay.png not written: {exc} (--no-plot skips it)", file=sys.stderr)
    return files


def _plot(path: Path, config: ReplayConfig, result: ReplayResult, acc: Optional[dict]) -> Path:
    """replay.png: the estimate aligned onto the ground truth when there is one; MissingOptional without matplotlib."""
    from cemnet_ros.replay.plot import save_replay_plot

    if acc and "ate" in acc:
        est = np.einsum("ij,njk->nik", acc["_aligned"], acc["_est"])
        return save_replay_plot(path, est, acc["_gt"], acc["_rpe"], title=config.bag.name)
    return save_replay_plot(path, np.stack(result.poses), title=config.bag.name)


def build_summary(config: ReplayConfig, facts: dict[str, Any], result: ReplayResult, acc: Optional[dict],
                  files: dict[str, str]) -> dict:
    """summary.json's content; ``facts``: info, gt_frame, copies and scale of the replay."""
    info, node = facts["info"], config.node
    return {
        "bag": str(config.bag), "cloud_topic": info.cloud_topic, "gt_topic": info.gt_topic,
        "gt_frame": facts["gt_frame"],
        "frames": {"odom_frame": node.odom_frame, "base_frame": node.base_frame,
                   "base_to_sensor": list(node.base_to_sensor)},
        "replay_topics": {**output_topics(node), **{t: info.topics[t] for t in facts["copies"]}},
        "messages": result.n_messages, "scans": len(result.steps), "scale_m_per_unit": facts["scale"],
        "accuracy": None if acc is None else {k: v for k, v in acc.items() if not k.startswith("_")},
        "speed": speed(result), "skipped_count": len(result.skipped),
        "skipped": [s.as_dict() for s in result.skipped], "rejected": result.rejected,
        "flagged": [{"index": s["index"], "reason": s["reason"]} for s in result.steps
                    if not s["accepted"] or s["reason"]],
        "live": None if result.live is None else {"rate": config.realtime, "queue_size": node.queue_size,
                                                  "behind_effort": node.behind_effort,
                                                  "scan_budget": node.scan_budget, **live_summary(result.live)},
        "steps": result.steps, "config": asdict(config.pipeline), "node_config": {k: getattr(node, k) for k in NODE},
        "outputs": files,
    }


def replay(config: ReplayConfig) -> tuple[ReplayResult, dict[str, Any], tuple[np.ndarray, np.ndarray]]:
    """Run the bag through a fresh aligner into out/replay.mcap: (result, run facts, ground truth). BagError."""
    from cemnet_ros.pipeline.aligner import ScanAligner

    with BagReader(config.bag, topic=config.topic, gt_topic=config.gt_topic) as reader:
        copies = copied_topics(reader, config.node)
        gt_stamps, gt_poses, gt_frame = reader.ground_truth()
        aligner = ScanAligner(config.pipeline)
        config.out.mkdir(parents=True, exist_ok=True)
        result = run_replay(reader, aligner, config.out / "replay.mcap", config.limit, progress=config.progress,
                            node=config.node, realtime=config.realtime)
        facts = {"info": reader.info, "gt_frame": gt_frame, "copies": copies,
                 "scale": float(aligner.scale or float("nan"))}
    return result, facts, (gt_stamps, gt_poses)


def run(config: ReplayConfig) -> ReplayReport:
    """Replay the bag, score it against its ground truth and write the trajectory files and the plot."""
    result, facts, gt = replay(config)
    if not result.poses:
        return ReplayReport(str(config.bag), config.out, None,
                            skipped_line([s.as_dict() for s in result.skipped], result.n_messages))
    acc = evaluate(result, *gt)
    files = write_outputs(config, result, acc, gt)
    files["summary"] = str(config.out / "summary.json")
    return ReplayReport(str(config.bag), config.out, build_summary(config, facts, result, acc, files))


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = parse_args(argv)
    with reported_errors(PROG, BagError) as outcome:
        report = run(configure(args))
        if report.summary is None:
            print(f"{PROG}: {report.to_markdown()}", file=sys.stderr)
            return 1
        write_report(report.out / "summary.json", report.to_json())
        print(report.to_markdown())
    return outcome.code


if __name__ == "__main__":
    sys.exit(main())
