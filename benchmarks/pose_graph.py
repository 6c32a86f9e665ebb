"""A tiny pose graph (Gauss-Newton in numpy): what a SLAM back end does with the node's odometry and covariances.

A between factor ``(i, j, T_i_j, Sigma)`` says ``inv(T_i) T_j = T_i_j`` up to an error of covariance ``Sigma``
(6x6, ROS order [v, w]) in the base axes of pose j: ``v = R_ij^T (t_ij - t_meas)``, ``w = log(R_meas^T R_ij)``.
That is exactly the node's pose covariance turned into base axes (:func:`~cemnet_ros.runtime.extrinsic.
in_body_axes`, the twist covariance times dt^2): its rotation is about the base's position, so in the base's
axes it is a right perturbation of the step's motion. Pose 0 is held fixed.
"""
from __future__ import annotations

from typing import Optional, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from cemnet_ros.core.geometry import hat

UNKNOWN_VARIANCE = 1e6  # a step without a known motion (map restart): connects the graph, constrains nothing


class PoseGraph:
    """Poses (4x4) linked by between factors; :meth:`optimise` returns the poses that fit them best."""

    def __init__(self, initial: Sequence[np.ndarray]) -> None:
        self.initial = [np.asarray(T, dtype=np.float64) for T in initial]
        self._factors: list[tuple[int, int, np.ndarray, np.ndarray]] = []

    def add_between(self, i: int, j: int, T_i_j: np.ndarray, covariance: np.ndarray) -> None:
        """``inv(T_i) T_j`` measured as ``T_i_j`` with ``covariance`` (ROS order, base axes of pose j)."""
        information = np.linalg.inv(covariance)
        whiten = np.linalg.cholesky((information + information.T) / 2).T  # whiten^T whiten = Sigma^-1
        self._factors.append((i, j, np.asarray(T_i_j, dtype=np.float64), whiten))

    def _linearised(self, R: np.ndarray, t: np.ndarray, i: int, j: int, T_i_j: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(error (6,) [v, w], d error / d pose i, d error / d pose j) of one factor; a pose moves by [dtheta, dt]:
        R <- exp([dtheta]x) R, t <- t + dt (Jacobians exact where the error is zero)."""
        b = R[i] @ T_i_j[:3, 3]
        a = t[j] - t[i] - b
        error = np.r_[R[j].T @ a, Rotation.from_matrix(T_i_j[:3, :3].T @ R[i].T @ R[j]).as_rotvec()]
        d_i, d_j = np.zeros((6, 6)), np.zeros((6, 6))
        d_i[:3, :3], d_i[:3, 3:], d_i[3:, :3] = R[j].T @ hat(b), -R[j].T, -R[j].T
        d_j[:3, :3], d_j[:3, 3:], d_j[3:, :3] = R[j].T @ hat(a), R[j].T, R[j].T
        return error, d_i, d_j

    def optimise(self, iterations: int = 30, tolerance: float = 1e-10) -> list[np.ndarray]:
        """The poses minimising the whitened factor errors (Gauss-Newton from the initial ones; pose 0 fixed)."""
        n = len(self.initial)
        R = np.array([T[:3, :3] for T in self.initial])
        t = np.array([T[:3, 3] for T in self.initial])
        for _ in range(iterations):
            hessian, gradient = np.zeros((6 * n, 6 * n)), np.zeros(6 * n)
            for i, j, T_i_j, whiten in self._factors:
                error, d_i, d_j = self._linearised(R, t, i, j, T_i_j)
                blocks = ((i, whiten @ d_i), (j, whiten @ d_j))
                for a, J_a in blocks:
                    gradient[6 * a:6 * a + 6] += J_a.T @ (whiten @ error)
                    for b, J_b in blocks:
                        hessian[6 * a:6 * a + 6, 6 * b:6 * b + 6] += J_a.T @ J_b
            step = np.zeros(6 * n)
            step[6:] = np.linalg.solve(hessian[6:, 6:], -gradient[6:])
            moves = step.reshape(n, 6)
            R = np.einsum("nab,nbc->nac", Rotation.from_rotvec(moves[:, :3]).as_matrix(), R)
            t = t + moves[:, 3:]
            if np.max(np.abs(step)) < tolerance:
                break
        out = [np.eye(4) for _ in range(n)]
        for T, R_k, t_k in zip(out, R, t):
            T[:3, :3], T[:3, 3] = R_k, t_k
        return out


def close_loop(poses: Sequence[np.ndarray], body_covariances: Sequence[Optional[np.ndarray]],
               T_first_last: np.ndarray, closure_std: tuple[float, float] = (1e-3, 1e-3)) -> list[np.ndarray]:
    """Odometry ``poses`` (T_odom_base), each step k weighted by ``body_covariances[k]`` (base axes; None: a
    step with no known motion), closed by a factor saying ``inv(T_0) T_last = T_first_last`` with
    ``closure_std`` (m, rad). Returns the optimised poses."""
    graph = PoseGraph(poses)
    for k in range(1, len(poses)):
        covariance = body_covariances[k]
        graph.add_between(k - 1, k, np.linalg.inv(poses[k - 1]) @ poses[k],
                          np.eye(6) * UNKNOWN_VARIANCE if covariance is None else covariance)
    std = np.r_[np.full(3, closure_std[0]), np.full(3, closure_std[1])]
    graph.add_between(0, len(poses) - 1, T_first_last, np.diag(std ** 2))
    return graph.optimise()
