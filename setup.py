"""ament_python package definition; also a plain pip-installable package with console scripts."""
import re
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

package_name = "cemnet_ros"
# The one version string is cemnet_ros.__version__ (package.xml repeats it: ament needs a literal; a test checks).
version = re.search(r'__version__ = "([^"]+)"', (Path(__file__).parent / package_name / "__init__.py").read_text())[1]

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
        "matplotlib>=3.7",
        "pillow>=9",  # depth PNGs (7-Scenes); matplotlib needs it too
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
    zip_safe=True,
    maintainer="cemnet_ros maintainers",
    maintainer_email="maintainers@cemnet-ros.invalid",
    description="Online point cloud alignment with CEMNet for ROS 2",
    license="MIT",
    tests_require=["pytest"],
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
