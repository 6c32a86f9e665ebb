"""The ROS side of the packaging: package.xml declares what the code imports, the launch file matches the node,
setup.py installs the launch and RViz files. Static checks (ast, xml, yaml): the launch file is never imported
(`launch` has no pip wheel)."""
import ast
import glob
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]
PACKAGE = "cemnet_ros"
LAUNCH_FILE = REPO / "launch" / "align_node.launch.py"
RVIZ_FILE = REPO / "rviz" / "cemnet_ros.rviz"
PIP_REQUIREMENTS = REPO / "requirements-ros.txt"
INSTALL_DOC = REPO / "docs" / "install_ros.md"

PIP = "pip"  # no rosdep key fits: requirements-ros.txt installs it (docs/install_ros.md)
OPTIONAL = "optional"  # imported lazily behind a clear error; a setup.py extra installs it

# Top-level module -> rosdep key (rosdistro: jazzy/distribution.yaml, rosdep/base.yaml, rosdep/python.yaml),
# or (PIP | OPTIONAL, pip distribution). A new third-party import fails test_every_import_is_declared until it
# is added here and declared in package.xml (or in requirements-ros.txt for PIP).
ROSDEP_KEYS = {
    "rclpy": "rclpy",
    "rcl_interfaces": "rcl_interfaces",
    "sensor_msgs": "sensor_msgs",
    "geometry_msgs": "geometry_msgs",
    "nav_msgs": "nav_msgs",
    "diagnostic_msgs": "diagnostic_msgs",
    "std_srvs": "std_srvs",
    "tf2_msgs": "tf2_msgs",
    "tf2_ros": "tf2_ros_py",  # the Python tf2_ros is package tf2_ros_py (package tf2_ros is the C++ one)
    "launch": "launch",
    "launch_ros": "launch_ros",
    "ament_index_python": "ament_index_python",
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "numba": "python3-numba",
    "matplotlib": "python3-matplotlib",
    "tqdm": "python3-tqdm",
    "yaml": "python3-yaml",
    "torch": (PIP, "torch"),  # python3-torch is the distribution's own build, not the pinned 2.13.0 CPU one
    "rosbags": (PIP, "rosbags"),  # only python3-rosbags-pip (`sudo pip`, refused on Ubuntu 24.04: PEP 668)
    "open3d": (OPTIONAL, "open3d-cpu"),  # cemnet-eval's FPFH baseline only
}


# -- imports and package.xml -------------------------------------------------------------------------------
def _imports_in(source: str, filename: str = "<string>") -> set:
    """Top-level third-party names of every absolute import: module level, functions, try/except alike."""
    names = set()
    for node in ast.walk(ast.parse(source, filename=filename)):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return {name for name in names if name not in sys.stdlib_module_names and name != PACKAGE}


def _code_imports() -> set:
    """What the package and the launch file import."""
    paths = [*(REPO / PACKAGE).rglob("*.py"), LAUNCH_FILE]
    return set().union(*(_imports_in(path.read_text(), str(path)) for path in paths))


def _runtime_keys() -> set:
    root = ET.parse(REPO / "package.xml").getroot()
    return {element.text.strip() for tag in ("exec_depend", "depend") for element in root.iter(tag)}


def _requirement_name(requirement: str) -> str:
    for separator in "<>=!~;[ ":
        requirement = requirement.split(separator)[0]
    return requirement.strip().lower()


def _pip_requirements() -> set:
    lines = (line.split("#")[0].strip() for line in PIP_REQUIREMENTS.read_text().splitlines())
    return {_requirement_name(line) for line in lines if line and not line.startswith("-")}


def _undeclared(modules: set, table: dict, declared: set) -> list:
    """Why `modules` are not covered: no entry in the table, or a rosdep key package.xml lacks."""
    problems = [f"{module}: no rosdep mapping (add it to ROSDEP_KEYS)" for module in sorted(modules - table.keys())]
    problems += [f"{module}: package.xml lacks <exec_depend>{table[module]}</exec_depend>"
                 for module in sorted(modules & table.keys())
                 if isinstance(table[module], str) and table[module] not in declared]
    return problems


def test_the_import_scan_sees_the_known_dependencies():
    found = _code_imports()
    assert {"numpy", "scipy", "torch", "numba", "rclpy", "rcl_interfaces", "tf2_msgs", "rosbags", "open3d",
            "launch", "launch_ros", "ament_index_python"} <= found
    assert not found & {"os", "typing", "__future__", PACKAGE}


def test_every_import_is_declared():
    assert _undeclared(_code_imports(), ROSDEP_KEYS, _runtime_keys()) == []


def test_an_undeclared_import_would_be_caught():
    # `import shapely` added anywhere in cemnet_ros/, with or without a table entry (python3-shapely exists)
    modules = _code_imports() | _imports_in("def f():\n    from shapely.geometry import Point\n")
    assert "shapely" in modules
    assert "shapely: no rosdep mapping (add it to ROSDEP_KEYS)" in _undeclared(modules, ROSDEP_KEYS, _runtime_keys())
    with_entry = {**ROSDEP_KEYS, "shapely": "python3-shapely"}
    assert "shapely: package.xml lacks <exec_depend>python3-shapely</exec_depend>" in _undeclared(
        modules, with_entry, _runtime_keys())


