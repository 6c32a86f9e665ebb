"""The one parameter schema: every config field documented, dotted names, checked values, YAML and flags."""
from __future__ import annotations

import argparse

import pytest
import yaml

from cemnet_ros.core.config import CEMConfig, RegistrationConfig
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.ros.node_config import NodeConfig, configs_from_parameters, node_parameters, params_file_text
from cemnet_ros.schema import add_arguments, build, flatten_mapping, parameters, parsed_overrides, values


def test_every_field_of_every_config_is_documented_and_named_by_section():
    params = node_parameters()
    assert all(p.help for p in params.values())
    assert "registration.cem_preset" in params and "preprocess.max_range" in params and "mode" in params
    assert not {"registration.prior", "registration.prior_sigma"} & set(params)  # the pipeline: tracking.centre
    assert params["registration.cem_preset"].default == AlignerConfig().registration.cem_preset == "tracking"
    assert params["registration.cem_preset"].choices == ("tracking", "refine", "paper")
    assert set(parameters(RegistrationConfig())) >= {"cem.n_candidates", "cem.seed", "prior", "weights", "n_points"}


def test_build_applies_dotted_values_and_refuses_bad_ones():
    config = build(AlignerConfig(), {"registration.cem_preset": "paper", "preprocess.max_range": 50,
                                     "recovery.search.resample_sigma": [0.1] * 6})
    assert config.registration.cem_preset == "paper" and config.preprocess.max_range == 50.0
    assert isinstance(config.preprocess.max_range, float) and config.recovery.search.resample_sigma == (0.1,) * 6
    assert config.recovery.search.refine_preset == AlignerConfig().recovery.search.refine_preset
    for gone in ("registration.prior", "tracking.prior", "recovery.prior", "recovery.search.n_prior",
                 "registration.cem.n_iters", "recovery.search.refine.n_iters", "registration.seed",
                 "registration.cem.seed", "recovery.search.refine.seed", "recovery.turn_yaw"):
        with pytest.raises(ValueError, match="unknown parameter"):  # renamed (CHANGELOG, issues 29, 40): no aliases
            build(AlignerConfig(), {gone: 1})
    with pytest.raises(ValueError, match="tracking.centre must be one of"):
        build(AlignerConfig(), {"tracking.centre": "magic"})
    with pytest.raises(ValueError, match="registration.cem_preset must be one of"):
        build(AlignerConfig(), {"registration.cem_preset": "fast"})
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
    assert values(pipeline)["recovery.search.refine_preset"] == pipeline.recovery.search.refine_preset


def test_flags_are_built_from_the_schema():
    params = parameters(AlignerConfig())
    parser = argparse.ArgumentParser()
    add_arguments(parser, params, "pipeline")
    args = parser.parse_args(["--registration.cem-preset", "refine", "--seed", "3", "--preprocess.deskew", "false",
                              "--tracking.centre", "identity", "--recovery.search.refine_sigma", *["0.2"] * 6])
    overrides = parsed_overrides(args, params)
    assert overrides == {"registration.cem_preset": "refine", "seed": 3, "preprocess.deskew": False,
                         "tracking.centre": "identity", "recovery.search.refine_sigma": [0.2] * 6}
    assert build(AlignerConfig(), overrides).tracking.centre == "identity"
    for bad in (["--tracking.centre", "magic"], ["--recovery.search.refine_preset", "fast"]):
        with pytest.raises(SystemExit):
            parser.parse_args(bad)


def test_shipped_params_file_and_docs_tables_are_generated_from_the_schema():
    from pathlib import Path

    from cemnet_ros.ros.node_config import parameters_markdown

    repo = Path(__file__).resolve().parents[1]
    assert (repo / "config" / "align_node.yaml").read_text() == params_file_text(), \
        "regenerate: python -m cemnet_ros.ros.node_config > config/align_node.yaml"
    assert parameters_markdown() in (repo / "docs" / "node.md").read_text(), \
        "regenerate the tables in docs/node.md: python -m cemnet_ros.ros.node_config --markdown"


def test_shipped_params_file_holds_the_user_tier_alone_in_at_most_60_lines():
    from pathlib import Path

    from cemnet_ros.ros.node_config import user_parameters

    text = (Path(__file__).resolve().parents[1] / "config" / "align_node.yaml").read_text()
    assert len(text.splitlines()) <= 60, "issue 40: a params file a user can hold"
    shipped = yaml.safe_load(text)["/**"]["ros__parameters"]
    user, declared = user_parameters(), node_parameters()
    assert list(shipped) == list(user), "the file holds exactly the user tier, in the schema's order"
    assert set(user) <= set(declared), "each user parameter is one the node declares"
    assert all(shipped[n] == (list(p.default) if p.kind is tuple else p.default) for n, p in user.items())
    assert 10 <= len(user) <= 20, "about 15 user parameters; the rest are expert ones"
    assert {"input_topic", "odom_frame", "base_frame", "publish_tf", "preprocess.max_range",
            "preprocess.deskew", "registration.device"} <= set(user)
    assert "Expert parameters" in text and "docs/node.md" in text, "the header points to the expert tier"


