"""The node's parameters: its own (topics, frames, QoS, outputs) and the pipeline's, from one schema.

No rclpy here: the params file, the docs table and the tests read the same schema without a ROS install.
Two tiers (:func:`cemnet_ros.schema.param`'s ``user``): about 15 user parameters, the shipped params file's and
the docs' first table, and the expert rest, documented apart. Regenerate the shipped params file with
``python -m cemnet_ros.ros.node_config > config/align_node.yaml`` and the docs' tables with ``--markdown``.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Mapping

from cemnet_ros.pipeline.cem_presets import CEM_PRESETS, cem_preset
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.schema import Parameter, build, param, parameters, params_yaml

MODES = ("sequential", "pair")
RELIABILITIES = ("best_effort", "reliable")
COVARIANCE_MODES = ("registration", "fixed")


@dataclass
class NodeConfig:
    """ROS wiring of ``align_node``; the pipeline's sections (:class:`AlignerConfig`) sit beside it. The node reads
    the ``dynamic`` ones (the save paths) again when it uses them: their values here are those at start-up."""

    mode: str = param("sequential", "'sequential' (scan-to-map odometry) or 'pair' (source to target topic)",
                      choices=MODES, user=True)
    input_topic: str = param("points", "PointCloud2 input of sequential mode", user=True)
    source_topic: str = param("source", "PointCloud2 source of pair mode", user=True)
    target_topic: str = param("target", "PointCloud2 target of pair mode (subscribed TRANSIENT_LOCAL by default)",
                              user=True)
    target_transient_local: bool = param(True, "pair mode: subscribe the target RELIABLE + TRANSIENT_LOCAL (a "
                                         "latched map); false = same QoS as the source")
    pair_tolerance: float = param(0.05, "pair mode: max |stamp difference| in s; 0 = always use the latest target",
                                  low=0.0, high=3600.0)
    odom_frame: str = param("odom", "parent frame of the pose, odometry and TF (REP-105)", user=True)
    base_frame: str = param("base_link", "the robot's frame: child of odometry and TF, whose motion is published",
                            user=True)
    base_to_sensor: tuple = param((0.0,) * 6, "pose of the sensor in base_frame (x y z m, roll pitch yaw rad), "
                                  "used when TF does not give it (no tf2_ros, or no transform)", user=True)
    publish_tf: bool = param(True, "publish odom -> base_frame on /tf", user=True)
    invert_tf: bool = param(False, "publish base_frame -> odom instead (when another node owns odom -> base)",
                            user=True)
    qos_reliability: str = param("best_effort", "input QoS reliability ('best_effort' = sensor data)",
                                 choices=RELIABILITIES, user=True)
    qos_depth: int = param(5, "input QoS history depth", low=1, high=1000)
    queue_size: int = param(8, "scans waiting for the worker; when full the oldest is dropped (a global search "
                            "holds the worker 0.3-1.5 s: docs/live.md)", low=1, high=100)
    scan_budget: float = param(2.0, "input periods (the median interval between arriving scans) a scan may hold the "
                               "worker: the global search and the turns run in it only where what they cost here "
                               "fits, else its answer is published flagged 'unconfirmed'; 0 = no bound (as offline)",
                               low=0.0, user=True)
    behind_effort: float = param(0.5, "share of the polishes' and the global search's budgets a scan gets while "
                                 "newer scans wait (1 = the same as offline)", low=0.05, high=1.0)
    covariance_mode: str = param("registration", "'registration': per step, from the polish's Hessian "
                                 "(docs/covariance.md); 'fixed': the fixed variances below", choices=COVARIANCE_MODES)
    fixed_position_variance: float = param(2.5e-5, "covariance_mode fixed: x, y, z variance (m^2) per step (5 mm: "
                                           "measure your sensor's, docs/covariance.md)", low=1e-12)
    fixed_orientation_variance: float = param(5e-7, "covariance_mode fixed: roll, pitch, yaw variance (rad^2) per "
                                              "step (0.7 mrad: measure your sensor's, docs/covariance.md)", low=1e-12)
    publish_aligned_cloud: bool = param(False, "publish each scan in odom_frame on ~/aligned_cloud (all fields)")
    aligned_cloud_voxel: float = param(0.0, "voxel grid (m) of ~/aligned_cloud; 0 = full resolution", low=0.0)
    local_map_period: float = param(1.0, "seconds between ~/local_map publications; 0 = never", low=0.0)
    input_timeout: float = param(1.0, "diagnostics WARN when no scan came for this long (s), ERROR after 3x",
                                 low=0.01)
    trajectory_max_poses: int = param(1_000_000, "published poses kept for ~/save_trajectory and ~/path (115 bytes "
                                      "each; 1e6 = 28 h at 10 Hz); beyond it the oldest are dropped", low=1,
                                      high=100_000_000)
    save_directory: str = param("", "folder of the saved files whose path is relative; '' = $ROS_HOME/cemnet_ros "
                                "(~/.ros/cemnet_ros); created when missing", dynamic=True, user=True)
    save_map_path: str = param("cemnet_map_{time}.pcd", "~/save_map writes the local map (odom_frame) here: .pcd "
                               "(binary) or .ply; {time} = the local date and time", dynamic=True)
    save_trajectory_path: str = param("cemnet_trajectory_{time}.tum", "~/save_trajectory writes the published "
                                      "poses here: .tum or .txt (TUM), .kitti (KITTI), and their flags beside it "
                                      "(.flags.csv); {time} = the local date and time", dynamic=True)
    path_period: float = param(0.0, "seconds between ~/path (nav_msgs/Path of the published poses) publications "
                               "while someone subscribes; 0 = no ~/path", low=0.0)
    path_max_poses: int = param(10_000, "~/path holds the newest this many poses", low=1, high=1_000_000)


def node_parameters() -> dict[str, Parameter]:
    """Every ROS parameter of the node: its own, then the pipeline's (dotted), by name."""
    own = parameters(NodeConfig())
    pipeline = parameters(AlignerConfig())
    clash = set(own) & set(pipeline)
    if clash:
        raise TypeError(f"node and pipeline parameters share names: {sorted(clash)}")
    return {**own, **pipeline}


