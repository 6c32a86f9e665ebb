"""The CEMNet engine's flags for cemnet-eval, cemnet-bench and cemnet-register, built from the schema.

One flag per :class:`~cemnet_ros.core.config.RegistrationConfig` field, dotted by section:
``--cem.n_candidates 500 --cem.n_iters 5 --prior identity --weights official --allow-pickle``.
"""
from __future__ import annotations

import argparse

from cemnet_ros.core.config import RegistrationConfig
from cemnet_ros.schema import add_arguments, build, parameters, parsed_overrides

ENGINE = parameters(RegistrationConfig())


def add_engine_args(parser: argparse.ArgumentParser) -> None:
    add_arguments(parser, ENGINE, "CEMNet engine (defaults: the paper's; docs/evaluation.md)")


def config_from_args(args: argparse.Namespace) -> RegistrationConfig:
    """The :class:`RegistrationConfig` the engine flags describe (ValueError on inconsistent values)."""
    return build(RegistrationConfig(), parsed_overrides(args, ENGINE))
