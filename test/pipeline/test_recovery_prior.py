"""The recovery's optional network prior: configuration, plumbing through the pipeline, the benchmark's verdict."""
import dataclasses
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
from courtyard_pair import courtyard_pair

from benchmarks.metrics import relative_error
from cemnet_ros.core import Registrar
from cemnet_ros.core.checkpoint import CheckpointError
from cemnet_ros.pipeline.aligner import ScanAligner
from cemnet_ros.pipeline.config import AlignerConfig, RecoveryConfig
from cemnet_ros.pipeline.steps.metric_cem import prior_registrar
from cemnet_ros.schema import build


def _load_bench():
    """scripts/bench_recovery_prior.py as a module (the scripts are not a package)."""
    path = Path(__file__).resolve().parents[2] / "scripts" / "bench_recovery_prior.py"
    spec = importlib.util.spec_from_file_location("bench_recovery_prior", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("bench_recovery_prior", module)  # its dataclasses look their module up while built
    spec.loader.exec_module(module)
    return module


bench = _load_bench()


def test_recovery_prior_is_validated():
    assert RecoveryConfig().scatter == "uniform" and RecoveryConfig().weights == "scan"  # used once switched on
    with pytest.raises(ValueError, match="RecoveryConfig.scatter must be one of"):
        RecoveryConfig(scatter="magic")
    with pytest.raises(ValueError, match="must be one of"):
        build(AlignerConfig(), {"recovery.scatter": "magic"})
    config = build(AlignerConfig(), {"recovery.scatter": "network", "recovery.weights": "official"})
    assert config.recovery.scatter == "network" and config.recovery.weights == "official"


def test_a_prior_registrar_exists_only_for_the_network_prior(tmp_path):
    given = object()
    assert prior_registrar(AlignerConfig()) is None
    assert prior_registrar(AlignerConfig(), given) is None  # "uniform" ignores one given
    network = build(AlignerConfig(), {"recovery.scatter": "network"})
    assert prior_registrar(network, given) is given
    registrar = prior_registrar(network)
    assert isinstance(registrar, Registrar) and registrar.engine.network is not None  # the package's weights
    pickled = tmp_path / "weights.pth"
    pickled.write_bytes(b"not even a pickle")
    with pytest.raises(CheckpointError):  # a .pth needs recovery.allow_pickle
        prior_registrar(build(AlignerConfig(), {"recovery.scatter": "network", "recovery.weights": str(pickled)}))


def _first_pair_error(prior: str, oracle=None):
    """(m, deg) of the first pair's recovery with a tiny scatter (8 uniform candidates, 8 from the prior)."""
    first, second, motion = courtyard_pair()
    config = build(AlignerConfig(), {"recovery.scatter": prior, "recovery.search.n_scatter": 8,
                                     "recovery.search.n_network": 8, "recovery.search.n_seeds": 2,
                                     "recovery.search.n_per_seed": 0, "recovery.search.n_hypotheses": 2})
    aligner = ScanAligner(config, recovery_prior=oracle)
    if oracle is not None:
        oracle.aligner = aligner
    aligner.process(first, 0)
    step = aligner.process(second, 100_000_000)
    assert step.recovered and step.recovery_reason == "first pair"
    return relative_error(step.pose, motion)


def test_the_recovery_draws_part_of_its_scatter_from_the_prior():
    _, _, motion = courtyard_pair()
    sigma = np.array([0.05, 0.02, 0.02, 0.05, 0.05, 0.01])
    metres, degrees = _first_pair_error("uniform", bench.OraclePrior(motion, sigma))
    assert metres > 2.0 or degrees > 5.0  # "uniform" does not use the prior given; 8 uniform draws miss
    oracle = bench.OraclePrior(motion, sigma)
    metres, degrees = _first_pair_error("network", oracle)
    assert metres < 0.1 and degrees < 0.5 and oracle.mu0 is not None


def _summary(recall, ms, paired=None):
    return {"recall": recall, "ms_median": ms, "ms_median_ratio": ms / 1000.0,
            "ms_paired_ratio": ms / 1000.0 if paired is None else paired}


def test_the_benchmark_applies_issue_12s_criterion():
    chosen = bench.variants(2000, [0.5, 0.25], [0.25, 0.5], oracle=False, weights={"network": ""}, lean=False)
    assert [v.name for v in chosen] == ["uniform-2000", "uniform-1000", "uniform-500", "network+500",
                                        "network+1000"]
    several = bench.variants(2000, [1.0, 0.0625], [0.0625], oracle=True, weights={"a": "", "b": "scan"}, lean=True)
    assert [v.name for v in several] == [
        "uniform-2000", "uniform-125", "a+125", "b+125", "oracle+125",  # the default once, first
        "lean uniform-125", "lean a+125", "lean b+125", "lean oracle+125"]
    summary = {"uniform-2000": _summary(0.9, 1000), "uniform-1000": _summary(0.8, 700),
               "uniform-500": _summary(0.6, 500), "network+500": _summary(0.9, 450),
               "network+1000": _summary(0.85, 700)}
    pays, higher = bench.verdicts(chosen, summary)
    assert "PAYS" in pays and "0.5x" in pays  # the default's recall at 0.45x
    assert "PAYS" in higher and "uniform-1000" in higher  # more recall than the uniform scatter as slow
    summary = {"uniform-2000": _summary(0.9, 1000), "uniform-1000": _summary(0.9, 700),
               "uniform-500": _summary(0.6, 500, paired=0.4),  # slower by the medians, faster pair by pair
               "network+500": _summary(0.9, 450, paired=0.6),  # not 0.5x pair by pair
               "network+1000": _summary(0.9, 700)}  # ties are not higher
    assert all("does not pay" in line for line in bench.verdicts(chosen, summary))
    args = bench.parse_args(["--n-prior", "300", "--weights", "a=", "b=scan"])
    lean = bench.config_for(several[-2], args)
    assert (lean.recovery.weights, lean.recovery.search.n_hypotheses) == ("scan", bench.LEAN["n_hypotheses"])
    config = bench.config_for(chosen[3], bench.parse_args(["--n-prior", "300"]))
    assert (config.recovery.scatter, config.recovery.search.n_scatter, config.recovery.search.n_network) == (
        "network", 500, 300)
    default_search = dataclasses.replace(config.recovery.search, n_scatter=2000, n_network=500)
    assert default_search == AlignerConfig().recovery.search  # nothing else changed
