"""The one parameter schema: every config field documented, dotted names, checked values, YAML and flags."""
from __future__ import annotations

import argparse

import pytest
import yaml

from cemnet_ros.core.config import CEMConfig, RegistrationConfig
from cemnet_ros.pipeline.config import DERIVED, AlignerConfig
from cemnet_ros.ros.node_config import NodeConfig, configs_from_parameters, node_parameters, params_file_text
from cemnet_ros.schema import add_arguments, build, flatten_mapping, parameters, parsed_overrides, values


def test_every_field_of_every_config_is_documented_and_named_by_section():
    params = node_parameters()
    assert all(p.help for p in params.values())
    assert "registration.cem.n_iters" in params and "preprocess.max_range" in params and "mode" in params
    assert "registration.prior" not in params  # derived from tracking.prior in the pipeline
    assert params["registration.cem.n_iters"].default == AlignerConfig().registration.cem.n_iters
    assert set(parameters(RegistrationConfig())) >= {"cem.n_candidates", "prior", "weights", "n_points"}


def test_build_applies_dotted_values_and_refuses_bad_ones():
    config = build(AlignerConfig(), {"registration.cem.n_iters": 4, "preprocess.max_range": 50,
                                     "recovery.search.resample_sigma": [0.1] * 6}, exclude=DERIVED)
    assert config.registration.cem.n_iters == 4 and config.preprocess.max_range == 50.0
    assert isinstance(config.preprocess.max_range, float) and config.recovery.search.resample_sigma == (0.1,) * 6
    assert config.registration.cem.n_candidates == AlignerConfig().registration.cem.n_candidates
    with pytest.raises(ValueError, match="unknown parameter"):
        build(AlignerConfig(), {"registration.prior": "identity"}, exclude=DERIVED)
    with pytest.raises(ValueError, match="tracking.prior must be one of"):
        build(AlignerConfig(), {"tracking.prior": "magic"})
    with pytest.raises(ValueError, match="outside"):
        build(AlignerConfig(), {"health.min_fitness": 1.5})
    with pytest.raises(ValueError, match="expected an integer"):
        build(AlignerConfig(), {"registration.n_points": 1.5})
    with pytest.raises(ValueError, match="n_fused_iters"):  # the sections' own checks still run
        build(CEMConfig(), {"n_iters": 2})


def test_params_file_round_trips_to_the_defaults():
    data = yaml.safe_load(params_file_text())
    node, pipeline = configs_from_parameters(flatten_mapping(data["/**"]["ros__parameters"]))
    assert node == NodeConfig() and pipeline == AlignerConfig()
    assert values(pipeline, DERIVED)["registration.cem.n_iters"] == pipeline.registration.cem.n_iters


def test_flags_are_built_from_the_schema():
    params = parameters(AlignerConfig(), exclude=DERIVED)
    parser = argparse.ArgumentParser()
    add_arguments(parser, params, "pipeline")
    args = parser.parse_args(["--registration.cem.n_iters", "3", "--preprocess.deskew", "false",
                              "--tracking.prior", "identity", "--recovery.search.refine_sigma", *["0.2"] * 6])
    overrides = parsed_overrides(args, params)
    assert overrides == {"registration.cem.n_iters": 3, "preprocess.deskew": False, "tracking.prior": "identity",
                         "recovery.search.refine_sigma": [0.2] * 6}
    assert build(AlignerConfig(), overrides, exclude=DERIVED).tracking.prior == "identity"
    with pytest.raises(SystemExit):
        parser.parse_args(["--tracking.prior", "magic"])


def test_shipped_params_file_and_docs_table_are_generated_from_the_schema():
    from pathlib import Path

    from cemnet_ros.ros.node_config import parameters_markdown

    repo = Path(__file__).resolve().parents[1]
    assert (repo / "config" / "align_node.yaml").read_text() == params_file_text(), \
        "regenerate: python -m cemnet_ros.ros.node_config > config/align_node.yaml"
    assert parameters_markdown() in (repo / "docs" / "node.md").read_text(), \
        "regenerate the table in docs/node.md: python -m cemnet_ros.ros.node_config --markdown"
