"""The ModelNet40 pair protocol: ranges, geometry, crop, noise, seeding, and shape archives."""
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from shared_data import MODELNET, requires_shared

from cemnet_ros.data.shapes import bracket_shape
from cemnet_ros.eval.protocol import ProtocolConfig, load_shapes, make_pair, protocol_pairs

SHAPE = bracket_shape(2048, seed=3)
EXACT = ProtocolConfig(partial=False, noise=False)


def _nn_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return cKDTree(b).query(a)[0]


def test_angles_and_translation_within_range():
    for i in range(50):
        pair = make_pair(SHAPE, np.random.default_rng(i), ProtocolConfig())
        assert np.all(pair.euler_zyx >= 0) and np.all(pair.euler_zyx <= np.radians(45.0))
        assert np.all(np.abs(pair.translation) <= 0.5)
        np.testing.assert_allclose(pair.rotation, Rotation.from_euler("zyx", pair.euler_zyx).as_matrix())
        np.testing.assert_allclose(pair.rotation.T @ pair.rotation, np.eye(3), atol=1e-12)


def test_target_is_rotated_source_before_crop_and_noise():
    pair = make_pair(SHAPE, np.random.default_rng(0), EXACT)
    assert pair.source.shape == pair.target.shape == (1024, 3)
    assert pair.source.dtype == pair.target.dtype == np.float32
    moved = pair.source.astype(np.float64) @ pair.rotation.T + pair.translation
    assert _nn_distance(moved, pair.target).max() < 1e-5
    # the same set of points as the shape's first 1024 (just shuffled)
    assert _nn_distance(pair.source, SHAPE[:1024]).max() == 0.0
    # the opposite direction would be wrong: R^T (x - t) does not land on the target
    wrong = (pair.source.astype(np.float64) - pair.translation) @ pair.rotation
    assert _nn_distance(wrong, pair.target).mean() > 0.01


def test_shuffled_without_index_correspondence():
    pair = make_pair(SHAPE, np.random.default_rng(1), EXACT)
    moved = pair.source.astype(np.float64) @ pair.rotation.T + pair.translation
    assert np.linalg.norm(moved - pair.target, axis=1).mean() > 0.1
    assert not np.array_equal(pair.source, SHAPE[:1024])


