"""The package's RViz view for one launch: the topics and the fixed frame of the node that this launch starts.

``rviz/cemnet_ros.rviz`` names the topics of a node started at the root, with the defaults
(``/align_node/odometry``, ``/points``, fixed frame ``odom``). Under a namespace (``PushRosNamespace``, an including
launch file), with another ``input_topic`` or ``odom_frame``, those displays would stay empty. The launch file
hands RViz2 a copy in which every topic is the absolute name the node resolves (its namespace, ``~``, relative
names), written to a temporary file. Absolute names, so the copy does not depend on how RViz2 resolves a relative
display topic; remaps in force where RViz2 is started (``SetRemap``) apply to RViz2's subscriptions as to the
node's, since launch_ros hands them to every node it starts. Plain code (PyYAML): tested without ``launch``.
"""
from __future__ import annotations

import os
import tempfile
from typing import Any, Iterator, Optional

import yaml

NODE_NAME = "align_node"
TEMPLATE_NODE = "/" + NODE_NAME  # the node's full name in the shipped view
TEMPLATE_INPUT = "/points"  # the input topic in the shipped view (input_topic's default, at the root)


def resolve_topic(name: str, namespace: Optional[str], node_name: str = NODE_NAME) -> str:
    """``name`` as a node ``node_name`` in ``namespace`` (None or '' = the root) resolves it: absolute names kept,
    ``~`` the node's full name, relative names under the namespace."""
    ns = "/" + (namespace or "").strip("/")
    base = ns.rstrip("/")
    if name.startswith("/"):
        return name
    if name == "~" or name.startswith("~/"):
        return f"{base}/{node_name}{name[1:]}"
    return f"{base}/{name}"


def resolved_config(text: str, namespace: Optional[str], input_topic: str, odom_frame: str,
                    node_name: str = NODE_NAME) -> str:
    """The shipped view (``text``) with the node's topics under ``namespace``, ``input_topic`` for the input
    display and ``odom_frame`` as the fixed frame."""
    config = yaml.safe_load(text)
    node = resolve_topic("~", namespace, node_name)
    for display in _displays(config["Visualization Manager"]):
        topic = display.get("Topic")
        if not isinstance(topic, dict) or not isinstance(topic.get("Value"), str):
            continue
        value = topic["Value"]
        if value == TEMPLATE_INPUT:
            topic["Value"] = resolve_topic(input_topic, namespace, node_name)
        elif value.startswith(TEMPLATE_NODE + "/"):
            topic["Value"] = node + value[len(TEMPLATE_NODE):]
    config["Visualization Manager"]["Global Options"]["Fixed Frame"] = odom_frame
    return yaml.safe_dump(config, sort_keys=False, default_flow_style=False)


def _displays(group: dict) -> Iterator[dict]:
    """Every display of a view, those inside display groups included."""
    for display in group.get("Displays") or []:
        yield display
        yield from _displays(display)


def topics(text: str) -> dict[str, str]:
    """A view's display name -> its topic (displays with a topic)."""
    config: Any = yaml.safe_load(text)
    return {d["Name"]: d["Topic"]["Value"] for d in _displays(config["Visualization Manager"])
            if isinstance(d.get("Topic"), dict)}


def write_resolved_config(template_path: str, namespace: Optional[str], input_topic: str, odom_frame: str) -> str:
    """:func:`resolved_config` of the file ``template_path`` written to a new temporary ``.rviz`` file; its path.
    (RViz2's "Save Config" writes back to it: "Save Config As" keeps a view.)"""
    with open(template_path, encoding="utf-8") as handle:
        text = resolved_config(handle.read(), namespace, input_topic, odom_frame)
    label = (namespace or "").strip("/").replace("/", "_")
    fd, path = tempfile.mkstemp(prefix=f"cemnet_ros_{label + '_' if label else ''}", suffix=".rviz")
    with os.fdopen(fd, "w", encoding="utf-8") as handle:
        handle.write(text)
    return path
