"""Global CEM search: the cross-entropy method started from the whole space of plausible motions.

Local registration (ICP, or a CEM around a prediction) falls into the nearest minimum. The CEM's sampling needs
no initial guess, so a wide search survives what breaks local methods (the first pair, a dropout, a kidnap):

1. **scatter**: candidates drawn uniformly over yaw (the full circle about the cloud's z axis), uniformly over a
   disc of translations around a centre, with small roll, pitch and height spreads (a ground robot); with a
   prior (e.g. the sampling network's mu0, sigma0), ``n_network`` more drawn from it, so that a good prior lets
   a smaller uniform scatter suffice;
2. **score coarsely**: each candidate's fused reward (the paper's current + after-ICP max-consensus) at a coarse
   epsilon, so that candidates in the right basin score even when they are metres off;
3. **resample**: new candidates around the best distinct ones, scored the same way (one cross-entropy step of a
   mixture: the scatter finds the basins, the resampling fills them);
4. **keep distinct hypotheses**: the best candidates, at most one per (yaw, translation) neighbourhood;
5. **refine each with the CEM** at the fine epsilon (sparsemax-weighted refits, fused reward in the first
   iterations, as in Algorithm 1 of the paper), all hypotheses in one batch;
6. **rank** them by their final max-consensus fitness.

Everything is in the engine's units (clouds scaled to the ModelNet unit sphere) and actions
``[euler z, y, x, tx, ty, tz]``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
import torch

from .config import CEMConfig, GlobalSearchConfig
from .engine import CEMNet
from .geometry import action_to_matrix_np
from .scoring import CandidateScorer

SCATTER_CHUNK = 500  # candidates scored at once (bounds the memory of one scoring call)


@dataclass
class SearchPrior:
    """A Gaussian over actions (6,) ``[euler z, y, x, tx, ty, tz]`` (units) that part of the scatter is drawn from.

    It is used as given: the spread's widening is the search's ``network_scale``, and the uniform scatter beside it
    is the exploration (the CEM's test-time blend towards the identity would halve a large yaw).
    """

    mu: np.ndarray
    sigma: np.ndarray


@dataclass
class Hypothesis:
    """One refined answer of the global search: ``T_target_source`` (4x4, units) and its fitness in [0, 1]."""

    T_target_source: np.ndarray
    fitness: float
    sigma: np.ndarray  # (6,) the CEM's final spread


def scatter(centre: np.ndarray, radius: float, config: GlobalSearchConfig, rng: np.random.Generator,
            prior: Optional[SearchPrior] = None) -> np.ndarray:
    """(n_scatter, 6) actions: yaw uniform on the circle, translation uniform on a disc around ``centre`` (6,).

    With a ``prior``, (n_network + n_scatter, 6): the first ``n_network`` from N(mu, (network_scale * sigma)^2), the
    uniform ones drawn as without a prior.
    """
    uniform = _uniform(centre, radius, config.n_scatter, config, rng)
    if prior is None:
        return uniform
    drawn = prior.mu + rng.normal(size=(config.n_network, 6)) * (config.network_scale * np.asarray(prior.sigma))
    return np.vstack([drawn, uniform])


def _uniform(centre: np.ndarray, radius: float, n: int, config: GlobalSearchConfig, rng: np.random.Generator
             ) -> np.ndarray:
    """(n, 6) actions: yaw uniform on the circle, translation uniform on the disc, small tilt and height."""
    r, angle = radius * np.sqrt(rng.uniform(0.0, 1.0, n)), rng.uniform(-np.pi, np.pi, n)
    actions = np.empty((n, 6))
    actions[:, 0] = centre[0] + rng.uniform(-np.pi, np.pi, n)
    actions[:, 1] = centre[1] + rng.normal(0.0, config.tilt_sigma, n)
    actions[:, 2] = centre[2] + rng.normal(0.0, config.tilt_sigma, n)
    actions[:, 3] = centre[3] + r * np.cos(angle)
    actions[:, 4] = centre[4] + r * np.sin(angle)
    actions[:, 5] = centre[5] + rng.normal(0.0, config.height_sigma, n)
    return actions


def distinct_best(actions: np.ndarray, cost: np.ndarray, config: GlobalSearchConfig, count: int) -> np.ndarray:
    """The ``count`` lowest-cost actions, skipping any within the separation of one already kept."""
    kept: list[np.ndarray] = []
    for i in np.argsort(cost):
        a = actions[i]
        if all(abs(np.angle(np.exp(1j * (a[0] - k[0])))) > config.min_separation_yaw
               or np.linalg.norm(a[3:5] - k[3:5]) > config.min_separation_translation for k in kept):
            kept.append(a)
            if len(kept) == count:
                break
    return np.array(kept)


def _scores(scorer: CandidateScorer, actions: np.ndarray) -> np.ndarray:
    """Fused costs of all ``actions``, in chunks. Every candidate is scored, whatever the machine's speed: the
    same scan always yields the same hypotheses."""
    if len(actions) == 0:
        return np.zeros(0)
    chunks = np.array_split(actions, max(1, len(actions) // SCATTER_CHUNK))
    return np.concatenate([scorer.cost(torch.from_numpy(chunk)[None], fused=True)[0].numpy() for chunk in chunks])


def global_search(source: np.ndarray, target: np.ndarray, centre: np.ndarray, radius: float,
                  config: Optional[GlobalSearchConfig] = None, seed: int = 0,
                  prior: Optional[SearchPrior] = None) -> list[Hypothesis]:
    """Search ``T_target_source`` for prepared clouds (n, 3), (m, 3) in units; best hypothesis first.

    ``centre`` (6,) is the action the translation disc and yaw circle are centred on (e.g. a prediction) and
    ``radius`` the disc's radius in units; ``prior`` (absolute actions, not relative to ``centre``) adds
    ``config.n_network`` candidates drawn from it to the scatter.
    """
    config = config or GlobalSearchConfig()
    rng = np.random.default_rng(seed)
    src = torch.as_tensor(np.asarray(source), dtype=torch.float32)[None]
    tgt = torch.as_tensor(np.asarray(target), dtype=torch.float32)[None]
    coarse = CEMConfig(epsilon=config.coarse_epsilon, icp_steps=config.refine.icp_steps,
                       icp_max_distance=2.0 * config.coarse_epsilon)
    scorer = CandidateScorer(src, tgt, coarse)
    actions = scatter(np.asarray(centre, dtype=np.float64), radius, config, rng, prior)
    cost = _scores(scorer, actions)
    seeds = distinct_best(actions, cost, config, config.n_seeds)
    around = (seeds[:, None, :] + rng.normal(size=(len(seeds), config.n_per_seed, 6))
              * np.asarray(config.resample_sigma)).reshape(-1, 6)
    around_cost = _scores(scorer, around)
    starts = distinct_best(np.vstack([actions, around]), np.concatenate([cost, around_cost]), config,
                           config.n_hypotheses)
    k = len(starts)
    engine = CEMNet(config.refine)
    out = engine(src.expand(k, -1, -1), tgt.expand(k, -1, -1),  # broadcast: one lattice for all hypotheses
                 torch.as_tensor(starts, dtype=torch.float32),
                 torch.tensor(config.refine_sigma, dtype=torch.float32).expand(k, 6).contiguous(),
                 generator=torch.Generator().manual_seed(seed))
    mu, sigma, fitness = out.mu.double().numpy(), out.sigma.double().numpy(), out.fitness.double().numpy()
    order = np.argsort(-fitness)
    return [Hypothesis(action_to_matrix_np(mu[i]), float(fitness[i]), sigma[i]) for i in order]

