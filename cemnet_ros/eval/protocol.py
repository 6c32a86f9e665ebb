"""The paper's ModelNet40 registration protocol (as in DCP / CEMNet), seeded pair by pair.

For each shape: keep the first ``n_points`` points; draw Euler angles ``U[0, max_angle]`` per axis
(``[z, y, x]``, ``R = Rx Ry Rz``) and ``t ~ U[-max_translation, max_translation]^3``; target = R source + t;
shuffle source and target independently (no index correspondence); partial: keep in each cloud the
``n_partial`` points nearest to one far random point p (the same p, in each cloud's own frame). As in the
reference (DCP/PRNet's ``farthest_subsample_points``), p = U[0, 1)^3 + 500 s (1, 1, 1) with s = +-1, so the
crop plane is always roughly normal to the (1, 1, 1) diagonal (``far_point="reference"``, the distribution
the official checkpoints were trained on); ``far_point="sphere"`` draws p in a uniformly random direction
(not the paper's protocol; the network's initial guess is less accurate on it). Noise:
``clip(N(0, sigma), -clip, clip)`` per coordinate, drawn independently for source and target after the crop
(the reference adds it just before the crop; the difference is negligible).
Pair i is drawn from ``np.random.default_rng(seed_offset + i)`` so every method sees the same pairs.
"""
from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Optional, Tuple, Union

import numpy as np
from scipy.spatial.transform import Rotation

from cemnet_ros.schema import param, validate

# Distance of the far point that selects the partial view (unit-sphere objects: "at infinity").
_FAR_RADIUS = 500.0
FAR_POINTS = ("reference", "sphere")


@dataclass
class ProtocolConfig:
    """How a registration pair is made from one shape."""

    n_points: int = param(1024, "the first n_points of each shape are used (a scan keeps n_points random points)",
                          low=3)
    n_partial: int = param(768, "points kept per cloud by the partial crop (<= n_points)", low=3)
    max_angle_deg: float = param(45.0, "Euler angles ~ U[0, max_angle_deg] per axis (degrees)", low=0.0, high=180.0)
    max_translation: float = param(0.5, "translation ~ U[-max, max] per axis", low=0.0)
    partial: bool = param(True, "partial crop of both clouds (false = full clouds)")
    noise: bool = param(False, "clipped Gaussian noise on both clouds")
    noise_sigma: float = param(0.01, "standard deviation of the noise", low=0.0)
    noise_clip: float = param(0.05, "the noise is clipped to [-noise_clip, noise_clip]", low=0.0)
    far_point: str = param("reference", "partial crop point: 'reference' (+-500 (1, 1, 1) + U[0, 1)^3, the paper's) "
                           "or 'sphere' (a uniformly random direction)", choices=FAR_POINTS)

    def __post_init__(self) -> None:
        validate(self)
        if self.partial and self.n_partial > self.n_points:
            raise ValueError(f"n_partial must lie in [3, n_points={self.n_points}], got {self.n_partial}")


@dataclass
class RegistrationPair:
    """One test case: ``target ~= rotation @ source + translation`` (up to crop, noise and shuffling)."""

    source: np.ndarray  # (n, 3) float32
    target: np.ndarray  # (n, 3) float32
    rotation: np.ndarray  # (3, 3) float64
    translation: np.ndarray  # (3,) float64
    euler_zyx: np.ndarray  # (3,) float64, radians [z, y, x]


def make_pair(points: np.ndarray, rng: np.random.Generator, cfg: ProtocolConfig) -> RegistrationPair:
    """Make one pair from an ``(m, 3+)`` shape with ``m >= cfg.n_points``, using only ``rng``."""
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] < 3:
        raise ValueError(f"make_pair needs an (m, 3+) shape, got {points.shape}")
    if len(points) < cfg.n_points:
        raise ValueError(f"the shape has {len(points)} points, the protocol needs n_points={cfg.n_points}")
    source = points[:cfg.n_points, :3].astype(np.float64)
    if not np.isfinite(source).all():
        raise ValueError("the shape has non-finite coordinates")
    max_angle = np.radians(cfg.max_angle_deg)
    angle_x, angle_y, angle_z = rng.uniform(0.0, max_angle, size=3)  # drawn x, y, z as the reference
    euler = np.array([angle_z, angle_y, angle_x])
    translation = rng.uniform(-cfg.max_translation, cfg.max_translation, size=3)
    rotation = Rotation.from_euler("zyx", euler).as_matrix()
    target = source @ rotation.T + translation
    source = source[rng.permutation(len(source))]
    target = target[rng.permutation(len(target))]
    if cfg.partial and cfg.n_partial < cfg.n_points:
        far_point = _far_point(rng, cfg.far_point)
        source = _nearest_to(source, far_point, cfg.n_partial)
        target = _nearest_to(target, far_point, cfg.n_partial)
    if cfg.noise:
        source = source + _clipped_noise(rng, source.shape, cfg)
        target = target + _clipped_noise(rng, target.shape, cfg)
    return RegistrationPair(source.astype(np.float32), target.astype(np.float32), rotation, translation, euler)


