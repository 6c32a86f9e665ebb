"""The scan pipeline's CEMs, chosen by name: the node, its params file and the replay pick each of their two CEMs
(``registration.cem_preset``, ``recovery.search.refine_preset``) from this table instead of setting a
:class:`~cemnet_ros.core.config.CEMConfig` field by field. The engine's own CLIs (cemnet-register, cemnet-eval,
training) keep every field.
"""
from __future__ import annotations

import dataclasses
from typing import Callable, NamedTuple

from cemnet_ros.core.config import CEMConfig, GlobalSearchConfig


class CEMPreset(NamedTuple):
    """A named CEM: what makes its :class:`CEMConfig` (the fields it does not set keep the paper's defaults) and
    its use."""

    make: Callable[[], CEMConfig]
    purpose: str


CEM_PRESETS: dict[str, CEMPreset] = {
    "tracking": CEMPreset(lambda: CEMConfig(n_candidates=100, n_iters=2, n_fused_iters=0, lattice_spacing=0.5),
                          "tracking around the motion prediction: a short search, without the after-ICP reward, "
                          "on a lattice of epsilon / 2 (the polish against the map gives the precision, the "
                          "global search is the wide one)"),
    "refine": CEMPreset(lambda: GlobalSearchConfig().refine,
                        "refining each hypothesis of the global search: longer, with the after-ICP reward in its "
                        "first two iterations (a hypothesis starts farther off than a prediction)"),
    "paper": CEMPreset(CEMConfig, "the paper's CEM, cemnet-register's and cemnet-eval's default: to compare the "
                       "pipeline with the method alone (50x the tracking preset's samples)"),
}
CEM_PRESET_NAMES = tuple(CEM_PRESETS)


def cem_preset(name: str, seed: int) -> CEMConfig:
    """A fresh :class:`CEMConfig` of preset ``name`` sampling with ``seed`` (-1 = unseeded)."""
    return dataclasses.replace(CEM_PRESETS[name].make(), seed=seed)
