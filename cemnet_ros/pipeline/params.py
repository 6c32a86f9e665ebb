"""Flat parameter names (ROS parameters, YAML files, command-line flags) -> the pipeline's typed config.

One mapping for the node and the offline replay, so the two cannot drift apart. Names are looked up in
AlignerConfig, then RegistrationConfig, then CEMConfig (the outermost level wins a shared name such as ``prior``).
"""
from __future__ import annotations

import dataclasses
from dataclasses import fields
from typing import Any

from .config import AlignerConfig


def aligner_config_from_params(params: dict[str, Any]) -> AlignerConfig:
    """AlignerConfig from flat parameter names (ROS parameters, YAML, CLI flags); names it does not know are ignored."""
    base = AlignerConfig()
    known = _all_names(base)
    values = {k: v for k, v in params.items() if k in known}
    if values.get("weights") == "":  # ROS parameter files cannot hold None: '' = package weights
        values["weights"] = None
    if "n_iters" in values:  # n_iters 2 alone stays valid: the fused iterations are clamped to it
        fused = values.get("n_fused_iters", base.registration.cem.n_fused_iters)
        values["n_fused_iters"] = min(int(fused), int(values["n_iters"]))
    return _apply(base, values, "AlignerConfig")


def _apply(obj: Any, values: dict[str, Any], where: str) -> Any:
    """dataclasses.replace with nested names resolved: AlignerConfig -> .registration -> .registration.cem."""
    own = {f.name for f in fields(obj)}
    mine = {k: v for k, v in values.items() if k in own and not dataclasses.is_dataclass(getattr(obj, k))}
    rest = {k: v for k, v in values.items() if k not in mine}
    nested = {}
    for f in fields(obj):
        child = getattr(obj, f.name)
        if dataclasses.is_dataclass(child):
            sub = dict(rest.pop(f.name, {}) or {})
            names = _all_names(child)
            sub.update({k: rest.pop(k) for k in list(rest) if k in names})
            if sub:
                nested[f.name] = _apply(child, sub, f"{where}.{f.name}")
    if rest:
        raise ValueError(f"unknown {where} parameter(s): {sorted(rest)}")
    for k, v in mine.items():
        if isinstance(getattr(obj, k), tuple) and isinstance(v, list):
            mine[k] = tuple(v)
    return dataclasses.replace(obj, **mine, **nested)


def _all_names(obj: Any) -> set[str]:
    names = set()
    for f in fields(obj):
        names.add(f.name)
        child = getattr(obj, f.name)
        if dataclasses.is_dataclass(child):
            names |= _all_names(child)
    return names
