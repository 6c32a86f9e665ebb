"""cemnet-register: register two point cloud files with CEMNet and print the source -> target transform.

Reads .ply / .pcd / .npy / .npz / KITTI .bin and aligns them with :func:`cemnet_ros.align_clouds.align_clouds`:
metric scans through the scan pipeline's pair mode, object-scale clouds through the paper's engine
(``--mode`` chooses). Prints the 4x4 matrix T with ``target ~= T @ source``, which method ran, the fitness, and
the engine's final CEM spread (sigma) or the pipeline's verdict.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from cemnet_ros.align_clouds import METRIC_EXTENT, MODES, UNIT_RADIUS, align_clouds
from cemnet_ros.core.checkpoint import CheckpointError
from cemnet_ros.core.config import RegistrationConfig
from cemnet_ros.io.pointcloud_files import read_points
from cemnet_ros.io.report import Report, emit
from cemnet_ros.tools.cli_errors import reported_errors
from cemnet_ros.tools.engine_args import add_engine_args, config_from_args

PROG = "cemnet-register"
METHOD_NAMES = {"scan": "the scan pipeline's pair mode (global CEM search, point-to-plane polish, judged)",
                "engine": "the paper's engine (CEMNet alone)"}


@dataclass(frozen=True)
class RegisterConfig:
    """The two files, the method (``auto``, ``scan`` or ``engine``), the ``--scale`` text (a number or 'auto')
    and the engine's configuration."""

    source: str
    target: str
    mode: str = "auto"
    scale: str = "auto"
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)


@dataclass
class RegisterReport(Report):
    """T_target_source in the clouds' units, the method that ran, the fitness, the engine's sigma (None for the
    scan pipeline) or the pipeline's verdict, sizes and the registration's runtime."""

    T_target_source: np.ndarray
    method: str
    fitness: float
    accepted: bool
    reason: str
    sigma: Optional[np.ndarray]  # engine: [euler z, y, x (rad), tx, ty, tz (cloud units)]
    scale: float
    n_source: int
    n_target: int
    runtime_s: float

    def to_markdown(self) -> str:
        verdict = (f"sigma [z, y, x rad, tx, ty, tz units]: {self.sigma}" if self.sigma is not None else
                   "verdict: " + ("accepted" if self.accepted else f"flagged ({self.reason})"))
        with np.printoptions(precision=6, suppress=True, floatmode="fixed"):
            return "\n".join(
                [f"# source -> target transform (target ~= T @ source); scale {self.scale:g} units per network unit"]
                + [" ".join(f"{v: .6f}" for v in row) for row in self.T_target_source]
                + [f"method: {self.method}, {METHOD_NAMES[self.method]}", f"fitness: {self.fitness:.4f}", verdict,
                   f"points: source {self.n_source}, target {self.n_target}; runtime {self.runtime_s * 1e3:.0f} ms"])


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("source", help="cloud to move (.ply, .pcd, .npy, .npz, KITTI .bin)")
    parser.add_argument("target", help="cloud to align onto")
    parser.add_argument("--mode", default="auto", choices=MODES,
                        help="'scan': the scan pipeline's pair mode (metric scans: global CEM search, point-to-plane "
                             "polish in metres, judged; the pipeline's default parameters); 'engine': the paper's "
                             "engine alone (object-scale clouds, the paper's protocol; configured by the flags "
                             "below); 'auto' (default): 'scan' when either cloud's bounding box is longer than "
                             f"{METRIC_EXTENT:g} units on a side, else 'engine'")
    parser.add_argument("--scale", default="auto",
                        help="units per network unit: coordinates are divided by it before registration and the "
                             "translation is multiplied by it after (the network works on unit-sphere objects). "
                             f"'auto' (default): the engine takes 1.0 when both clouds have a radius (max distance "
                             f"to their centroid) below {UNIT_RADIUS:g}, else the 90th percentile of the target's "
                             "distances to its centroid; the scan pipeline measures it on the target "
                             "(preprocess.scale 0); give a number to override")
    parser.add_argument("--json", default=None, help="also write the result (transform, sigma, fitness) here")
    add_engine_args(parser)
    return parser


def parsed_scale(text: str) -> Optional[float]:
    """A ``--scale`` number, or None for 'auto'; ValueError for anything else."""
    if text == "auto":
        return None
    try:
        scale = float(text)
    except ValueError:
        raise ValueError(f"--scale must be a positive number or 'auto', not {text!r}") from None
    if not np.isfinite(scale) or scale <= 0:
        raise ValueError(f"--scale must be a positive number or 'auto', not {text!r}")
    return scale


def run(config: RegisterConfig) -> RegisterReport:
    """Read both files and align them with the method ``config.mode`` picks."""
    source, target = read_points(config.source), read_points(config.target)
    result = align_clouds(source, target, config.mode, registration=config.registration,
                          scale=parsed_scale(config.scale))
    return RegisterReport(result.transform, result.method, result.fitness, result.accepted, result.reason,
                          result.sigma, result.scale, len(source), len(target), result.runtime_s)


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    with reported_errors(PROG, CheckpointError) as outcome:
        emit(run(RegisterConfig(args.source, args.target, args.mode, args.scale, config_from_args(args))),
             args.json)
    return outcome.code


if __name__ == "__main__":
    sys.exit(main())
