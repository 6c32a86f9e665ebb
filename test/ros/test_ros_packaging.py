"""The ROS side of the packaging: package.xml declares what the code imports and what it runs on, requirements and
setup.py agree with it. Static checks (ast, xml, yaml): the launch file is never imported
(`launch` has no pip wheel)."""
import ast
import sys
import xml.etree.ElementTree as ET

from package_files import LAUNCH_FILE, PACKAGE, REPO, calls, constant, keyword, launch_tree, setup_keyword

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
    "PIL": "python3-pil",  # 7-Scenes depth PNGs (cemnet_ros/data/rgbd.py)
    "tqdm": "python3-tqdm",
    "yaml": "python3-yaml",
    "torch": (PIP, "torch"),  # python3-torch is the distribution's own build, not the pinned 2.13.0 CPU one
    "rosbags": (PIP, "rosbags"),  # only python3-rosbags-pip (`sudo pip`, refused on Ubuntu 24.04: PEP 668)
    "open3d": (OPTIONAL, "open3d-cpu"),  # cemnet-eval's FPFH baseline only
    "kiss_icp": (OPTIONAL, "kiss-icp"),  # the robustness benchmark's peers only (benchmarks)
    "small_gicp": (PIP, "small-gicp"),  # GICP, the polish's wide stage: its Python bindings are on PyPI only
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
    tree = launch_tree()
    keys = {"ros2launch"} | {constant(keyword(call, "package")) for call in calls(tree, "Node")}
    for call in calls(tree, "ExecuteProcess"):
        if [constant(word) for word in keyword(call, "cmd").elts][:2] == ["ros2", "bag"]:
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
    assert _pip_requirements() <= {_requirement_name(r) for r in setup_keyword("install_requires")}
    extras = {_requirement_name(r) for group in setup_keyword("extras_require").values() for r in group}
    optional = {entry[1] for entry in ROSDEP_KEYS.values() if isinstance(entry, tuple) and entry[0] == OPTIONAL}
    assert optional <= extras, f"optional imports without a setup.py extra: {sorted(optional - extras)}"


# -- the launch file, read with ast ------------------------------------------------------------------------


































# -- setup.py and the RViz config --------------------------------------------------------------------------








def test_package_xml_repeats_the_one_version_string():
    import cemnet_ros

    assert ET.parse(REPO / "package.xml").getroot().findtext("version") == cemnet_ros.__version__
