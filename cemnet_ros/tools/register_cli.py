"""cemnet-register: register two point cloud files with CEMNet and print the source -> target transform.

Reads .ply / .pcd / .npy / .npz / KITTI .bin, runs :func:`cemnet_ros.core.register` and prints the 4x4
matrix T with ``target ~= T @ source`` plus the fitness and the final CEM spread (sigma).
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from cemnet_ros.core import register
from cemnet_ros.core.checkpoint import CheckpointError
from cemnet_ros.core.config import RegistrationConfig
from cemnet_ros.io.pointcloud_files import read_points
from cemnet_ros.io.report import Report, emit
from cemnet_ros.tools.cli_errors import reported_errors
from cemnet_ros.tools.engine_args import add_engine_args, config_from_args

PROG = "cemnet-register"
AUTO_SCALE_RADIUS = 2.0  # clouds smaller than this are taken to be in network (unit-sphere) units


@dataclass(frozen=True)
class RegisterConfig:
    """The two files, the ``--scale`` text (a number or 'auto') and the engine's configuration."""

    source: str
    target: str
    scale: str = "auto"
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)


@dataclass
class RegisterReport(Report):
    """T_target_source and sigma in the clouds' units, the fitness, sizes and the engine's runtime."""

    T_target_source: np.ndarray
    sigma: np.ndarray  # [euler z, y, x (rad), tx, ty, tz (cloud units)]
    fitness: float
    scale: float
    n_source: int
    n_target: int
    runtime_s: float

    def to_markdown(self) -> str:
        with np.printoptions(precision=6, suppress=True, floatmode="fixed"):
            return "\n".join(
                [f"# source -> target transform (target ~= T @ source); scale {self.scale:g} units per network unit"]
                + [" ".join(f"{v: .6f}" for v in row) for row in self.T_target_source]
                + [f"fitness: {self.fitness:.4f}", f"sigma [z, y, x rad, tx, ty, tz units]: {self.sigma}",
                   f"points: source {self.n_source}, target {self.n_target}; runtime {self.runtime_s * 1e3:.0f} ms"])


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("source", help="cloud to move (.ply, .pcd, .npy, .npz, KITTI .bin)")
    parser.add_argument("target", help="cloud to align onto")
    parser.add_argument("--scale", default="auto",
                        help="units per network unit: coordinates are divided by it before registration and the "
                             "translation is multiplied by it after (the network works on unit-sphere objects). "
                             f"'auto' (default): 1.0 when both clouds have a radius (max distance to their "
                             f"centroid) below {AUTO_SCALE_RADIUS:g}, else the 90th percentile of the target's "
                             "distances to its centroid (e.g. for scans in metres); give a number to override")
    parser.add_argument("--json", default=None, help="also write the result (transform, sigma, fitness) here")
    add_engine_args(parser)
    return parser


def resolve_scale(text: str, source: np.ndarray, target: np.ndarray) -> float:
    """The ``--scale`` value as a positive float (see the flag's help for 'auto')."""
    if text == "auto":
        radius = max(np.linalg.norm(c - c.mean(0), axis=1).max() for c in (source, target))
        if radius < AUTO_SCALE_RADIUS:
            return 1.0
        return float(np.percentile(np.linalg.norm(target - target.mean(0), axis=1), 90))
    try:
        scale = float(text)
    except ValueError:
        raise ValueError(f"--scale must be a positive number or 'auto', not {text!r}") from None
    if not np.isfinite(scale) or scale <= 0:
        raise ValueError(f"--scale must be a positive number or 'auto', not {text!r}")
    return scale


def run(config: RegisterConfig) -> RegisterReport:
    """Read both files, register them in network units, and scale the translation and sigma back."""
    source, target = read_points(config.source), read_points(config.target)
    scale = resolve_scale(config.scale, source, target)
    result = register(source / scale, target / scale, config.registration)
    transform, sigma = result.transform, result.sigma.copy()
    transform[:3, 3] *= scale
    sigma[3:] *= scale
    return RegisterReport(transform, sigma, float(result.fitness), scale, len(source), len(target),
                          float(result.runtime_s))


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    with reported_errors(PROG, CheckpointError) as outcome:
        emit(run(RegisterConfig(args.source, args.target, args.scale, config_from_args(args))), args.json)
    return outcome.code


if __name__ == "__main__":
    sys.exit(main())
