"""The RViz view a launch hands RViz2 (cemnet_ros/rviz_config.py): the node's topics under the launch's namespace,
input_topic resolved as the node resolves it, odom_frame as the fixed frame; the rest of the view unchanged."""
from pathlib import Path

import pytest
import yaml

from cemnet_ros.rviz_config import resolve_topic, resolved_config, topics, write_resolved_config

VIEW = Path(__file__).resolve().parents[1] / "rviz" / "cemnet_ros.rviz"
NODE_OUTPUTS = {"odometry", "path", "local_map", "aligned_cloud"}  # ~/<name> topics the view shows


@pytest.mark.parametrize("name, namespace, resolved", [
    ("points", None, "/points"), ("points", "", "/points"), ("points", "/", "/points"),
    ("points", "/robot1", "/robot1/points"), ("lidar/points", "/fleet/robot1/", "/fleet/robot1/lidar/points"),
    ("/velodyne_points", "/robot1", "/velodyne_points"),
    ("~/odometry", "/robot1", "/robot1/align_node/odometry"), ("~", None, "/align_node"),
])
def test_topics_resolve_as_ros_resolves_them(name, namespace, resolved):
    assert resolve_topic(name, namespace) == resolved


def test_the_shipped_view_is_the_root_launch_s_own():
    text = VIEW.read_text()
    assert topics(resolved_config(text, None, "points", "odom")) == topics(text)
    assert {t.rsplit("/", 1)[1] for t in topics(text).values() if t.startswith("/align_node/")} == NODE_OUTPUTS


def test_a_namespaced_launch_with_another_input_and_frame():
    text = VIEW.read_text()
    resolved = resolved_config(text, "/robot1", "velodyne_points", "robot1/odom")
    assert topics(resolved) == {
        "Odometry": "/robot1/align_node/odometry", "Path": "/robot1/align_node/path",
        "Local map": "/robot1/align_node/local_map", "Aligned cloud": "/robot1/align_node/aligned_cloud",
        "Input cloud": "/robot1/velodyne_points"}
    assert topics(resolved_config(text, "/robot1", "/sensors/points", "odom"))["Input cloud"] == "/sensors/points"
    before, after = yaml.safe_load(text), yaml.safe_load(resolved)
    assert after["Visualization Manager"]["Global Options"]["Fixed Frame"] == "robot1/odom"
    for config in (before, after):  # everything else is the shipped view's
        config["Visualization Manager"]["Global Options"].pop("Fixed Frame")
        for display in config["Visualization Manager"]["Displays"]:
            display.get("Topic", {}).pop("Value", None)
    assert after == before


def test_displays_inside_a_group_follow_too():
    group = {"Visualization Manager": {"Global Options": {"Fixed Frame": "odom"}, "Displays": [
        {"Class": "rviz_common/Group", "Name": "g", "Displays": [
            {"Class": "rviz_default_plugins/Odometry", "Name": "o", "Topic": {"Value": "/align_node/odometry"}}]}]}}
    assert topics(resolved_config(yaml.safe_dump(group), "/r2", "points", "odom")) == {"o": "/r2/align_node/odometry"}


def test_the_copy_is_a_new_file_each_launch(tmp_path, monkeypatch):
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    first = write_resolved_config(str(VIEW), "/robot1", "points", "odom")
    second = write_resolved_config(str(VIEW), "/robot1", "points", "odom")
    assert first != second and Path(first).parent == tmp_path and Path(first).name.startswith("cemnet_ros_robot1_")
    assert topics(Path(first).read_text())["Input cloud"] == "/robot1/points"
