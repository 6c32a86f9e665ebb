"""The pipeline's two CEMs by preset and its one seed: what reaches the tracking registrar and the global search."""
from __future__ import annotations

import numpy as np
import pytest

from cemnet_ros.core.config import CEMConfig, EngineConfig
from cemnet_ros.pipeline import aligner as aligner_module
from cemnet_ros.pipeline.cem_presets import CEM_PRESETS, cem_preset
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.steps import metric_cem
from cemnet_ros.pipeline.steps.frame import Frame
from cemnet_ros.schema import build

TRACKING = CEMConfig(n_candidates=100, n_iters=2, n_fused_iters=0, lattice_spacing=0.5, seed=0)
REFINE = CEMConfig(n_candidates=100, n_iters=5, n_fused_iters=2, seed=0)


def test_the_default_presets_are_the_tracking_and_refine_cems():
    config = AlignerConfig()
    assert (config.registration.cem_preset, config.recovery.search.refine_preset) == ("tracking", "refine")
    assert config.tracking_engine() == EngineConfig(n_points=512, cem=TRACKING, seed=0)
    assert config.global_search().refine == REFINE
    assert cem_preset("paper", 0) == CEMConfig()  # N 1000, T 10, M 3
    assert all(preset.purpose for preset in CEM_PRESETS.values())


def test_a_preset_changes_the_cem_and_nothing_else():
    config = build(AlignerConfig(), {"registration.cem_preset": "paper", "recovery.search.refine_preset": "tracking"})
    engine, search = config.tracking_engine(), config.global_search()
    assert engine == EngineConfig(n_points=512, cem=CEMConfig(), seed=0)
    assert search.refine == TRACKING
    assert search.n_scatter == AlignerConfig().global_search().n_scatter


@pytest.mark.parametrize("seed", [7, -1])
def test_one_seed_sets_the_sub_sampling_and_both_cems(seed):
    config = build(AlignerConfig(), {"seed": seed})
    engine = config.tracking_engine()
    assert (engine.seed, engine.cem.seed, config.global_search().refine.seed) == (seed, seed, seed)


def test_the_aligners_registrar_gets_the_preset_and_the_seed(monkeypatch):
    built = []
    monkeypatch.setattr(aligner_module, "Registrar", built.append)
    aligner_module.ScanAligner(build(AlignerConfig(), {"registration.cem_preset": "refine", "seed": 5}))
    (config,) = built
    assert config.cem == cem_preset("refine", 5) and config.seed == 5 and config.n_points == 512
    assert config.prior == "identity"  # tracking.centre 'motion': the CEM is centred on the prediction


def test_the_global_search_gets_the_refine_preset_and_the_seed(monkeypatch):
    searched = []

    def fake_search(source, target, centre, radius, config, seed, prior):
        searched.append((config, seed))
        return []

    monkeypatch.setattr(metric_cem, "global_search", fake_search)
    config = build(AlignerConfig(), {"recovery.search.refine_preset": "paper", "seed": 4})
    points = np.random.default_rng(0).uniform(-5.0, 5.0, (2000, 3))
    frame = Frame(points, points, points[:512], points, scale=5.0, voxel=0.1)
    assert metric_cem.MetricEngine(config, registrar=None).search(frame, points, 0.3, np.eye(4), effort=1.0) == []
    ((search, seed),) = searched
    assert search.refine == cem_preset("paper", 4) and seed == 4
