"""High-level registration API: ``register(source, target)`` on numpy clouds of any size."""
from __future__ import annotations

import collections
import time
import warnings
from dataclasses import dataclass
from typing import Optional

import numpy as np
import torch

from . import lattice_rewards
from .checkpoint import load_network
from .config import RegistrationConfig, seed_or_none
from .engine import CEMNet
from .geometry import euler_to_matrix_np, matrix_to_action_np, rigid_transform
from .icp import point_to_point_icp
from .lattice_rewards import consensus_fitness

NETWORK_MIN_POINTS = 20  # the network's k-NN graph


@dataclass
class RegistrationResult:
    """A rigid motion mapping the source onto the target: ``target ~= rotation @ source + translation``."""

    rotation: np.ndarray  # (3, 3)
    translation: np.ndarray  # (3,)
    sigma: np.ndarray  # (6,) final CEM spread [z, y, x (rad), tx, ty, tz]: the pose uncertainty
    mu: np.ndarray  # (6,) final mean action
    mu0: np.ndarray  # (6,) initial mean (network, motion model or identity)
    sigma0: np.ndarray  # (6,)
    fitness: float  # max-consensus inlier score in [0, 1] at epsilon (1 = every point has a partner at 0)
    runtime_s: float

    @property
    def transform(self) -> np.ndarray:
        """4x4 ``T_target_source``."""
        return rigid_transform(self.rotation, self.translation)


@dataclass
class BatchRegistrationResult:
    """The registrations of B pairs, row b for pair b: ``target_b ~= rotation[b] @ source_b + translation[b]``."""

    rotation: np.ndarray  # (B, 3, 3)
    translation: np.ndarray  # (B, 3)
    sigma: np.ndarray  # (B, 6) final CEM spread (mu0's spread when the CEM did not run)
    mu: np.ndarray  # (B, 6) final mean action
    mu0: np.ndarray  # (B, 6) initial mean
    sigma0: np.ndarray  # (B, 6)
    fitness: np.ndarray  # (B,) max-consensus inlier score in [0, 1] at epsilon

    def pair(self, b: int, runtime_s: float) -> RegistrationResult:
        """The registration of pair ``b``, which took ``runtime_s``."""
        return RegistrationResult(self.rotation[b], self.translation[b], self.sigma[b], self.mu[b], self.mu0[b],
                                  self.sigma0[b], float(self.fitness[b]), runtime_s)


def _float64_copy(values: torch.Tensor) -> np.ndarray:
    """A float64 numpy copy of a tensor (never a view: the refinement writes into it)."""
    return np.array(values.detach().double().cpu().numpy())


