"""``align_node``: CEMNet point cloud alignment as a ROS 2 odometry node.

The ROS layer converts, queues and publishes (:mod:`.alignment`); what it decides is plain code in
:mod:`cemnet_ros.pipeline`. The numba kernels are compiled before it subscribes when their cache is not complete
(:mod:`.kernels`: the first start after a build); then a background thread loads the engine, so that the
subscriptions exist at once and early scans wait in the queue. ``align_lifecycle_node``
(:mod:`.align_lifecycle_node`) is the managed variant.

Modes: ``sequential`` registers each ``input_topic`` scan against a local map (odometry of ``base_frame`` in
``odom_frame``); ``pair`` aligns each ``source_topic`` scan to the ``target_topic`` cloud nearest in stamp (or
the latest one, e.g. a latched map, when ``pair_tolerance`` is 0). Parameters: :mod:`.node_config`; see
docs/node.md.
"""
from __future__ import annotations

import threading
from typing import Any, Optional

from rclpy.node import Node

from cemnet_ros.ros.alignment import Alignment
from cemnet_ros.ros.kernels import counted_load, prepare_kernels
from cemnet_ros.ros.node_config import NodeConfig
from cemnet_ros.ros.parameters import declare_and_read
from cemnet_ros.ros.process import run
from cemnet_ros.runtime.aligner_session import AlignerSession
from cemnet_ros.runtime.extrinsic import BaseFrame, pose_from_xyz_rpy
from cemnet_ros.runtime.extrinsic_hold import ExtrinsicHold
from cemnet_ros.schema import values as config_values


class AlignNode(Node):
    """Subscribes PointCloud2; publishes odometry, pose, TF, optional aligned cloud and map, diagnostics.

    Raises ConfigError for a parameter it cannot start with; :attr:`fatal_error` is set when the engine
    cannot load (``main`` then exits 2).
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("align_node", **kwargs)
        cfg, pipeline_config = declare_and_read(self)
        log_parameters(self, cfg, pipeline_config)
        prepare_kernels(self.get_logger())  # compiled now when the cache lacks them: no scan waits for it
        self._session, extrinsic = new_session(cfg, pipeline_config)
        self.alignment = Alignment(self, cfg, self._session, extrinsic)
        threading.Thread(target=self._load, name="cemnet_load", daemon=True).start()
        self.get_logger().info(f"align_node subscribed ({cfg.mode} mode); loading the engine")

    @property
    def fatal_error(self) -> Optional[str]:
        """Why the engine did not load (None: it loaded or is loading)."""
        return self._session.fatal_error

    def _load(self) -> None:
        """Import torch, load the weights and the kernels (seconds, a thread): scans queue meanwhile."""
        seconds, kernels = counted_load(self._session)
        if seconds is None:
            self.get_logger().error(self._session.fatal_error)
            return
        self.alignment.engine_ready(seconds, kernels)

    def destroy_node(self) -> None:
        self._session.close()  # a worker waiting for the engine gives up
        self.alignment.destroy()
        super().destroy_node()


def new_session(cfg: NodeConfig, pipeline_config: Any) -> tuple[AlignerSession, ExtrinsicHold]:
    """An aligner session (not loaded yet) and the extrinsic its outputs use, base_to_sensor until TF gives one."""
    extrinsic = ExtrinsicHold(pose_from_xyz_rpy(cfg.base_to_sensor))
    return AlignerSession(pipeline_config, cfg, BaseFrame(extrinsic.T_base_sensor)), extrinsic


def log_parameters(node: Node, cfg: NodeConfig, pipeline_config: Any) -> None:
    node.get_logger().info("parameters in force: " + ", ".join(
        f"{k}={v}" for k, v in {**config_values(cfg), **config_values(pipeline_config)}.items()))


def main(args: Optional[list] = None) -> None:
    """Spin until SIGINT; a fatal configuration or engine error is one line on stderr and exit status 2."""
    run(AlignNode, "align_node", args)


if __name__ == "__main__":
    main()