def _kept_mask(full: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """Which rows of ``full`` are (up to float32 rounding) in ``kept``."""
    return _nn_distance(full, kept) < 1e-5


def _margin(full: np.ndarray, mask: np.ndarray, direction: np.ndarray) -> float:
    """min projection of the kept points minus max projection of the dropped ones (> 0: a half-space cut)."""
    proj = full @ direction
    return float(proj[mask].min() - proj[~mask].max())


def test_partial_crop_same_far_point_in_each_frame():
    full = SHAPE[:1024].astype(np.float64)
    for seed in range(6):
        pair = make_pair(SHAPE, np.random.default_rng(seed), ProtocolConfig())
        assert pair.source.shape == pair.target.shape == (768, 3)
        full_target = full @ pair.rotation.T + pair.translation
        src_mask, tgt_mask = _kept_mask(full, pair.source), _kept_mask(full_target, pair.target)
        assert src_mask.sum() == tgt_mask.sum() == 768
        # reference far point +-500 (1, 1, 1): both crops are (nearly) half-space cuts normal to the diagonal,
        # each in its own frame, with the same sign
        diagonal = np.ones(3) / np.sqrt(3.0)
        sign = 1.0 if _margin(full, src_mask, diagonal) > _margin(full, src_mask, -diagonal) else -1.0
        assert _margin(full, src_mask, sign * diagonal) > -0.01
        assert _margin(full_target, tgt_mask, sign * diagonal) > -0.01
        # so the target's crop is a different part of the object than the source's
        assert 0.4 < np.mean(src_mask & tgt_mask) / np.mean(src_mask) < 1.0


def test_partial_crop_sphere_far_point():
    full = SHAPE[:1024].astype(np.float64)
    pair = make_pair(SHAPE, np.random.default_rng(3), ProtocolConfig(far_point="sphere"))
    mask = _kept_mask(full, pair.source)
    assert mask.sum() == 768
    directions = np.random.default_rng(0).normal(size=(20000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    margins = [_margin(full, mask, d) for d in directions]
    assert max(margins) > -0.02  # a half-space cut along some direction...
    assert _margin(full, mask, np.ones(3) / np.sqrt(3)) < -0.05  # ...not the reference's diagonal here
    with pytest.raises(ValueError, match="far_point"):
        ProtocolConfig(far_point="north")


def test_noise_is_clipped_independent_and_after_crop():
    cfg = ProtocolConfig(partial=False, noise=True)
    clean = make_pair(SHAPE, np.random.default_rng(4), EXACT)
    noisy = make_pair(SHAPE, np.random.default_rng(4), cfg)
    # same rng stream up to the noise: same transform and same shuffles
    np.testing.assert_array_equal(clean.rotation, noisy.rotation)
    d_src = noisy.source.astype(np.float64) - clean.source
    d_tgt = noisy.target.astype(np.float64) - clean.target
    assert np.abs(d_src).max() <= 0.05 + 1e-6 and np.abs(d_tgt).max() <= 0.05 + 1e-6
    assert 0.008 < d_src.std() < 0.012
    assert abs(np.corrcoef(d_src.ravel(), d_tgt.ravel())[0, 1]) < 0.1
    partial = make_pair(SHAPE, np.random.default_rng(4), replace(cfg, partial=True))
    assert partial.source.shape == (768, 3)


def test_seeded_reproducibility_and_pairs_differ():
    cfg = ProtocolConfig(noise=True)
    shapes = np.stack([SHAPE, bracket_shape(2048, seed=9)])
    first = list(protocol_pairs(shapes, cfg))
    again = list(protocol_pairs(shapes, cfg))
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a.source, b.source)
        np.testing.assert_array_equal(a.target, b.target)
    direct = make_pair(shapes[1], np.random.default_rng(1), cfg)
    np.testing.assert_array_equal(direct.target, first[1].target)
    shifted = list(protocol_pairs(shapes, cfg, seed_offset=1))
    np.testing.assert_array_equal(shifted[0].euler_zyx, direct.euler_zyx)
    assert not np.allclose(first[0].euler_zyx, first[1].euler_zyx)


def test_bad_shapes_and_config():
    with pytest.raises(ValueError, match="needs n_points=1024"):
        make_pair(SHAPE[:500], np.random.default_rng(0), ProtocolConfig())
    with pytest.raises(ValueError, match=r"\(m, 3\+\)"):
        make_pair(SHAPE[:, :2], np.random.default_rng(0), ProtocolConfig())
    bad = SHAPE.copy()
    bad[5, 0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        make_pair(bad, np.random.default_rng(0), ProtocolConfig())
    with pytest.raises(ValueError, match="n_partial"):
        ProtocolConfig(n_partial=2000)
    small = make_pair(SHAPE, np.random.default_rng(0), ProtocolConfig(n_points=64, n_partial=48))
    assert small.source.shape == (48, 3)


def _archive(tmp_path, split, labels=None, name="shapes.npz"):
    points = np.stack([bracket_shape(64, seed=i) for i in range(len(split))])
    arrays = {"points": points, "split": np.asarray(split)}
    if labels is not None:
        arrays["labels"] = np.asarray(labels)
    np.savez(tmp_path / name, **arrays)
    return tmp_path / name, points


@pytest.mark.parametrize("split_values", [["train", "test", "train", "test"], [0, 1, 0, 1]])
def test_load_shapes_splits_and_unseen(tmp_path, split_values):
    path, points = _archive(tmp_path, split_values, labels=[3, 25, 21, 4])
    test, labels = load_shapes(path, "test")
    np.testing.assert_array_equal(test, points[[1, 3]])
    np.testing.assert_array_equal(labels, [25, 4])
    train, labels = load_shapes(path, "train", unseen=True)
    np.testing.assert_array_equal(labels, [3])
    _, labels = load_shapes(path, "test", unseen=True)
    np.testing.assert_array_equal(labels, [25])
    everything, _ = load_shapes(path, "all")
    assert everything.shape == (4, 64, 3) and everything.dtype == np.float32


def test_load_shapes_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_shapes(tmp_path / "missing.npz")
    (tmp_path / "junk.npz").write_bytes(b"garbage")
    with pytest.raises(ValueError, match="cannot read"):
        load_shapes(tmp_path / "junk.npz")
    np.savez(tmp_path / "nopoints.npz", xyz=np.zeros((2, 4, 3)))
    with pytest.raises(ValueError, match="no 'points'"):
        load_shapes(tmp_path / "nopoints.npz")
    np.savez(tmp_path / "flat.npz", points=np.zeros((4, 3)), split=np.array(["test"] * 4))
    with pytest.raises(ValueError, match=r"\(S, m, 3\+\)"):
        load_shapes(tmp_path / "flat.npz")
    path, _ = _archive(tmp_path, ["train", "valid"], name="odd.npz")
    with pytest.raises(ValueError, match="unknown split names"):
        load_shapes(path)
    path, _ = _archive(tmp_path, ["train", "test"], name="nolabels.npz")
    with pytest.raises(ValueError, match="labels"):
        load_shapes(path, "test", unseen=True)
    with pytest.raises(ValueError, match="split must be"):
        load_shapes(path, "val")
    np.savez(tmp_path / "nosplit.npz", points=np.zeros((2, 4, 3)))
    with pytest.raises(ValueError, match="no 'split'"):
        load_shapes(tmp_path / "nosplit.npz", "test")
    assert load_shapes(tmp_path / "nosplit.npz", "all")[0].shape == (2, 4, 3)


@requires_shared(MODELNET)
def test_real_modelnet_subset():
    test, labels = load_shapes(MODELNET, "test")
    assert test.shape == (63, 2048, 3)
    unseen, unseen_labels = load_shapes(MODELNET, "test", unseen=True)
    assert len(unseen) == 22 and unseen_labels.min() >= 20
    train, train_labels = load_shapes(MODELNET, "train", unseen=True)
    assert train_labels.max() < 20 and len(train) == 228
    pair = next(protocol_pairs(test, ProtocolConfig()))
    assert pair.source.shape == (768, 3)