def _launch_uses() -> set:
    """Keys the launch file needs besides its imports: `ros2 launch`, the packages of its Nodes, `ros2 bag`."""
    tree = _launch_tree()
    keys = {"ros2launch"} | {_constant(_keyword(call, "package")) for call in _calls(tree, "Node")}
    for call in _calls(tree, "ExecuteProcess"):
        if [_constant(word) for word in _keyword(call, "cmd").elts][:2] == ["ros2", "bag"]:
            keys |= {"ros2bag", "rosbag2_storage_default_plugins"}  # the CLI and its mcap/sqlite3 readers
    return keys - {PACKAGE}


def test_every_declared_runtime_dependency_is_used():
    used = {ROSDEP_KEYS[module] for module in _code_imports() if isinstance(ROSDEP_KEYS.get(module), str)}
    unused = sorted(_runtime_keys() - used - _launch_uses())
    assert not unused, f"package.xml declares what nothing imports or launches: {unused}"


def test_pip_only_modules_are_in_the_documented_pip_command():
    pip_only = {entry[1] for entry in ROSDEP_KEYS.values() if isinstance(entry, tuple) and entry[0] == PIP}
    missing = sorted(pip_only - _pip_requirements())
    assert not missing, f"{missing} missing from {PIP_REQUIREMENTS.name}"
    (torch_pin,) = [line for line in (REPO / "requirements.txt").read_text().splitlines() if line.startswith("torch")]
    assert torch_pin in PIP_REQUIREMENTS.read_text().splitlines(), f"the full-ROS path installs {torch_pin} too"
    doc = INSTALL_DOC.read_text()
    assert "rosdep install" in doc and "pip install -r src/cemnet_ros/requirements-ros.txt" in doc


def test_pip_requirements_and_optional_imports_agree_with_setup_py():
    assert _pip_requirements() <= {_requirement_name(r) for r in _setup_keyword("install_requires")}
    extras = {_requirement_name(r) for group in _setup_keyword("extras_require").values() for r in group}
    optional = {entry[1] for entry in ROSDEP_KEYS.values() if isinstance(entry, tuple) and entry[0] == OPTIONAL}
    assert optional <= extras, f"optional imports without a setup.py extra: {sorted(optional - extras)}"


# -- the launch file, read with ast ------------------------------------------------------------------------
def _launch_tree() -> ast.Module:
    return ast.parse(LAUNCH_FILE.read_text(), filename=str(LAUNCH_FILE))


def _calls(tree: ast.AST, name: str) -> list:
    """Calls of `name(...)` or `anything.name(...)`."""
    return [node for node in ast.walk(tree) if isinstance(node, ast.Call)
            and name in (getattr(node.func, "id", None), getattr(node.func, "attr", None))]


def _keyword(call: ast.Call, name: str):
    return next((keyword.value for keyword in call.keywords if keyword.arg == name), None)


def _constant(node):
    return node.value if isinstance(node, ast.Constant) else None


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
            and [_constant(arg) for arg in share.args] == [PACKAGE]):
        return None
    parts = [_constant(arg) for arg in node.args[1:]]
    return "/".join(parts) if all(isinstance(part, str) for part in parts) else None


def _declared_arguments(tree: ast.AST) -> dict:
    """DeclareLaunchArgument name -> (default_value node, description)."""
    return {_constant(call.args[0]): (_keyword(call, "default_value"), _constant(_keyword(call, "description")))
            for call in _calls(tree, "DeclareLaunchArgument")}


def _node_parameter_entries(tree: ast.AST) -> list:
    nodes = [call for call in _calls(tree, "Node") if _constant(_keyword(call, "package")) == PACKAGE]
    assert len(nodes) == 1, "the launch file should start align_node once"
    assert _constant(_keyword(nodes[0], "executable")) == "align_node"
    parameters = _keyword(nodes[0], "parameters")
    assert isinstance(parameters, ast.List), "parameters= should be a literal list"
    return parameters.elts


def _referenced_arguments(node: ast.AST, tree: ast.AST) -> set:
    """The X of every LaunchConfiguration("X") in `node`, names bound to one included."""
    node = _resolve(node, tree)
    names = {_resolve(name, tree) for name in ast.walk(node) if isinstance(name, ast.Name)} - {node}
    return {_constant(call.args[0]) for part in [node, *names] for call in _calls(part, "LaunchConfiguration")
            if call.args}


def test_launch_arguments_and_defaults():
    arguments = _declared_arguments(_launch_tree())
    defaults = {name: _constant(default) for name, (default, _) in arguments.items()}
    assert defaults == {"input_topic": "points", "params_file": None, "use_sim_time": "false", "odom_frame": "odom",
                        "base_frame": "base_link", "rviz": "true", "bag": "", "dds_profile": None}
    assert all(description for _, description in arguments.values()), "every argument has a description"
    assert "use_sim_time:=true" in arguments["bag"][1]