def configs_from_parameters(values: Mapping[str, Any]) -> tuple[NodeConfig, AlignerConfig]:
    """(NodeConfig, AlignerConfig) from parameter values by name; ValueError names a bad one."""
    own = set(parameters(NodeConfig()))
    node = build(NodeConfig(), {k: v for k, v in values.items() if k in own})
    pipeline = build(AlignerConfig(), {k: v for k, v in values.items() if k not in own})
    return node, pipeline


HEADER = """align_node's user parameters (ROS 2 params file, keyed /** to apply under any namespace or node name).
  ros2 launch cemnet_ros align_node.launch.py   (uses the installed copy of this file)
  ros2 run cemnet_ros align_node --ros-args \\
    --params-file $(ros2 pkg prefix cemnet_ros)/share/cemnet_ros/config/align_node.yaml
Read once at start-up, but save_directory ("settable at runtime": ros2 param set).
Every other parameter is an expert setting, at its default unless set: add it here (or -p name:=value) the same
way; docs/node.md ("Expert parameters") lists them all with their defaults and help.
Generated from the schema: python -m cemnet_ros.ros.node_config"""


def user_parameters() -> dict[str, Parameter]:
    """The user tier of :func:`node_parameters` (what a ROS user sets on a robot), by name."""
    return {name: p for name, p in node_parameters().items() if p.user}


def params_file_text() -> str:
    """The shipped params file: the user tier at its defaults (the expert tier stays at the schema's)."""
    return params_yaml(user_parameters(), HEADER)


def _table(params: Mapping[str, Parameter]) -> list[str]:
    rows = ["| name | default | meaning |", "| --- | --- | --- |"]
    for p in params.values():
        default = list(p.default) if p.kind is tuple else "''" if p.default == "" else p.default
        rows.append(f"| `{p.name}` | `{default}` | {p.describe().replace('|', '/')} |")
    return rows


def _presets_table() -> list[str]:
    rows = ["| preset | N | T | M | lattice spacing | for |", "| --- | --- | --- | --- | --- | --- |"]
    for name, preset in CEM_PRESETS.items():
        cem = cem_preset(name, 0)
        rows.append(f"| `{name}` | {cem.n_candidates} | {cem.n_iters} | {cem.n_fused_iters} | "
                    f"{cem.lattice_spacing} | {preset.purpose} |")
    return rows


def parameters_markdown() -> str:
    """The docs' two parameter tables, the user tier then the expert one by section, and the CEM presets
    (docs/node.md holds them between markers; a test compares)."""
    lines = ["### User parameters", "",
             "What a ROS user sets on a robot; `config/align_node.yaml` holds these alone, at their defaults.", "",
             *_table(user_parameters()), "", "### Expert parameters", "",
             "Every other parameter: declared and settable the same way (a params file, `-p name:=value`), at its "
             "default unless set. By section:"]
    sections = {f.name: f.metadata["help"] for f in fields(AlignerConfig)}
    own = parameters(NodeConfig())
    groups: dict[str, dict[str, Parameter]] = {}
    for name, p in node_parameters().items():
        if not p.user:
            group = "" if name in own else name.split(".")[0] if "." in name else "pipeline"
            groups.setdefault(group, {})[name] = p
    for prefix, group in groups.items():
        title = (f"`{prefix}.*`: {sections[prefix]}" if prefix in sections else "the pipeline's own" if prefix
                 else "the node's own (topics, QoS, outputs)")
        lines += ["", f"#### {title[0].upper()}{title[1:]}", "", *_table(group)]
    lines += ["", "### CEM presets", "",
              "`registration.cem_preset` and `recovery.search.refine_preset` name one of these (N candidates, T "
              "iterations, the first M fusing the after-ICP reward; lattice spacing in units of epsilon; the other "
              "fields at the paper's defaults, the seed the pipeline's `seed`):", "", *_presets_table()]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    import sys

    print(parameters_markdown() if "--markdown" in sys.argv else params_file_text(), end="")