def protocol_pairs(points: np.ndarray, cfg: ProtocolConfig, seed_offset: int = 0) -> Iterator[RegistrationPair]:
    """Pairs for an ``(S, m, 3+)`` stack of shapes; pair i uses ``np.random.default_rng(seed_offset + i)``."""
    for i, shape in enumerate(points):
        yield make_pair(shape, np.random.default_rng(seed_offset + i), cfg)


def load_shapes(npz_path: Union[str, Path], split: str = "test", unseen: bool = False
                ) -> Tuple[np.ndarray, Optional[np.ndarray]]:
    """Load ``points (S, m, 3)`` float32 and ``labels (S,)`` (or None) of one split of a shape archive.

    The archive holds ``points (S, m, 3+)``, optional ``labels (S,)`` and ``split (S,)`` (strings
    'train'/'test' or ints 0/1 = train/test). ``split='all'`` keeps every shape. ``unseen=True`` is the
    paper's unseen-categories setting: the train split keeps labels < 20, the test split labels >= 20.
    """
    if split not in ("train", "test", "all"):
        raise ValueError(f"split must be 'train', 'test' or 'all', not {split!r}")
    path = Path(npz_path)
    if not path.is_file():
        raise FileNotFoundError(f"shape archive not found: {path}")
    arrays = _read_archive(path)
    if "points" not in arrays:
        raise ValueError(f"{path}: no 'points' array (arrays: {sorted(arrays)})")
    points, labels, splits = arrays["points"], arrays.get("labels"), arrays.get("split")
    if points.ndim != 3 or points.shape[2] < 3:
        raise ValueError(f"{path}: 'points' must be (S, m, 3+), got {points.shape}")
    n_shapes = len(points)
    for name, array in (("labels", labels), ("split", splits)):
        if array is not None and array.shape != (n_shapes,):
            raise ValueError(f"{path}: '{name}' must have shape ({n_shapes},), got {array.shape}")
    keep = np.ones(n_shapes, dtype=bool)
    if split != "all":
        if splits is None:
            raise ValueError(f"{path}: has no 'split' array, so only split='all' is possible")
        keep &= _split_mask(splits, split, path)
    if unseen:
        if labels is None:
            raise ValueError(f"{path}: unseen categories need a 'labels' array")
        if split == "all":
            raise ValueError("unseen=True needs split 'train' or 'test'")
        keep &= (labels < 20) if split == "train" else (labels >= 20)
    return points[keep, :, :3].astype(np.float32), (labels[keep] if labels is not None else None)


def _read_archive(path: Path) -> dict:
    """The points/labels/split arrays of an .npz (pickle-free), with load errors as ValueError."""
    try:
        archive = np.load(path, allow_pickle=False)
        if not isinstance(archive, np.lib.npyio.NpzFile):
            raise ValueError("it is a single .npy array, not an .npz archive")
        with archive:
            return {k: np.asarray(archive[k]) for k in ("points", "labels", "split") if k in archive.files}
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{path}: cannot read the shape archive ({exc})") from None


def _split_mask(splits: np.ndarray, split: str, path: Path) -> np.ndarray:
    if splits.dtype.kind in "US":
        values = np.char.lower(np.char.strip(splits.astype(str)))
        unknown = sorted(set(values.tolist()) - {"train", "test"})
        if unknown:
            raise ValueError(f"{path}: unknown split names {unknown} (expected 'train'/'test')")
        return values == split
    if splits.dtype.kind in "iub":
        unknown = sorted(set(np.unique(splits).tolist()) - {0, 1})
        if unknown:
            raise ValueError(f"{path}: unknown split codes {unknown} (expected 0 = train, 1 = test)")
        return splits.astype(int) == (0 if split == "train" else 1)
    raise ValueError(f"{path}: 'split' array has unsupported dtype {splits.dtype}")


def _far_point(rng: np.random.Generator, kind: str) -> np.ndarray:
    if kind == "reference":
        return rng.random(3) + _FAR_RADIUS * rng.choice([-1.0, 1.0]) * np.ones(3)
    direction = rng.normal(size=3)
    return _FAR_RADIUS * direction / np.linalg.norm(direction)


def _nearest_to(points: np.ndarray, point: np.ndarray, k: int) -> np.ndarray:
    """The k points closest to ``point``, kept in their (shuffled) order."""
    distances = np.linalg.norm(points - point, axis=1)
    return points[np.sort(np.argpartition(distances, k - 1)[:k])]


def _clipped_noise(rng: np.random.Generator, shape: tuple, cfg: ProtocolConfig) -> np.ndarray:
    return np.clip(rng.normal(0.0, cfg.noise_sigma, size=shape), -cfg.noise_clip, cfg.noise_clip)
