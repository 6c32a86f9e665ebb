"""The published covariances mean what docs/node.md says: errors drawn from the pose covariance of a step give
twists whose spread is the twist covariance (odometry_output)."""
from dataclasses import dataclass

import numpy as np
from street_scene import make_transform

from cemnet_ros.core.geometry import so3_exp
from cemnet_ros.ros.node_config import NodeConfig
from cemnet_ros.runtime.extrinsic import BaseFrame
from cemnet_ros.runtime.odometry_output import odometry_output

DT_S = 0.5


@dataclass
class Step:
    """The fields of an AlignmentStep that odometry_output reads."""

    pose: np.ndarray
    relative: np.ndarray
    covariance: np.ndarray
    accepted: bool = True


def test_the_twist_covariance_is_the_spread_of_the_twist_that_the_pose_errors_give():
    """A step turning 40 deg: the twist is the step's motion in the previous base frame's axes over dt, so its
    covariance must be the pose covariance turned into those axes (not the current pose's) over dt^2."""
    rng = np.random.default_rng(3)
    previous = make_transform(t=(3.0, 1.0, 0.0), yaw=0.3)
    current = previous @ make_transform(t=(1.0, 0.4, 0.0), yaw=np.radians(40.0))
    covariance = np.diag([0.04, 0.0025, 0.0004, 1e-6, 1e-6, 1e-4])  # loose along odom x, tight along y
    base, node = BaseFrame(np.eye(4)), NodeConfig()
    out = odometry_output(Step(current, np.linalg.inv(previous) @ current, covariance), base, DT_S, node, 100.0)
    twists = []
    for e in rng.multivariate_normal(np.zeros(6), covariance, size=4000):
        moved = current.copy()
        moved[:3, :3], moved[:3, 3] = so3_exp(e[3:]) @ current[:3, :3], current[:3, 3] + e[:3]
        o = odometry_output(Step(moved, np.linalg.inv(previous) @ moved, covariance), base, DT_S, node, 100.0)
        twists.append(np.r_[o.linear, o.angular])
    # roll and pitch left out: across a 40 deg turn their rotation vector picks up SO(3)'s Jacobian (~4 %)
    keep = np.ix_([0, 1, 2, 5], [0, 1, 2, 5])
    spread, published = np.cov(np.array(twists).T)[keep], out.twist_covariance[keep]
    std = np.sqrt(np.diag(published))
    np.testing.assert_allclose(spread / np.outer(std, std), published / np.outer(std, std), atol=0.08)
