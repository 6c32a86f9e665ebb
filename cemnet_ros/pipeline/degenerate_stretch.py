"""A degenerate stretch: the scans the map took in while their view left a direction weakly constrained.

A degenerate step publishes its answer as registered and the map takes it in (decision rule 8): along its weak
direction the answer lies where the scan's weak pull left it, a few centimetres from the truth, and a run of such
steps can carry the map's newest part along that direction. The next step the decision accepts stands on the map
as it now is, drifted or not; it can be tied to the last vouched pose only through the part of the map the node
vouched for. So the stretch keeps the map as last vouched (a snapshot when the stretch's first scan goes in),
and the step that ends it is vouched only where at least ``health.min_vouched_share`` of its fit lies on that
map's surfaces. Otherwise its pose rests on the degenerate steps alone: it is flagged degenerate, and the map
restarts from it (a new anchor: the odometry stays continuous). On the corpus the steps that ended a stretch and
were right fitted 0.26-0.88 of their fit on the map as last vouched; the one wrong, 0.02 (docs/node.md).
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.answer import fit_and_cover
from cemnet_ros.pipeline.steps.frame import Frame


class DegenerateStretch:
    """The map as last vouched, while degenerate scans have joined the map since."""

    def __init__(self) -> None:
        self._map_vouched: Optional[VoxelMap] = None

    def entering(self, target_map: VoxelMap) -> None:
        """A degenerate scan is about to join ``target_map``: the first of a stretch keeps the map as it is."""
        if self._map_vouched is None:
            self._map_vouched = target_map.snapshot()

    def clear(self) -> None:
        """A vouched scan joined the map, or the map restarted: no stretch."""
        self._map_vouched = None

    def untied(self, config: AlignerConfig, frame: Frame, T_odom_sensor: np.ndarray, fitness: float) -> str:
        """Why an answer that fits the map by ``fitness`` cannot be tied to the last vouched pose ("": it can, or no
        stretch runs)."""
        if self._map_vouched is None or fitness <= 0.0:
            return ""
        vouched_fitness, _ = fit_and_cover(config, frame, self._map_vouched, T_odom_sensor)
        share, least = vouched_fitness / fitness, config.health.min_vouched_share
        if share >= least:
            return ""
        return (f"after degenerate steps: {share:.2f} of its fit lies on the map as last vouched (< {least:.2f}), "
                "its pose rests on the degenerate steps alone: the map restarts from this scan")
