"""Training data: shape pairs reproducible per epoch and fixed for validation, duplicates dropped, seeded splits,
scan folders, the real subset's held-out shapes."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from shared_data import MODELNET, requires_shared
from tiny_training import TINY, box_union_shapes

from cemnet_ros.eval.protocol import ProtocolConfig
from cemnet_ros.train.config import TrainConfig
from cemnet_ros.train.data import PairDataset, build_datasets, drop_duplicates, load_scan_shapes, split_train_val


def test_pairs_reproducible_per_epoch_and_fixed_for_validation():
    shapes = box_union_shapes(3, TINY.n_points, seed=2)
    train, val = PairDataset(shapes, TINY, seed=9), PairDataset(shapes, TINY, seed=9, fixed=True)
    train.set_epoch(1)
    a = train[1]
    assert a["source"].shape == (TINY.n_partial, 3) and a["rotation"].shape == (3, 3)
    again = PairDataset(shapes, TINY, seed=9)
    again.set_epoch(1)
    assert torch.equal(a["source"], again[1]["source"]) and torch.equal(a["rotation"], again[1]["rotation"])
    train.set_epoch(2)
    assert not torch.equal(a["rotation"], train[1]["rotation"])  # a new pose every epoch
    v1 = val[0]["rotation"]
    val.set_epoch(7)
    assert torch.equal(v1, val[0]["rotation"])  # validation pairs never change
    # target ~= R source + t holds for the full (uncropped, noise-free) protocol
    full = PairDataset(shapes, ProtocolConfig(n_points=TINY.n_points, partial=False), seed=9)[0]
    moved = full["source"].double() @ full["rotation"].double().T + full["translation"].double()
    d = torch.cdist(moved, full["target"].double()).min(1).values
    assert d.max() < 1e-5


def test_duplicate_shapes_are_dropped():
    shapes = box_union_shapes(3, 40, seed=0)
    with pytest.warns(UserWarning, match="1 exact duplicate"):
        kept = drop_duplicates(np.concatenate([shapes, shapes[1:2]]))
    assert np.array_equal(kept, shapes)


def test_split_is_disjoint_and_seeded():
    train, val = split_train_val(50, 0.1, seed=3)
    assert len(val) == 5 and len(train) == 45 and not set(train) & set(val)
    assert np.array_equal(val, split_train_val(50, 0.1, seed=3)[1])
    with pytest.raises(ValueError):
        split_train_val(1, 0.1, seed=3)


def test_scan_folder_is_normalised_and_bad_files_are_skipped(tmp_path):
    rng = np.random.default_rng(0)
    for i in range(3):
        np.save(tmp_path / f"scan{i}.npy", rng.normal(size=(500, 3)) * 20.0 + 100.0)
    np.save(tmp_path / "tiny.npy", rng.normal(size=(10, 3)))
    (tmp_path / "notes.txt").write_text("ignored")
    with pytest.warns(UserWarning, match="tiny.npy"):
        shapes, files = load_scan_shapes(tmp_path, 200, seed=1, progress=False)
    assert shapes.shape == (3, 200, 3) and [f.name for f in files] == ["scan0.npy", "scan1.npy", "scan2.npy"]
    assert np.allclose(shapes.mean(1), 0.0, atol=1e-5)
    assert np.allclose(np.linalg.norm(shapes, axis=2).max(1), 1.0, atol=1e-5)
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no scans"):
        load_scan_shapes(tmp_path / "empty", 200, seed=1, progress=False)


@requires_shared(MODELNET)
def test_real_subset_holds_out_train_shapes_only():
    config = TrainConfig(data=str(MODELNET), progress=False)
    with pytest.warns(UserWarning, match="3 exact duplicate"):  # the subset repeats 3 bench shapes as 'airplane'
        train, val = build_datasets(config)
    assert len(train) + len(val) == 283 and len(val) == 28  # the train split only; test stays untouched
    assert not {s.tobytes() for s in train.shapes} & {s.tobytes() for s in val.shapes}
