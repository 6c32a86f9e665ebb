"""The launch file's decisions as plain code (testable without ``launch``): whether to start RViz2, which Fast
DDS profile the processes get, whether the node is the lifecycle one and the launch file brings it up.

``rviz:=auto`` (the default) starts RViz2 only where it is installed, so that the default launch works on a
headless robot or in a container; ``rviz:=true`` asks for it and fails before anything starts when it is missing.
"""
from __future__ import annotations

import os
from typing import Optional

TRUE, FALSE = ("true", "1", "yes", "on"), ("false", "0", "no", "off")
# `ros2 launch` refuses an empty `name:=`: these spell "no profile" on a command line.
NO_PROFILE = ("", "''", '""', "none")


class LaunchChoiceError(ValueError):
    """A launch argument that cannot be honoured; the message says which and what to do."""


def rviz_wanted(value: str, installed: bool) -> bool:
    """Start RViz2? ``value`` is the ``rviz`` argument (auto, true or false), ``installed`` whether the rviz2
    package is found; raises LaunchChoiceError for ``true`` without RViz2 or an unknown value."""
    choice = value.strip().lower()
    if choice == "auto":
        return installed
    if choice in FALSE:
        return False
    if choice not in TRUE:
        raise LaunchChoiceError(f"rviz:={value!r}: expected auto, true or false")
    if not installed:
        raise LaunchChoiceError("rviz:=true but the rviz2 package is not installed (apt install ros-jazzy-rviz2, "
                                "or rviz:=auto / rviz:=false to run without it); nothing was started")
    return True


def dds_profile_file(value: str) -> Optional[str]:
    """The FASTRTPS_DEFAULT_PROFILES_FILE to set from the ``dds_profile`` argument, None to unset it (Fast DDS
    reads an empty value as a file name and prints an XML parser error); raises LaunchChoiceError for a file
    that does not exist."""
    path = value.strip()
    if path.lower() in NO_PROFILE:
        return None
    if not os.path.isfile(path):
        raise LaunchChoiceError(f"dds_profile:={value}: no such file (dds_profile:=none for Fast DDS's defaults); "
                                "nothing was started")
    return path


def _flag(name: str, value: str) -> bool:
    choice = value.strip().lower()
    if choice not in TRUE + FALSE:
        raise LaunchChoiceError(f"{name}:={value!r}: expected true or false")
    return choice in TRUE


def lifecycle_wanted(lifecycle: str, autostart: str) -> tuple[bool, bool]:
    """(start align_lifecycle_node instead of align_node, configure and activate it from the launch file) from the
    ``lifecycle`` and ``autostart`` arguments; autostart means nothing without lifecycle. LaunchChoiceError for a
    value that is not true or false."""
    managed, bring_up = _flag("lifecycle", lifecycle), _flag("autostart", autostart)
    return managed, managed and bring_up
