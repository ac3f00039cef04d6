"""ament_python / pip packaging of vjm_ros."""

from glob import glob

from setuptools import find_packages, setup

package_name = "vjm_ros"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "benchmarks", "benchmarks.*"]),
    package_data={"vjm_ros.scene": ["builtin/*.yaml"], "vjm_ros.logs": ["ros2_types.json"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    python_requires=">=3.10",
    install_requires=[
        "numpy>=1.24,<3",
        "scipy>=1.10,<2",
        "PyYAML>=6,<7",
        "matplotlib>=3.6,<4",
        # 1.4 is the first reader that reads indexed ROS 2 files in time order correctly.
        "mcap>=1.4,<2",
        "mcap-ros2-support>=0.5,<1",
        # vjm_ros/logs/mcap_block.py compresses the MCAP chunks itself (one zstd compressor kept
        # for the whole file, at a chosen level; lz4 on request), importing both directly: mcap
        # requires them too, but without a range. Lower bounds: the first releases with wheels
        # for CPython 3.10, the lowest Python allowed here.
        "zstandard>=0.16,<1",
        "lz4>=4,<5",
        "rerun-sdk>=0.41,<0.42",
        # ROS 2 message definitions and type hashes for the logs (a pure-Python bag library).
        "rosbags>=0.11,<0.12",
        # Compiled physics kernel (vjm_ros/core/kernels.py): ~30x per evaluation. 0.64 is the first
        # release whose requirements admit numpy 2.4; without numba the numpy reference is used.
        "numba>=0.64,<1",
    ],
    extras_require={
        "test": [
            "pytest>=8",
            "pytest-benchmark>=4",
            "hypothesis>=6.100",
            "ruff>=0.5",
            # Holds the package's layering (docs/design.md section 7) in the test suite.
            "import-linter>=2.16,<3",
        ],
        # MuJoCo side by side in `vjm bench`; 4.0.0 has a sparse-Cholesky bug fixed in 4.0.1.
        "compare": ["mujoco>=3.2,!=4.0.0"],
        # `vjm sweep` / `vjm tune` on Dask distributed, results as Parquet.
        "sweep": ["distributed>=2024.8", "pyarrow>=15"],
        # URDF models in (`vjm import`) and the check of the URDF export: a maintained parser
        # that also computes forward kinematics, so the export is read by code we did not write.
        "formats": ["yourdfpy>=0.0.56"],
    },
    zip_safe=True,
    maintainer="vjm_ros maintainers",
    maintainer_email="vjm_ros@example.com",
    description="Planar closed-chain mechanisms by the virtual joint method, as a ROS 2 node and replayable logs.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "vjm = vjm_ros.app.cli:main",
            "vjm_sim_node = vjm_ros.ros.node:main",
            "vjm_pd_controller = vjm_ros.ros.controller:main",
            "vjm_ct_controller = vjm_ros.ros.computed_torque:main",
        ],
    },
)
