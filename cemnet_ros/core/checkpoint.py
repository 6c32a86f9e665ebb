"""Weights on disk: the project's safe .npz format and the official (pickled) .pth checkpoints.

The project's format is a NumPy ``.npz`` read with ``allow_pickle=False``: tensors under ``param/<name>``
plus a JSON metadata string, so loading never executes code. The official checkpoints are legacy torch
pickles; they load only with an explicit ``allow_pickle=True`` and even then through torch's restricted
``weights_only`` unpickler.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch

from ..io.atomic import atomic_file
from .network import SamplingNetwork
from .weight_files import DEFAULT_WEIGHTS, NAMED_WEIGHTS, OFFICIAL_WEIGHTS, SCAN_WEIGHTS  # noqa: F401 (importers')

_OFFICIAL_PREFIXES = (("coarse_policy.emb_nn.", "embedding."), ("coarse_policy.nn.", "sigma_head."))
_OFFICIAL_IGNORED = ("coarse_policy.reflect",)


class CheckpointError(RuntimeError):
    """A weights file is missing, corrupt, unsafe to load, or does not fit the network."""


def save_weights(path: str | os.PathLike, state_dict: Mapping[str, torch.Tensor], meta: Mapping[str, Any] | None = None
                 ) -> Path:
    """Write ``state_dict`` (+ JSON-serialisable ``meta``) to ``path`` atomically in the safe .npz format."""
    path = Path(path)
    arrays = {f"param/{k}": v.detach().cpu().numpy() for k, v in state_dict.items()}
    arrays["__meta__"] = np.frombuffer(json.dumps(dict(meta or {})).encode(), dtype=np.uint8)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as handle:
        np.savez(handle, **arrays)  # type: ignore[arg-type]  # numpy stubs: the first keyword is allow_pickle
    return path


def _load_npz(path: Path) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    try:
        with np.load(path, allow_pickle=False) as data:
            state = {k[len("param/"):]: torch.from_numpy(data[k].copy()) for k in data.files if k.startswith("param/")}
            meta = json.loads(bytes(data["__meta__"]).decode()) if "__meta__" in data.files else {}
    except Exception as exc:  # zipfile/ValueError/OSError: all mean a corrupt file
        raise CheckpointError(f"cannot read weights {path}: {exc}") from exc
    if not state:
        raise CheckpointError(f"{path} holds no parameters (expected 'param/<name>' arrays)")
    return state, meta


def _load_official(path: Path) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    try:
        raw = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        raise CheckpointError(f"cannot read checkpoint {path} with the restricted unpickler: {exc}") from exc
    if not isinstance(raw, Mapping):
        raise CheckpointError(f"{path} is not a state dict")
    state = {}
    for key, value in raw.items():
        if key in _OFFICIAL_IGNORED:
            continue
        for old, new in _OFFICIAL_PREFIXES:
            if key.startswith(old):
                state[new + key[len(old):]] = value
                break
        else:
            raise CheckpointError(f"{path}: unexpected key {key!r} (not an official CEMNet checkpoint)")
    return state, {"source": "official", "file": path.name}


def load_weights(path: str | os.PathLike, allow_pickle: bool = False) -> tuple[dict[str, torch.Tensor], dict]:
    """Read a state dict: ``.npz`` (safe) or an official ``.pth`` (needs ``allow_pickle=True``)."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"weights file not found: {path}")
    if path.suffix == ".npz":
        return _load_npz(path)
    if path.suffix in (".pth", ".pt"):
        if not allow_pickle:
            raise CheckpointError(
                f"{path} is a pickle; loading it needs an explicit opt-in (allow_pickle=True / --allow-pickle). "
                "Convert it once with `cemnet-convert-weights` to the safe .npz format.")
        return _load_official(path)
    raise CheckpointError(f"unknown weights format {path.suffix!r} (expected .npz or .pth)")


def load_network(path: str | os.PathLike | None = None, allow_pickle: bool = False) -> SamplingNetwork:
    """A :class:`SamplingNetwork` with weights from ``path``: a file, None or "" (the package's default weights),
    ``"official"`` (the official ModelNet40 clean checkpoint, converted) or ``"scan"`` (the package's LiDAR scan
    weights), all shipped in the package."""
    name = "" if path is None else os.fspath(path)
    state, _ = load_weights(NAMED_WEIGHTS.get(name, name), allow_pickle)
    network = SamplingNetwork()
    try:
        missing, unexpected = network.load_state_dict(state, strict=False)
    except RuntimeError as exc:  # shape mismatches
        raise CheckpointError(f"weights do not fit the network: {exc}") from exc
    if missing or unexpected:
        raise CheckpointError(f"weights do not fit the network: missing {missing[:5]}, unexpected {unexpected[:5]}")
    return network
