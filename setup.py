"""ament_python package definition; also a plain pip-installable package with console scripts.

The console scripts start ``/usr/bin/env python3`` (setup.cfg ``[build_scripts]``): the python3 on PATH when the node
runs (an activated venv with torch), not the interpreter that built them (colcon's may be the system's). Before
``install``/``develop`` (what colcon runs) that python3 is checked: a missing torch fails the build with the fix
(cemnet_ros/tools/runtime_check.py). pip builds wheels (``install --root``) and writes its own scripts: no check.
"""
import importlib.util
import os
import re
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup
from setuptools.command.develop import develop
from setuptools.command.install import install

package_name = "cemnet_ros"
# The one version string is cemnet_ros.__version__ (package.xml repeats it: ament needs a literal; a test checks).
version = re.search(r'__version__ = "([^"]+)"', (Path(__file__).parent / package_name / "__init__.py").read_text())[1]


def check_runtime_python():
    """Exit with the fix when the python3 that will run the executables cannot import the node's dependencies."""
    path = Path(__file__).parent / package_name / "tools" / "runtime_check.py"
    spec = importlib.util.spec_from_file_location("cemnet_runtime_check", path)
    check = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(check)
    if os.environ.get(check.SKIP_VARIABLE):
        return
    message = check.problem()
    if message is not None:
        raise SystemExit(message)


class Install(install):
    """``setup.py install`` (colcon build): the runtime check first, unless staging into a root (a wheel, a deb)."""

    def run(self):
        if not self.root:
            check_runtime_python()
        super().run()


class Develop(develop):
    """``setup.py develop`` (colcon build --symlink-install): the check, and the wrapper scripts with the same
    ``/usr/bin/env python3`` line as ``install`` writes (develop would write the building interpreter's)."""

    def run(self):
        check_runtime_python()
        super().run()

    def install_wrapper_scripts(self, dist):
        from setuptools.command.easy_install import ScriptWriter

        header = ScriptWriter.get_header(executable=self.get_finalized_command("build_scripts").executable)
        for args in ScriptWriter.best().get_args(dist, header):
            self.write_script(*args)


setup(
    name=package_name,
    version=version,
    packages=find_packages(exclude=["test", "test.*", "benchmarks", "benchmarks.*"]),
    package_data={package_name: ["weights/*.npz", "weights/*.md"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml") + glob("config/*.xml")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
        ("share/" + package_name + "/rviz", glob("rviz/*.rviz")),
    ],
    python_requires=">=3.10",
    install_requires=[
        "numpy>=1.24",
        "scipy>=1.10",
        "numba>=0.59",
        "small-gicp>=1.0",  # GICP: the wide stage of the polish (cemnet_ros/pipeline/steps/basin.py, map/gicp_cloud.py)
        # The CPU wheel is pinned in requirements.txt (torch==2.13.0); an unpinned install pulls a CUDA build.
        "torch>=2.2",
        "tqdm>=4.60",
        # the tools' figures and depth PNGs, not the node's: package.xml leaves them out (cemnet_ros/io/optional.py)
        "matplotlib>=3.7",
        "pillow>=9",
        "rosbags>=0.10",
        "mcap>=1.1",
        "pyyaml>=6.0",
    ],
    extras_require={
        "test": ["pytest>=7", "colcon-common-extensions", "ruff>=0.17,<0.18", "mypy>=2.4,<3"],
        "ros": ["ros-jazzy-rclpy[fastrtps]", "ros-jazzy-common-interfaces"],
        "open3d": ["open3d-cpu>=0.18"],
        "bench": ["kiss-icp", "genz-icp", "evo"],
    },
    cmdclass={"install": Install, "develop": Develop},
    zip_safe=True,
    maintainer="cemnet_ros maintainers",
    maintainer_email="maintainers@cemnet-ros.invalid",
    description="Online point cloud alignment with CEMNet for ROS 2",
    license="MIT",
    entry_points={
        "console_scripts": [
            "align_node = cemnet_ros.ros.entry_points:align_node",
            "align_lifecycle_node = cemnet_ros.ros.entry_points:align_lifecycle_node",
            "cemnet-register = cemnet_ros.tools.register_cli:main",
            "cemnet-eval = cemnet_ros.tools.eval_cli:main",
            "cemnet-bench = cemnet_ros.tools.bench_cli:main",
            "cemnet-replay = cemnet_ros.tools.replay_cli:main",
            "cemnet-train = cemnet_ros.tools.train_cli:main",
            "cemnet-convert-weights = cemnet_ros.tools.convert_weights_cli:main",
            "cemnet-warm-kernels = cemnet_ros.tools.warm_kernels:main",
        ],
    },
)
