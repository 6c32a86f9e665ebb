"""The engine in metres: a frame's clouds and poses carried into the engine's units and its answers back.

The CEM and the global search work on the ModelNet unit sphere (epsilon = 0.1); a scan is in metres. Both the
tracking CEM and the global search see the scan through one :class:`EngineUnits`: scaled by the trajectory's
scale, centred on a point near the sensor (the search's yaw then turns about the sensor); :class:`MetricEngine`
is the one adapter that runs either.
"""
from __future__ import annotations

import dataclasses
from typing import Optional

import numpy as np
import torch

from cemnet_ros.core import Registrar, RegistrationConfig
from cemnet_ros.core.config import GlobalSearchConfig
from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.core.global_search import SearchPrior, global_search
from cemnet_ros.core.registration import NETWORK_MIN_POINTS
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.steps.frame import Frame
from cemnet_ros.pipeline.steps.preprocess import subsample, voxel_downsample

POLISH_FRACTION = 0.8  # hypotheses whose CEM fitness is this close to the best one's get polished


class EngineUnits:
    """Metres <-> the engine's units at ``frame``'s scale, centred on ``centre`` (3,) m."""

    def __init__(self, frame: Frame, centre: np.ndarray) -> None:
        self.to_units, self.from_units = frame.network_units(centre)
        self.scale = frame.scale

    def points(self, xyz_m: np.ndarray) -> np.ndarray:
        """Points (n, 3) in metres, in units."""
        return apply_transform(self.to_units, xyz_m)

    def pose(self, T_m: np.ndarray) -> np.ndarray:
        """A transform between two metric frames, as the engine sees it."""
        return self.to_units @ np.asarray(T_m, dtype=np.float64) @ self.from_units

    def pose_in_metres(self, T_units: np.ndarray) -> np.ndarray:
        """An engine's answer (4x4 in units), in metres (the bottom row made exact)."""
        T_m = self.from_units @ np.asarray(T_units, dtype=np.float64) @ self.to_units
        T_m[3] = (0.0, 0.0, 0.0, 1.0)
        return T_m

    def sigma(self, rotation_rad: float, translation_m: float) -> np.ndarray:
        """The engine's 6-D spread [Euler z, y, x (rad), t (units)] of these metric spreads."""
        return np.r_[np.full(3, rotation_rad), np.full(3, translation_m / self.scale)]


class MetricEngine:
    """The CEM and the global search on a frame in metres: one adapter for both (see the module).

    ``registrar``: the tracking CEM's engine; ``prior``: the registrar whose sampling network draws part of the
    search's scatter (None: a uniform scatter only).
    """

    def __init__(self, config: AlignerConfig, registrar: Registrar, prior: Optional[Registrar] = None) -> None:
        self.config, self.registrar, self.prior = config, registrar, prior

    def cem(self, frame: Frame, target_m: np.ndarray, T_centre: Optional[np.ndarray],
            sigma_metric: Optional[tuple[float, float]]) -> tuple[np.ndarray, float]:
        """The CEM of ``frame``'s sample onto the map points ``target_m`` (odom frame), centred on ``T_centre``
        (T_odom_sensor; None: the sampling network's mu0) with the spread ``sigma_metric`` (rad, m; None: the
        spread ``tracking.identity_sigma`` in the engine's own units); (T_odom_sensor, final spread m)."""
        units = EngineUnits(frame, target_m.mean(axis=0))
        clouds = units.points(frame.sampled), units.points(target_m)
        if T_centre is None:
            result = self.registrar.register(*clouds)
        else:
            sigma = (np.full(6, self.config.tracking.identity_sigma) if sigma_metric is None
                     else units.sigma(*sigma_metric))
            result = self.registrar.register(*clouds, prior_pose=units.pose(T_centre), prior_sigma=sigma)
        return units.pose_in_metres(result.transform), float(np.max(np.abs(result.sigma[3:]))) * frame.scale

    def search(self, frame: Frame, target_m: np.ndarray, map_voxel: float, T_guess: np.ndarray,
               effort: float) -> list[np.ndarray]:
        """The global search's hypotheses (T_odom_sensor) worth a polish: those whose CEM fitness comes within
        ``POLISH_FRACTION`` of the best one's. The scan is placed at the guess and the units are centred on the
        guessed sensor position, so that the search's yaw turns about the sensor and its translation disc is the
        sensor's displacement; ``map_voxel``: the map's voxel (the scan is thinned alike, :func:`search_source`)."""
        rec = self.config.recovery
        units = EngineUnits(frame, T_guess[:3, 3])
        seed = self.config.draw_seed
        source = units.points(apply_transform(T_guess, search_source(frame, map_voxel, rec.points, seed)))
        target = units.points(target_m)
        prior = self._network_prior(source, target)
        hypotheses = global_search(source, target, np.zeros(6), rec.radius / frame.scale,
                                   lean_search(self.config.global_search(), effort), seed=seed, prior=prior)
        best = hypotheses[0].fitness if hypotheses else 0.0
        return [units.pose_in_metres(h.T_target_source) @ T_guess for h in hypotheses
                if h.fitness >= POLISH_FRACTION * best]

    def _network_prior(self, source: np.ndarray, target: np.ndarray) -> Optional[SearchPrior]:
        """The network's raw mu0, sigma0 for the search's clouds in units (None: no network, or too few points)."""
        if self.prior is None or min(len(source), len(target)) < NETWORK_MIN_POINTS:
            return None
        clouds = (torch.as_tensor(cloud, dtype=torch.float32)[None] for cloud in (source, target))
        result = self.prior.register_batch(*clouds, run_cem=False)
        return SearchPrior(result.mu0[0], result.sigma0[0])


def search_source(frame: Frame, map_voxel: float, n: int, seed: int) -> np.ndarray:
    """The scan's points near the sensor thinned to the map's voxel (the map holds at most a few points per
    voxel: the scan is sampled at the same density), ``n`` of them at random."""
    return subsample(voxel_downsample(frame.near, map_voxel), n, "random", seed)


def lean_search(search: GlobalSearchConfig, effort: float) -> GlobalSearchConfig:
    """The search's scatter and seeds scaled by ``effort`` (0, 1] (the hypotheses and their CEM kept)."""
    if effort >= 1.0:
        return search
    return dataclasses.replace(search, n_scatter=max(search.n_hypotheses, search.n_seeds,
                                                     round(effort * search.n_scatter)),
                               n_per_seed=round(effort * search.n_per_seed))


def prior_registrar(config: AlignerConfig, given: Optional[Registrar] = None) -> Optional[Registrar]:
    """The registrar whose sampling network gives the search's prior: None unless ``recovery.scatter`` is
    'network'; then ``given``, or one loading ``recovery.weights``."""
    rec = config.recovery
    if rec.scatter != "network":
        return None
    return given or Registrar(RegistrationConfig(prior="network", weights=rec.weights, allow_pickle=rec.allow_pickle,
                                                 n_points=rec.points, device=config.registration.device))
