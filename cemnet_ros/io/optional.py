"""Optional libraries, imported where they are used, with a message that says what needs them and how to get them.

matplotlib (the replay figure, the training curves) and Pillow (7-Scenes depth PNGs) serve the tools, not the node: a
headless robot's ROS install (package.xml, rosdep) goes without them, and a missing one costs only its own output.
"""
from __future__ import annotations

import importlib
from types import ModuleType

# top-level module -> (Debian/rosdep package, pip distribution)
INSTALL = {"matplotlib": ("python3-matplotlib", "matplotlib"), "PIL": ("python3-pil", "pillow")}


class MissingOptional(ImportError):
    """An optional library that does not import; the message names what needs it and how to install it."""


def optional_module(name: str, needed_for: str) -> ModuleType:
    """``import name``, or MissingOptional: "<needed_for> needs <library> ...: sudo apt install ... or pip ..."."""
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        top = name.split(".")[0]
        apt, pip = INSTALL[top]
        raise MissingOptional(f"{needed_for} needs {top}, which does not import ({exc}): sudo apt install {apt} "
                              f"(a ROS install) or python3 -m pip install {pip}") from None