def _table_names(markdown: str, heading: str) -> list:
    """The parameter names of the tables under ``heading`` (a '### ' heading), up to the next '### ' heading."""
    names, inside = [], False
    for line in markdown.splitlines():
        if line.startswith("### "):
            inside = line == heading
        elif inside and line.startswith("| `"):
            names.append(line.split("`")[1])
    return names


def test_docs_tables_hold_the_user_tier_then_every_other_parameter_once():
    from cemnet_ros.ros.node_config import parameters_markdown, user_parameters

    markdown = parameters_markdown()
    user, expert = _table_names(markdown, "### User parameters"), _table_names(markdown, "### Expert parameters")
    declared = node_parameters()
    assert user == list(user_parameters())
    assert len(user) + len(expert) == len(set(user) | set(expert)) == len(declared), "each parameter once"
    assert set(user) | set(expert) == set(declared), "every declared node parameter is in one of the two tables"
    assert "#### `recovery.*`: when and how widely the global search runs" in markdown  # expert ones by section


def _limited_fields(config_class):
    """(field, low, high, choices) of each param of ``config_class`` that declares a limit."""
    import dataclasses

    for f in dataclasses.fields(config_class):
        meta = f.metadata
        if "help" in meta and f.default is not dataclasses.MISSING and (
                meta["low"] is not None or meta["high"] is not None or meta["choices"]):
            yield f.name, f.default, meta["low"], meta["high"], meta["choices"]


def _validated_classes():
    from cemnet_ros.core.config import GlobalSearchConfig
    from cemnet_ros.eval.protocol import ProtocolConfig
    from cemnet_ros.eval.sevenscenes import SevenScenesConfig
    from cemnet_ros.pipeline.config import (
        AdaptiveConfig,
        HealthConfig,
        InputChecksConfig,
        MapConfig,
        PolishConfig,
        PreprocessConfig,
        RecoveryConfig,
        RecoverySearchConfig,
        TrackingConfig,
        TrackingEngineConfig,
    )
    from cemnet_ros.train.config import ScanPairConfig, TrainConfig
    from cemnet_ros.train.known_motion import KnownMotionConfig

    return [CEMConfig, RegistrationConfig, GlobalSearchConfig, PreprocessConfig, MapConfig, AdaptiveConfig,
            HealthConfig, InputChecksConfig, TrackingConfig, PolishConfig, RecoveryConfig, TrainConfig,
            ScanPairConfig, KnownMotionConfig, ProtocolConfig, SevenScenesConfig, AlignerConfig,
            TrackingEngineConfig, RecoverySearchConfig]


@pytest.mark.parametrize("config_class", _validated_classes(), ids=lambda c: c.__name__)
def test_constructing_a_config_enforces_its_schema_limits_inclusively(config_class):
    name = config_class.__name__
    checked = 0
    for field_name, default, low, high, choices in _limited_fields(config_class):
        if choices:
            with pytest.raises(ValueError, match=f"{name}.{field_name} must be one of"):
                config_class(**{field_name: "no such choice"})
            checked += 1
            continue
        for bound, step in ((low, -1), (high, 1)):
            if bound is None:
                continue
            beyond = bound + step * max(abs(bound), 1.0) * 0.5
            if isinstance(default, int):
                beyond = int(bound) + step
            value = (beyond,) * len(default) if isinstance(default, tuple) else beyond
            with pytest.raises(ValueError, match=f"{name}.{field_name} = .* outside"):
                config_class(**{field_name: value})
            checked += 1
    assert checked > 0


def test_validate_bounds_are_inclusive_tuples_keep_their_length_and_cross_field_rules_stay():
    from cemnet_ros.pipeline.config import HealthConfig

    assert HealthConfig(min_fitness=0.99, fitness_drop=1.0).min_fitness == 0.99  # the bounds themselves pass
    with pytest.raises(ValueError, match=r"HealthConfig.min_fitness = 0.995 outside \[0.0, 0.99\]"):
        HealthConfig(min_fitness=0.995)
    with pytest.raises(ValueError, match="HealthConfig.min_fitness = nan outside"):
        HealthConfig(min_fitness=float("nan"))
    from cemnet_ros.core.config import GlobalSearchConfig

    with pytest.raises(ValueError, match="resample_sigma must have 6 values"):
        GlobalSearchConfig(resample_sigma=(0.1,) * 5)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="n_scatter must be >= n_hypotheses"):
        GlobalSearchConfig(n_scatter=2, n_seeds=16)
    with pytest.raises(ValueError, match="n_fused_iters"):
        CEMConfig(n_iters=2, n_fused_iters=3)
