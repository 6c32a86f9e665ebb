"""Which extrinsic ``T_base_sensor`` the node's outputs use, and why it never changes once they have begun.

The parameter ``base_to_sensor`` is in force until TF gives the transform; TF's is taken while no output has been
published. After the first output the extrinsic is held: swapping it would move every later pose of ``odom``
(``T_odom_base = T_base_sensor T_sensor0_sensor inv(T_base_sensor)``) with no motion of the robot. A TF
extrinsic that arrives later and differs is ignored, and said so (a standing warning: the outputs' base frame
then disagrees with the TF tree until the node restarts).
"""
from __future__ import annotations

from typing import Optional

import numpy as np

SAME_ATOL = 1e-6  # a TF extrinsic this close (m, and rotation matrix entries) to the one in use is the same


class ExtrinsicHold:
    """The extrinsic in use: :meth:`offer` TF's, :meth:`output_published` once a pose has gone out."""

    def __init__(self, T_base_sensor: np.ndarray) -> None:
        self.T_base_sensor = np.asarray(T_base_sensor, dtype=np.float64)
        self.source = "base_to_sensor"
        self.settled = False  # TF has answered: no more lookups
        self.ignored: Optional[str] = None  # the standing warning, when a later TF extrinsic differed
        self._published = False

    def output_published(self) -> None:
        self._published = True

    def offer(self, T_tf: np.ndarray, frames: str) -> tuple[bool, str]:
        """TF's extrinsic (``frames``: "base_link <- velodyne"): (whether it is now in use, a log line); a later,
        different one sets :attr:`ignored`."""
        self.settled = True
        T_tf = np.asarray(T_tf, dtype=np.float64)
        if not self._published:
            self.T_base_sensor, self.source = T_tf, "tf"
            return True, f"extrinsic {frames} from TF"
        if np.allclose(T_tf, self.T_base_sensor, atol=SAME_ATOL):
            return False, f"extrinsic {frames} from TF matches base_to_sensor, in use since the first output"
        shift = np.linalg.norm(T_tf[:3, 3] - self.T_base_sensor[:3, 3])
        angle = np.degrees(np.arccos(np.clip((np.trace(T_tf[:3, :3].T @ self.T_base_sensor[:3, :3]) - 1) / 2, -1, 1)))
        self.ignored = (f"the TF extrinsic {frames} arrived after the first output and differs from "
                        f"base_to_sensor, in use ({shift:.3f} m, {angle:.2f} deg): ignored, as swapping it would "
                        "jump odom; restart the node once TF is up (or set base_to_sensor to it)")
        return False, self.ignored
