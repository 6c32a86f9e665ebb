"""The ROS side of the packaging: package.xml declares what the code imports and what it runs on (a headless robot:
nothing the node can go without), requirements and setup.py agree with it, the optional libraries are imported only
where used. Static checks (ast, xml, yaml): the launch file is never imported (`launch` has no pip wheel)."""
import ast
import sys
import xml.etree.ElementTree as ET

from package_files import LAUNCH_FILE, PACKAGE, REPO, constant, setup_keyword

PIP_REQUIREMENTS = REPO / "requirements-ros.txt"
INSTALL_DOC = REPO / "docs" / "install_ros.md"

PIP = "pip"  # no rosdep key fits: requirements-ros.txt installs it (docs/install_ros.md)
OPTIONAL = "optional"  # imported where used, behind a clear message (cemnet_ros/io/optional.py); pip installs it

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
    "lifecycle_msgs": "lifecycle_msgs",  # the launch file's lifecycle transitions
    "ament_index_python": "ament_index_python",
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "numba": "python3-numba",
    "matplotlib": (OPTIONAL, "matplotlib"),  # the replay figure and the training curves (python3-matplotlib)
    "PIL": (OPTIONAL, "pillow"),  # 7-Scenes depth PNGs, cemnet_ros/data/rgbd.py (python3-pil)
    "tqdm": "python3-tqdm",
    "yaml": "python3-yaml",
    "torch": (PIP, "torch"),  # python3-torch is the distribution's own build, not the pinned 2.13.0 CPU one
    "rosbags": (PIP, "rosbags"),  # only python3-rosbags-pip (`sudo pip`, refused on Ubuntu 24.04: PEP 668)
    "open3d": (OPTIONAL, "open3d-cpu"),  # cemnet-eval's FPFH baseline only
    "kiss_icp": (OPTIONAL, "kiss-icp"),  # the robustness benchmark's peers only (benchmarks)
    "small_gicp": (PIP, "small-gicp"),  # GICP, the polish's wide stage: its Python bindings are on PyPI only
}


# -- imports and package.xml -------------------------------------------------------------------------------
def _imported(node: ast.AST) -> set:
    """Top-level names one node imports: an absolute import, or ``optional_module("name...", ...)``."""
    if isinstance(node, ast.Import):
        return {alias.name.split(".")[0] for alias in node.names}
    if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
        return {node.module.split(".")[0]}
    if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "optional_module" and node.args:
        return {constant(node.args[0]).split(".")[0]}
    return set()


def _imports_in(source: str, filename: str = "<string>") -> set:
    """Top-level third-party names of every absolute import: module level, functions, try/except alike."""
    names = set().union(*(_imported(node) for node in ast.walk(ast.parse(source, filename=filename))))
    return {name for name in names if name not in sys.stdlib_module_names and name != PACKAGE}


def _module_level_imports(source: str, filename: str = "<string>") -> set:
    """The names imported when the module is imported: outside every function body."""
    names: set = set()

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if not isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                names.update(_imported(child))
                visit(child)

    visit(ast.parse(source, filename=filename))
    return names


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


def test_every_declared_runtime_dependency_is_used():
    """Imported by the package or the launch file, or `ros2 launch` itself; RViz2 and `ros2 bag` (started only where
    installed, or when asked for: rviz:=auto, bag:=) are optional extras (docs/install_ros.md), not dependencies."""
    used = {ROSDEP_KEYS[module] for module in _code_imports() if isinstance(ROSDEP_KEYS.get(module), str)}
    unused = sorted(_runtime_keys() - used - {"ros2launch"})
    assert not unused, f"package.xml declares what nothing imports or launches: {unused}"


def test_a_headless_robot_installs_no_viewer_bag_tools_or_plotting():
    heavy = {"rviz2", "ros2bag", "rosbag2_storage_default_plugins", "python3-matplotlib", "python3-pil"}
    assert not heavy & _runtime_keys()
    doc = INSTALL_DOC.read_text()
    assert "ros-jazzy-rviz2" in doc and "ros-jazzy-ros2bag" in doc and "python3-matplotlib" in doc


def test_optional_libraries_are_imported_only_where_they_are_used():
    """A module that imports matplotlib or PIL at module level would make every importer need it."""
    optional = {module for module, entry in ROSDEP_KEYS.items() if isinstance(entry, tuple) and entry[0] == OPTIONAL}
    eager = {str(path.relative_to(REPO)): found for path in (REPO / PACKAGE).rglob("*.py")
             if (found := _module_level_imports(path.read_text(), str(path)) & optional)}
    assert not eager, f"optional libraries imported at module level: {eager}"
    assert _module_level_imports("import matplotlib\ndef f():\n    import PIL\n") == {"matplotlib"}


def test_pip_only_modules_are_in_the_documented_pip_command():
    pip_only = {entry[1] for entry in ROSDEP_KEYS.values() if isinstance(entry, tuple) and entry[0] == PIP}
    missing = sorted(pip_only - _pip_requirements())
    assert not missing, f"{missing} missing from {PIP_REQUIREMENTS.name}"
    (torch_pin,) = [line for line in (REPO / "requirements.txt").read_text().splitlines() if line.startswith("torch")]
    assert torch_pin == "torch==2.13.0", "CI and ./run install the pinned CPU wheel"
    (torch_ros,) = [line for line in PIP_REQUIREMENTS.read_text().splitlines() if line.startswith("torch")]
    setup_torch = next(r for r in setup_keyword("install_requires") if _requirement_name(r) == "torch")
    assert torch_ros == setup_torch and "==" not in torch_ros, "NVIDIA's Jetson build must satisfy it, as installed"
    doc = INSTALL_DOC.read_text()
    assert "rosdep install" in doc and "pip install -r src/cemnet_ros/requirements-ros.txt" in doc


def test_pip_requirements_and_optional_imports_agree_with_setup_py():
    required = {_requirement_name(r) for r in setup_keyword("install_requires")}
    assert _pip_requirements() <= required
    extras = {_requirement_name(r) for group in setup_keyword("extras_require").values() for r in group}
    optional = {entry[1] for entry in ROSDEP_KEYS.values() if isinstance(entry, tuple) and entry[0] == OPTIONAL}
    assert optional <= extras | required, f"optional imports pip cannot install: {sorted(optional - extras - required)}"


# -- the launch file, read with ast ------------------------------------------------------------------------


































# -- setup.py and the RViz config --------------------------------------------------------------------------








def test_package_xml_repeats_the_one_version_string():
    import cemnet_ros

    assert ET.parse(REPO / "package.xml").getroot().findtext("version") == cemnet_ros.__version__