def resolve_device(name: str) -> torch.device:
    """"auto" -> CUDA when available, else CPU."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def prepare_cloud(points: np.ndarray, n_points: int, rng: np.random.Generator, name: str, min_points: int
                  ) -> np.ndarray:
    """Validate an (n, 3) cloud, drop non-finite rows (with a warning) and sub-sample to ``n_points``."""
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"{name} must be an (n, 3) array, got shape {points.shape}")
    if not np.issubdtype(points.dtype, np.number):
        raise ValueError(f"{name} must be numeric, got dtype {points.dtype}")
    finite = np.isfinite(points).all(1)
    if not finite.all():
        warnings.warn(f"{name}: dropped {int((~finite).sum())} of {len(points)} non-finite points", stacklevel=3)
        points = points[finite]
    if len(points) < min_points:
        raise ValueError(f"{name} has {len(points)} finite points; at least {min_points} are needed")
    if len(points) > n_points:
        points = points[rng.choice(len(points), n_points, replace=False)]
    return points.astype(np.float32)


class Registrar:
    """Holds the engine (and the network's weights) for repeated registrations."""

    def __init__(self, config: RegistrationConfig | None = None):
        self.config = config or RegistrationConfig()
        self.device = resolve_device(self.config.device)
        network = None
        if self.config.prior == "network":
            network = load_network(self.config.weights, self.config.allow_pickle)
            network.batch_stats_at_inference = self.config.batchnorm == "batch"
        self.engine = CEMNet(self.config.cem, network, self.config.prior_sigma).to(self.device).eval()
        if self.device.type == "cpu":
            lattice_rewards.compile_kernels()

    def _generator(self) -> torch.Generator | None:
        seed = seed_or_none(self.config.cem.seed)
        return None if seed is None else torch.Generator(device=self.device).manual_seed(seed)

    @torch.no_grad()
    def register_batch(self, source: torch.Tensor, target: torch.Tensor, mu0: torch.Tensor | None = None,
                       sigma0: torch.Tensor | None = None, run_cem: bool = True) -> BatchRegistrationResult:
        """Register B pairs of prepared clouds (B, n, 3), (B, m, 3); ``run_cem=False`` returns mu0 alone."""
        source = source.to(self.device, torch.float32)
        target = target.to(self.device, torch.float32)
        if run_cem:
            out = self.engine(source, target, mu0, sigma0, generator=self._generator())
            mu, sigma, mu0, sigma0, fitness = out.mu, out.sigma, out.mu0, out.sigma0, out.fitness
        else:
            if mu0 is None or sigma0 is None:
                mu0, sigma0 = self.engine.initial_distribution(source, target)
            mu, sigma, fitness = mu0, sigma0, None
        mu_np = _float64_copy(mu)
        result = BatchRegistrationResult(euler_to_matrix_np(mu_np[:, :3]), mu_np[:, 3:].copy(), _float64_copy(sigma),
                                         mu_np, _float64_copy(mu0), _float64_copy(sigma0),
                                         np.empty(len(mu_np)) if fitness is None else _float64_copy(fitness))
        if self.config.cem.refine_icp_steps > 0 or fitness is None:
            self._refine_and_score(result, source.cpu().numpy(), target.cpu().numpy())
        return result

    def _refine_and_score(self, result: BatchRegistrationResult, sources: np.ndarray, targets: np.ndarray) -> None:
        """In place: each motion refined by ``refine_icp_steps`` ICP steps (pairs within epsilon), then scored."""
        cem = self.config.cem
        for b in range(len(result.mu)):
            if cem.refine_icp_steps > 0:
                result.rotation[b], result.translation[b] = point_to_point_icp(
                    sources[b], targets[b], result.rotation[b], result.translation[b], cem.refine_icp_steps,
                    max_distance=cem.epsilon)
                result.mu[b] = matrix_to_action_np(rigid_transform(result.rotation[b], result.translation[b]))
            result.fitness[b] = consensus_fitness(sources[b], targets[b], result.rotation[b], result.translation[b],
                                                  cem.epsilon)

    def register(self, source: np.ndarray, target: np.ndarray, prior_pose: Optional[np.ndarray] = None,
                 prior_sigma: Optional[np.ndarray] = None) -> RegistrationResult:
        """Register one pair of (n, 3) and (m, 3) clouds; ``prior_pose`` (4x4) replaces the network's mu0."""
        start = time.perf_counter()
        rng = np.random.default_rng(seed_or_none(self.config.seed))
        min_points = NETWORK_MIN_POINTS if prior_pose is None and self.config.prior == "network" else 3
        src = prepare_cloud(source, self.config.n_points, rng, "source", min_points)
        tgt = prepare_cloud(target, self.config.n_points, rng, "target", min_points)
        mu0 = sigma0 = None
        if prior_pose is not None:
            prior_pose = np.asarray(prior_pose, dtype=np.float64)
            if prior_pose.shape != (4, 4) or not np.isfinite(prior_pose).all():
                raise ValueError(f"prior_pose must be a finite 4x4 matrix, got shape {prior_pose.shape}")
            spread = self.config.prior_sigma if prior_sigma is None else prior_sigma
            mu0 = torch.as_tensor(matrix_to_action_np(prior_pose), dtype=torch.float32)[None]
            sigma0 = torch.as_tensor(np.asarray(spread, dtype=np.float64), dtype=torch.float32).reshape(1, 6)
        batch = self.register_batch(torch.from_numpy(src)[None], torch.from_numpy(tgt)[None], mu0, sigma0)
        return batch.pair(0, time.perf_counter() - start)


REGISTRARS_KEPT = 4  # distinct configs whose engine register() keeps (each holds a network): least recent out
_DEFAULT_REGISTRARS: collections.OrderedDict[str, Registrar] = collections.OrderedDict()


def register(source: np.ndarray, target: np.ndarray, config: RegistrationConfig | None = None, *,
             prior_pose: Optional[np.ndarray] = None, prior_sigma: Optional[np.ndarray] = None
             ) -> RegistrationResult:
    """Register ``source`` onto ``target`` (any sizes; sub-sampled to ``config.n_points``).

    The engine for a given config is built once and reused by later calls (the REGISTRARS_KEPT most recent).
    """
    config = config or RegistrationConfig()
    key = repr(config)
    registrar = _DEFAULT_REGISTRARS.pop(key, None) or Registrar(config)
    _DEFAULT_REGISTRARS[key] = registrar
    while len(_DEFAULT_REGISTRARS) > REGISTRARS_KEPT:
        _DEFAULT_REGISTRARS.popitem(last=False)
    return registrar.register(source, target, prior_pose, prior_sigma)
