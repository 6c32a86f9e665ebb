"""A procedural, asymmetric test object: no data files needed, the same points on every machine."""
from __future__ import annotations

import numpy as np


def _box_surface(rng: np.random.Generator, n: int, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    size = hi - lo
    areas = np.array([size[1] * size[2], size[0] * size[2], size[0] * size[1]]).repeat(2)
    face = rng.choice(6, n, p=areas / areas.sum())
    pts = lo + rng.random((n, 3)) * size
    axis = face // 2
    pts[np.arange(n), axis] = np.where(face % 2 == 0, lo[axis], hi[axis])
    return pts


def bracket_shape(n_points: int = 2048, seed: int = 0) -> np.ndarray:
    """(n, 3) float32 points on an L-shaped bracket with a peg and a knob, centred, scaled into the unit sphere.

    It has no rotational symmetry, so a registration of it has one right answer.
    """
    rng = np.random.default_rng(seed)
    n_base, n_wall, n_peg = int(n_points * 0.4), int(n_points * 0.3), int(n_points * 0.15)
    n_knob = n_points - n_base - n_wall - n_peg
    base = _box_surface(rng, n_base, np.array([-0.8, -0.5, -0.1]), np.array([0.8, 0.5, 0.1]))
    wall = _box_surface(rng, n_wall, np.array([-0.8, -0.5, 0.1]), np.array([-0.6, 0.5, 0.9]))
    theta, h = rng.random(n_peg) * 2 * np.pi, rng.random(n_peg) * 0.5
    peg = np.stack([0.4 + 0.12 * np.cos(theta), 0.2 + 0.12 * np.sin(theta), 0.1 + h], 1)
    knob = rng.standard_normal((n_knob, 3))
    knob = knob / np.linalg.norm(knob, axis=1, keepdims=True) * 0.15 + np.array([0.3, -0.3, 0.25])
    pts = np.concatenate([base, wall, peg, knob])
    pts -= pts.mean(0)
    pts /= np.linalg.norm(pts, axis=1).max()
    return rng.permutation(pts).astype(np.float32)