def test_every_launch_configuration_is_declared_and_every_argument_used():
    tree = _launch_tree()
    declared, referenced = set(_declared_arguments(tree)), _referenced_arguments(tree, tree)
    assert referenced <= declared, f"LaunchConfiguration of undeclared arguments: {sorted(referenced - declared)}"
    assert declared <= referenced, f"declared but unused arguments: {sorted(declared - referenced)}"


def test_node_gets_the_params_file_first_then_the_argument_overrides():
    tree = _launch_tree()
    params_file, overrides = _node_parameter_entries(tree)
    assert _referenced_arguments(params_file, tree) == {"params_file"}
    assert isinstance(overrides, ast.Dict), "the overrides come last (they win), as a literal dict"
    assert {_constant(key) for key in overrides.keys} == {"input_topic", "odom_frame", "base_frame", "use_sim_time"}
    for key, value in zip(overrides.keys, overrides.values):
        assert _referenced_arguments(value, tree) == {_constant(key)}, "each override is the argument of the same name"


def _node_parameter_defaults() -> dict:
    """align_node's parameters, name -> default."""
    from cemnet_ros.ros.node_config import node_parameters  # the schema: no rclpy needed

    return {name: parameter.default for name, parameter in node_parameters().items()}


def test_node_parameters_set_by_the_launch_file_exist():
    defaults = _node_parameter_defaults()
    tree = _launch_tree()
    names = {_constant(key) for entry in _node_parameter_entries(tree) if isinstance(entry, ast.Dict)
             for key in entry.keys}
    unknown = sorted(names - set(defaults) - {"use_sim_time"})
    assert not unknown, f"the launch file sets parameters align_node does not declare: {unknown}"
    arguments = _declared_arguments(tree)
    for name in names - {"use_sim_time"}:  # without arguments the node runs on its own defaults
        assert _constant(arguments[name][0]) == defaults[name], name


def test_default_params_file_is_the_installed_share_copy():
    tree = _launch_tree()
    default, _ = _declared_arguments(tree)["params_file"]
    assert _share_path(default, tree) == "config/align_node.yaml"


def test_files_the_launch_file_takes_from_its_share_exist_and_are_installed():
    tree = _launch_tree()
    paths = {_share_path(node, tree) for node in ast.walk(tree)} - {None}
    assert paths == {"config/align_node.yaml", "config/fastdds_large_data.xml", "rviz/cemnet_ros.rviz"}
    installed = _installed_files()
    for relative in paths:
        assert (REPO / relative).is_file(), relative
        assert relative in installed, f"setup.py does not install {relative} into share/{PACKAGE}"


def test_rviz_and_the_bag_replay_are_conditional():
    tree = _launch_tree()
    (rviz,) = [call for call in _calls(tree, "Node") if _constant(_keyword(call, "package")) == "rviz2"]
    assert _referenced_arguments(_keyword(rviz, "condition"), tree) == {"rviz"}
    (bag,) = _calls(tree, "ExecuteProcess")
    command = _keyword(bag, "cmd").elts
    assert [_constant(word) for word in command[:3]] == ["ros2", "bag", "play"]
    assert _referenced_arguments(command[3], tree) == {"bag"} and "--clock" in [_constant(word) for word in command]
    assert _referenced_arguments(_keyword(bag, "condition"), tree) == {"bag"}


# -- setup.py and the RViz config --------------------------------------------------------------------------
def _setup_keyword(name: str):
    """A keyword of setup(), evaluated for the forms setup.py uses: literals, names, `+`, glob("pattern")."""
    tree = ast.parse((REPO / "setup.py").read_text())
    names = {target.id: node.value.value for node in tree.body if isinstance(node, ast.Assign)
             and isinstance(node.value, ast.Constant) for target in node.targets}

    def evaluate(node):
        if isinstance(node, ast.Name):
            return names[node.id]
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
            return evaluate(node.left) + evaluate(node.right)
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "glob":
            return sorted(glob.glob(node.args[0].value, root_dir=REPO))
        if isinstance(node, (ast.List, ast.Tuple)):
            return [evaluate(element) for element in node.elts]
        if isinstance(node, ast.Dict):
            return {evaluate(key): evaluate(value) for key, value in zip(node.keys, node.values)}
        return ast.literal_eval(node)

    (setup,) = _calls(tree, "setup")
    return evaluate(_keyword(setup, name))


def _installed_files() -> set:
    """setup.py's data_files under share/cemnet_ros, relative to it: {"launch/align_node.launch.py", ...}."""
    share = f"share/{PACKAGE}"
    return {str(Path(destination).relative_to(share) / Path(path).name)
            for destination, paths in _setup_keyword("data_files")
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
    assert topics["Odometry"] == {"/align_node/odometry"}
    assert topics["PointCloud2"] == {"/points", "/align_node/aligned_cloud", "/align_node/local_map"}
    (odometry,) = [display for display in manager["Displays"] if display["Class"].endswith("/Odometry")]
    assert odometry["Covariance"]["Value"] is True


def test_package_xml_repeats_the_one_version_string():
    import cemnet_ros

    assert ET.parse(REPO / "package.xml").getroot().findtext("version") == cemnet_ros.__version__
