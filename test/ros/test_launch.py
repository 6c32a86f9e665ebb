"""The launch file matches the node (its arguments, parameters and share files), setup.py installs the launch and
RViz files, the RViz config shows the node's outputs. Static checks: the launch file is never imported (`launch`
has no pip wheel)."""
import ast
from pathlib import Path

import yaml
from package_files import PACKAGE, REPO, RVIZ_FILE, calls, constant, keyword, launch_tree, setup_keyword


def _resolve(node: ast.AST, tree: ast.AST) -> ast.AST:
    """A name -> the value it is bound to (the launch file binds each name once); anything else as it is."""
    if isinstance(node, ast.Name):
        return next((assign.value for assign in ast.walk(tree) if isinstance(assign, ast.Assign)
                     and any(getattr(target, "id", None) == node.id for target in assign.targets)), node)
    return node


def _share_path(node: ast.AST, tree: ast.AST):
    """`os.path.join(get_package_share_directory("cemnet_ros"), "a", "b")` -> "a/b" (the first argument may be
    a name bound to that call), None for anything else."""
    if not (isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "join" and node.args):
        return None
    share = _resolve(node.args[0], tree)
    if not (isinstance(share, ast.Call) and getattr(share.func, "id", None) == "get_package_share_directory"
            and [constant(arg) for arg in share.args] == [PACKAGE]):
        return None
    parts = [constant(arg) for arg in node.args[1:]]
    return "/".join(parts) if all(isinstance(part, str) for part in parts) else None


def _declared_arguments(tree: ast.AST) -> dict:
    """DeclareLaunchArgument name -> (default_value node, description)."""
    return {constant(call.args[0]): (keyword(call, "default_value"), constant(keyword(call, "description")))
            for call in calls(tree, "DeclareLaunchArgument")}


def _node_parameter_entries(tree: ast.AST) -> list:
    """The parameters both nodes get (align_node and align_lifecycle_node: one list, named once)."""
    nodes = [call for kind in ("Node", "LifecycleNode") for call in calls(tree, kind)
             if constant(keyword(call, "package")) == PACKAGE]
    assert [constant(keyword(node, "executable")) for node in nodes] == ["align_node", "align_lifecycle_node"]
    assert {constant(keyword(node, "name")) for node in nodes} == {"align_node"}, "one node name, one params key"
    assert len({ast.dump(keyword(node, "parameters")) for node in nodes}) == 1, "both get the same parameters"
    parameters = _resolve(keyword(nodes[0], "parameters"), tree)
    assert isinstance(parameters, ast.List), "parameters= should be a literal list"
    return parameters.elts


def _referenced_arguments(node: ast.AST, tree: ast.AST) -> set:
    """The X of every LaunchConfiguration("X") in `node`, names bound to one included."""
    node = _resolve(node, tree)
    names = {_resolve(name, tree) for name in ast.walk(node) if isinstance(name, ast.Name)} - {node}
    return {constant(call.args[0]) for part in [node, *names] for call in calls(part, "LaunchConfiguration")
            if call.args}


def test_launch_arguments_and_defaults():
    arguments = _declared_arguments(launch_tree())
    defaults = {name: constant(default) for name, (default, _) in arguments.items()}
    assert defaults == {"input_topic": "points", "params_file": None, "use_sim_time": "false", "odom_frame": "odom",
                        "base_frame": "base_link", "rviz": "auto", "bag": "", "dds_profile": None,
                        "lifecycle": "false", "autostart": "true"}
    assert all(description for _, description in arguments.values()), "every argument has a description"
    assert "use_sim_time:=true" in arguments["bag"][1]


def test_every_launch_configuration_is_declared_and_every_argument_used():
    tree = launch_tree()
    declared, referenced = set(_declared_arguments(tree)), _referenced_arguments(tree, tree)
    assert referenced <= declared, f"LaunchConfiguration of undeclared arguments: {sorted(referenced - declared)}"
    assert declared <= referenced, f"declared but unused arguments: {sorted(declared - referenced)}"


def test_node_gets_the_params_file_first_then_the_argument_overrides():
    tree = launch_tree()
    params_file, overrides = _node_parameter_entries(tree)
    assert _referenced_arguments(params_file, tree) == {"params_file"}
    assert isinstance(overrides, ast.Dict), "the overrides come last (they win), as a literal dict"
    assert {constant(key) for key in overrides.keys} == {"input_topic", "odom_frame", "base_frame", "use_sim_time"}
    for key, value in zip(overrides.keys, overrides.values):
        assert _referenced_arguments(value, tree) == {constant(key)}, "each override is the argument of the same name"


def _node_parameter_defaults() -> dict:
    """align_node's parameters, name -> default."""
    from cemnet_ros.ros.node_config import node_parameters  # the schema: no rclpy needed

    return {name: parameter.default for name, parameter in node_parameters().items()}


