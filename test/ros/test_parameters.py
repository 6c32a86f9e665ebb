"""align_node's parameters: the params file is the schema, bad values are refused, a fatal configuration
is one line and exit 2."""
from __future__ import annotations

import os
from pathlib import Path

import pytest
import yaml

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # read when the DDS participant is created

from rclpy.parameter import Parameter  # noqa: E402

from cemnet_ros.ros.align_node import AlignNode  # noqa: E402
from cemnet_ros.ros.node_config import node_parameters, params_file_text, user_parameters  # noqa: E402

REPO = Path(__file__).resolve().parents[2]


def test_params_file_is_the_schema_and_applies_under_a_namespace_and_a_renamed_node(context, tmp_path):
    path = REPO / "config" / "align_node.yaml"
    assert path.read_text() == params_file_text(), "regenerate: python -m cemnet_ros.ros.node_config"
    params = yaml.safe_load(path.read_text())["/**"]["ros__parameters"]
    user = user_parameters()  # the file holds the user tier; the node declares every parameter, both tiers
    assert set(params) == set(user)
    assert all(params[n] == (list(p.default) if p.kind is tuple else p.default) for n, p in user.items())
    changed = tmp_path / "robot.yaml"
    changed.write_text("/**:\n  ros__parameters:\n    registration.cem_preset: paper\n    seed: 7\n"
                       "    base_frame: robot1/base\n")
    node = AlignNode(context=context, cli_args=["--ros-args", "-r", "__ns:=/robot1", "-r", "__node:=lidar_odom",
                                                "--params-file", str(path), "--params-file", str(changed)])
    try:
        assert node.get_fully_qualified_name() == "/robot1/lidar_odom"
        assert all(node.has_parameter(name) for name in node_parameters()), "expert ones stay declared"
        defaults = node_parameters()  # an expert parameter the file leaves out keeps the schema's default
        assert node.get_parameter("health.min_fitness").value == defaults["health.min_fitness"].default
        assert node.get_parameter("registration.cem_preset").value == "paper"
        assert node.get_parameter("mode").value == "sequential"
        pipeline = node._session.config  # the parameters reach the pipeline's config and its engines
        engine, search = pipeline.tracking_engine(), pipeline.global_search()
        assert (engine.cem.n_candidates, engine.cem.n_iters, engine.cem.seed, engine.seed) == (1000, 10, 7, 7)
        assert (search.refine.n_iters, search.refine.seed) == (5, 7)  # the refinement's preset kept
        assert node.alignment._cfg.base_frame == "robot1/base"
        result = node.set_parameters([Parameter("registration.n_points", value=100)])[0]  # read-only
        assert not result.successful
    finally:
        node.destroy_node()


def test_bad_parameter_values_are_refused(context):
    with pytest.raises(ValueError, match="mode"):
        AlignNode(context=context, parameter_overrides=[Parameter("mode", value="bogus")])
    with pytest.raises(Exception, match="registration.n_points"):  # rclpy refuses it against the range
        AlignNode(context=context, parameter_overrides=[Parameter("registration.n_points", value=3)])


@pytest.mark.parametrize("args, needle", [
    (["-p", "preprocess.voxel_size:=-5.0"], "preprocess.voxel_size"),
    (["-p", "mode:=bogus"], "mode"),
    (["-p", "preprocess.max_range:=far"], "preprocess.max_range"),
    (["-p", "tracking.centre:=network", "-p", "registration.weights:=/nonexistent/w.npz"], "no such file"),
])
def test_fatal_configuration_is_one_line_and_exit_2(args, needle):
    import subprocess
    import sys

    env = {**os.environ, "ROS_DOMAIN_ID": "231"}
    run = subprocess.run([sys.executable, "-m", "cemnet_ros.ros.align_node", "--ros-args", *args], env=env,
                         capture_output=True, text=True, timeout=60)
    errors = [line for line in run.stderr.splitlines() if "error:" in line]
    assert run.returncode == 2, run.stderr
    assert "Traceback" not in run.stderr and len(errors) == 1 and needle in errors[0], run.stderr


def test_a_corrupt_weights_file_ends_the_node_with_one_line(tmp_path):
    import subprocess
    import sys

    weights = tmp_path / "corrupt.npz"
    weights.write_bytes(b"not an npz archive")
    env = {**os.environ, "ROS_DOMAIN_ID": "232"}
    run = subprocess.run([sys.executable, "-m", "cemnet_ros.ros.align_node", "--ros-args", "-p",
                          "tracking.centre:=network", "-p", f"registration.weights:={weights}"], env=env,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2 and "Traceback" not in run.stderr, run.stderr
    assert run.stderr.strip().splitlines()[-1].startswith("align_node: error: the engine did not load"), run.stderr


def test_the_node_and_its_parameters_import_without_torch():
    """Torch (~2 s to import) loads in the engine's background thread, after the subscriptions exist."""
    import subprocess
    import sys

    code = "import sys, cemnet_ros.ros.align_node; print('torch' in sys.modules)"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert run.stdout.split() == ["False"], run.stderr
