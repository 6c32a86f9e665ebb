"""One answer: a start polished against the map and what it says for itself, measured once (step 4 of the recipe
in :mod:`..aligner`).

- **fitness**: the share of the scan's polish points with a map point within ``polish.inlier_distance`` frame
  voxels and within ``polish.inlier_residual`` of its plane: how much of the scan lies on the map's surfaces;
- **coverage**: the share with a map point within ``health.coverage_distance`` frame voxels at all: where the map
  has surfaces. A wrong basin in a regular building (a turn of 90 deg, a shift by a room) often fits the walls
  as well as the truth but leaves part of the scan in empty space;
- **consistency**: fitness less the share off the map, the order answers rank in (:mod:`.evidence`);
- **conditioning**: the eigen-decomposition of the polish's normalised Hessian (a corridor or an open field
  leaves a direction unconstrained); with the residual variance it gives the covariance;
- **explained**: the polish converged within its reach of the prediction (the prediction was in this basin).

Answers closer than the precision the node vouches for (``DISTINCT_M``, ``DISTINCT_RAD``: metres and radians,
whatever the scene's size or the auto scale) are one answer.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.covariance import Conditioning
from cemnet_ros.pipeline.steps.frame import Frame
from cemnet_ros.pipeline.steps.health import Signals, disagreement
from cemnet_ros.pipeline.steps.polish import Polisher
from cemnet_ros.pipeline.steps.refine import PolishResult

DISTINCT_M, DISTINCT_RAD = 0.1, np.radians(1.0)  # answers farther apart than what the node vouches for differ
MIN_POLISH_PAIRS = 10  # a polish with fewer point-to-plane pairs constrains nothing


class Origin(str, enum.Enum):
    """The kind of start an answer was polished from."""

    PREDICTION = "prediction"  # the motion model's pose
    CEM = "cem"  # the tracking CEM's answer around the prediction
    LAST_POSE = "last pose"  # the sensor did not move as it did (a stop, a jerk, a turn reversed)
    SEARCH = "search"  # a hypothesis of the global search
    TURN = "turn"  # the last pose turned by a few tens of degrees (the recovery's grid of turns)
    NEIGHBOUR = "neighbour"  # an answer turned by the fine polish's reach either way (its basin checked)
    LAST_SCAN = "last scan"  # an answer polished wide from itself: where the map's last scan alone leads from it


def distinct(T_a: np.ndarray, T_b: np.ndarray) -> bool:
    """Two answers that differ by more than the precision the node vouches for."""
    metres, radians = disagreement(T_a, T_b)
    return metres > DISTINCT_M or radians > DISTINCT_RAD


@dataclass(frozen=True)
class Answer:
    """A polished start and its own evidence (see the module)."""

    T_odom_sensor: np.ndarray
    origin: Origin
    signals: Signals  # fitness, coverage, conditioning ratio, how far the polish moved the start, CEM spread
    conditioning: Conditioning
    residual_variance: float  # m^2, the polish's at its end
    n_pairs: int  # the polish's point-to-plane pairs at its end
    explained: bool  # the polish converged within its reach of the prediction

    @property
    def fitness(self) -> float:
        return self.signals.fitness

    @property
    def coverage(self) -> float:
        return self.signals.coverage

    @property
    def consistency(self) -> float:
        return self.signals.consistency

    @property
    def constrained(self) -> bool:
        """Its polish had enough pairs to constrain a pose at all."""
        return self.n_pairs >= MIN_POLISH_PAIRS


def fit_and_cover(config: AlignerConfig, frame: Frame, target_map: VoxelMap, T_odom_sensor: np.ndarray
                  ) -> tuple[float, float]:
    """The fitness and coverage of ``frame`` placed at ``T_odom_sensor`` against ``target_map``, as every answer
    is measured."""
    return target_map.overlap(frame.polish, T_odom_sensor, config.polish.inlier_distance * frame.polish_voxel,
                              config.polish.inlier_residual, config.health.coverage_distance * frame.polish_voxel)


def measured(polisher: Polisher, T_start: np.ndarray, polish: PolishResult, origin: Origin,
             T_predicted: np.ndarray, spread_m: float = 0.0) -> Answer:
    """The answer ``polish`` gives from ``T_start`` (``spread_m``: the CEM's final spread where the CEM gave the
    start, a recorded signal)."""
    frame = polisher.frame
    T_final = polish.T_target_source
    fitness, coverage = fit_and_cover(polisher.config, frame, polisher.map, T_final)
    conditioning = Conditioning.of(polish.hessian, frame.length)
    moved_m, moved_rad = disagreement(T_start, T_final)
    signals = Signals(fitness, moved_m, moved_rad, conditioning.ratio, spread_m, coverage)
    return Answer(T_final, origin, signals, conditioning, polish.residual_variance, polish.n_pairs,
                  polisher.within_reach(polish, T_predicted))