def test_node_parameters_set_by_the_launch_file_exist():
    defaults = _node_parameter_defaults()
    tree = launch_tree()
    names = {constant(key) for entry in _node_parameter_entries(tree) if isinstance(entry, ast.Dict)
             for key in entry.keys}
    unknown = sorted(names - set(defaults) - {"use_sim_time"})
    assert not unknown, f"the launch file sets parameters align_node does not declare: {unknown}"
    arguments = _declared_arguments(tree)
    for name in names - {"use_sim_time"}:  # without arguments the node runs on its own defaults
        assert constant(arguments[name][0]) == defaults[name], name


def test_default_params_file_is_the_installed_share_copy():
    tree = launch_tree()
    default, _ = _declared_arguments(tree)["params_file"]
    assert _share_path(default, tree) == "config/align_node.yaml"


def test_files_the_launch_file_takes_from_its_share_exist_and_are_installed():
    tree = launch_tree()
    paths = {_share_path(node, tree) for node in ast.walk(tree)} - {None}
    assert paths == {"config/align_node.yaml", "config/fastdds_large_data.xml", "rviz/cemnet_ros.rviz"}
    installed = _installed_files()
    for relative in paths:
        assert (REPO / relative).is_file(), relative
        assert relative in installed, f"setup.py does not install {relative} into share/{PACKAGE}"


def test_rviz_the_dds_profile_and_the_bag_replay_are_decided_before_any_process_starts():
    tree = launch_tree()
    (start,) = [call for call in calls(tree, "OpaqueFunction")]
    assert [getattr(arg, "id", None) for arg in keyword(start, "args").elts] == ["rviz", "bag_play", "align_node",
                                                                               "lifecycle_node"]
    (decide,) = [node for node in ast.walk(tree) if isinstance(node, ast.FunctionDef) and node.name == "_start"]
    choices = ("rviz_wanted", "dds_profile_file", "lifecycle_wanted")
    chosen = {call.func.id: [_referenced_arguments(arg, tree) for arg in call.args] for call in ast.walk(decide)
              if isinstance(call, ast.Call) and getattr(call.func, "id", None) in choices}
    assert chosen == {"rviz_wanted": [{"rviz"}, set()], "dds_profile_file": [{"dds_profile"}],
                      "lifecycle_wanted": [{"lifecycle"}, {"autostart"}]}
    (rviz,) = [call for call in calls(tree, "Node") if constant(keyword(call, "package")) == "rviz2"]
    assert keyword(rviz, "condition") is None, "rviz_wanted decides, not a condition on the raw argument"
    (bag,) = calls(tree, "ExecuteProcess")
    command = keyword(bag, "cmd").elts
    assert [constant(word) for word in command[:3]] == ["ros2", "bag", "play"]
    assert _referenced_arguments(command[3], tree) == {"bag"} and "--clock" in [constant(word) for word in command]
    assert _referenced_arguments(keyword(bag, "condition"), tree) == {"bag"}


def _installed_files() -> set:
    """setup.py's data_files under share/cemnet_ros, relative to it: {"launch/align_node.launch.py", ...}."""
    share = f"share/{PACKAGE}"
    return {str(Path(destination).relative_to(share) / Path(path).name)
            for destination, paths in setup_keyword("data_files")
            if destination == share or destination.startswith(share + "/") for path in paths}


def test_setup_installs_the_launch_and_rviz_files():
    assert {"launch/align_node.launch.py", "rviz/cemnet_ros.rviz", "config/align_node.yaml",
            "package.xml"} <= _installed_files()


def test_rviz_config_parses_and_shows_the_node_outputs():
    config = yaml.safe_load(RVIZ_FILE.read_text())
    assert {"Panels", "Visualization Manager", "Window Geometry"} <= set(config)
    manager = config["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == "odom"
    assert all(item["Class"].startswith("rviz_default_plugins/") for item in manager["Displays"] + manager["Tools"])
    topics = {}
    for display in manager["Displays"]:
        topics.setdefault(display["Class"].split("/")[1], set()).add(display.get("Topic", {}).get("Value"))
    assert "TF" in topics
    assert topics["Odometry"] == {"/align_node/odometry"} and topics["Path"] == {"/align_node/path"}
    assert topics["PointCloud2"] == {"/points", "/align_node/aligned_cloud", "/align_node/local_map"}
    (odometry,) = [display for display in manager["Displays"] if display["Class"].endswith("/Odometry")]
    assert odometry["Covariance"]["Value"] is True


def test_autostart_activates_after_configure_only():
    """'inactive' is reached by configure and by a deactivate: activating on the latter would undo a manager's or
    a user's deactivate. The handler waits for configuring -> inactive, and configure follows the process start."""
    tree = launch_tree()
    (on_state,) = calls(tree, "OnStateTransition")
    assert (constant(keyword(on_state, "start_state")), constant(keyword(on_state, "goal_state"))) == \
        ("configuring", "inactive")
    (on_start,) = calls(tree, "OnProcessStart")
    assert getattr(keyword(on_start, "target_action"), "id", None) == getattr(
        keyword(on_state, "target_lifecycle_node"), "id", None) == "node"
