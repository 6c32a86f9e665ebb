"""Training checkpoints in the project's safe .npz format (never pickle).

``<name>.npz`` holds the network weights + metadata (loadable by :func:`cemnet_ros.core.checkpoint.load_network`);
``<name>_optim.npz`` holds the optimiser's tensors, with its hyper-parameters in the JSON metadata. Both carry
the epoch and global step, so a resume notices a pair that does not belong together.
"""
from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import torch

from cemnet_ros.core.checkpoint import load_weights, save_weights


def optimizer_path(weights_path: Path) -> Path:
    """``last.npz`` -> ``last_optim.npz``."""
    return weights_path.with_name(weights_path.stem + "_optim.npz")


def save_optimizer(path: Path, optimizer: torch.optim.Optimizer, meta: dict[str, Any]) -> Path:
    """Write the optimiser state: tensors as ``<param index>/<key>``, everything else as JSON."""
    state = optimizer.state_dict()
    tensors, scalars = {}, {}
    for index, entries in state["state"].items():
        for key, value in entries.items():
            if torch.is_tensor(value):
                tensors[f"{index}/{key}"] = value
            else:
                scalars[f"{index}/{key}"] = value
    if not tensors:  # save_weights insists on at least one array (a fresh optimiser has no state yet)
        tensors["__empty__"] = torch.zeros(0)
    return save_weights(path, tensors, dict(meta, param_groups=state["param_groups"], scalars=scalars))


def restore_optimizer(optimizer: torch.optim.Optimizer, tensors: dict[str, torch.Tensor], meta: dict[str, Any]
                      ) -> None:
    """Load into ``optimizer`` the (tensors, meta) that :func:`save_optimizer` wrote."""
    state: dict[int, dict[str, Any]] = {}
    entries = [(name, value) for name, value in tensors.items() if name != "__empty__"]
    for name, value in entries + list(meta.get("scalars", {}).items()):
        index, key = name.split("/", 1)
        state.setdefault(int(index), {})[key] = value
    groups = meta["param_groups"]
    for group in groups:  # JSON turned tuples into lists
        if "betas" in group:
            group["betas"] = tuple(group["betas"])
    optimizer.load_state_dict({"state": state, "param_groups": groups})


def save_checkpoint(path: Path, network: torch.nn.Module, optimizer: torch.optim.Optimizer | None,
                    meta: dict[str, Any]) -> Path:
    """Weights (+ optimiser when given) of ``network``; the optimiser file is written first, so the weights
    file, written last, is the commit point."""
    if optimizer is not None:
        save_optimizer(optimizer_path(path), optimizer, {"epoch": meta["epoch"], "global_step": meta["global_step"]})
    return save_weights(path, network.state_dict(), meta)


def load_checkpoint(path: Path, network: torch.nn.Module, optimizer: torch.optim.Optimizer | None = None
                    ) -> dict[str, Any]:
    """Load weights into ``network`` (strict) and, when given, the matching optimiser state; returns meta.

    A missing or mismatched optimiser file only warns: training then continues with fresh Adam moments.
    """
    state, meta = load_weights(path)
    network.load_state_dict(state)
    if optimizer is None:
        return meta
    opt_path = optimizer_path(path)
    if not opt_path.is_file():
        warnings.warn(f"{opt_path} missing: resuming with a fresh optimiser state")
        return meta
    tensors, opt_meta = load_weights(opt_path)
    if (opt_meta.get("epoch"), opt_meta.get("global_step")) != (meta.get("epoch"), meta.get("global_step")):
        warnings.warn(f"{opt_path} belongs to another step than {path}: resuming with a fresh optimiser state")
        return meta
    restore_optimizer(optimizer, tensors, opt_meta)
    return meta
