"""Declaring the node's parameters from the schema, and turning every bad one into one clear line."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.node import Node

from cemnet_ros.core.weight_files import NAMED_WEIGHTS
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.ros.node_config import NodeConfig, configs_from_parameters, node_parameters


class ConfigError(ValueError):
    """A parameter (or the weights file it names) the node cannot start with; the message is the whole story."""


def descriptor(p: Any) -> ParameterDescriptor:
    """Read-only unless the schema marks it dynamic (the save paths), with the schema's help, range and choices
    (``ros2 param describe`` shows them)."""
    out = ParameterDescriptor(description=p.describe(), read_only=not p.dynamic)
    if p.low is not None or p.high is not None:
        low, high = (-1e300 if p.low is None else p.low), (1e300 if p.high is None else p.high)
        if p.kind is int:
            out.integer_range = [IntegerRange(from_value=int(low), to_value=int(min(high, 2 ** 31 - 1)), step=1)]
        elif p.kind is float:
            out.floating_point_range = [FloatingPointRange(from_value=float(low), to_value=float(high))]
    if p.choices:
        out.additional_constraints = "one of: " + ", ".join(p.choices)
    return out


def declare_and_read(node: Node) -> tuple[NodeConfig, AlignerConfig]:
    """Declare every parameter, read them into the two configs; ConfigError names the bad one."""
    declare(node)
    return read(node)


def declare(node: Node) -> None:
    """Declare every parameter of the schema (an override of the wrong type: ConfigError)."""
    for name, p in node_parameters().items():
        try:
            node.declare_parameter(name, list(p.default) if p.kind is tuple else p.default, descriptor(p))
        except ParameterException as exc:
            allowed = f" (allowed: {p.describe()})"
            raise ConfigError(f"parameter {name}: {str(exc).splitlines()[0]}{allowed}") from None


def read(node: Node) -> tuple[NodeConfig, AlignerConfig]:
    """The declared parameters as the two configs; ConfigError names a bad value or weights file."""
    schema = node_parameters()
    try:
        node_cfg, pipeline = configs_from_parameters({n: node.get_parameter(n).value for n in schema})
    except (ValueError, TypeError) as exc:
        raise ConfigError(str(exc).splitlines()[0]) from None
    check_weights(node, pipeline)
    return node_cfg, pipeline


def check_weights(node: Node, pipeline: AlignerConfig) -> None:
    """A weights path that does not exist is fatal where the network is used, a warning where it is not."""
    for name, weights, user, choice in (
            ("registration.weights", pipeline.registration.weights, "tracking.centre", pipeline.tracking.centre),
            ("recovery.weights", pipeline.recovery.weights, "recovery.scatter", pipeline.recovery.scatter)):
        if weights in NAMED_WEIGHTS:
            continue
        used = choice == "network"
        if not Path(weights).is_file():
            if used:
                raise ConfigError(f"parameter {name}: no such file {weights!r} ({user} is 'network'; '' = the "
                                  "package's weights, 'official' = the official checkpoint, 'scan' = the package's "
                                  "LiDAR scan weights)")
            node.get_logger().warn(f"{name} {weights!r} does not exist; it is not used either ({user} is {choice!r})")
        elif not used:
            node.get_logger().warn(f"{name} {weights!r} is not used: {user} is {choice!r}, not 'network'")
