"""Packaging for gyro_sim, in the style of ros2/examples (ament_python).

Works two ways:
  * ``pip install .`` on a machine without ROS (the ROS 2 Python wheels are the
    optional ``ros`` extra: ``pip install '.[ros]'``);
  * ``colcon build`` in a ROS 2 workspace, where ``package.xml`` names the ROS deps.

The data_files put the ament index markers, the manifests, config/*.yaml and the launch file
under ``<prefix>/share`` and the ``ros2 run`` executables under ``<prefix>/lib`` so ``ros2 run
gyro_sim ...``, ``ros2 launch gyro_sim gyro_sim.launch.py`` and ``get_package_share_directory``
work with either tool (with ``pip install -e``, ``gyro-sim ros-index`` lays them out:
gyro_sim/ros/index.py).
"""
from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'gyro_sim'
# realpath: colcon build --symlink-install runs a symlink to this file from the build folder
here = os.path.dirname(os.path.realpath(__file__))


def _read(name):
    with open(os.path.join(here, name), encoding='utf-8') as f:
        return f.read()


setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    # PEP 561 markers: the packages' annotations are for their users' type checkers too
    package_data={'gyro_sim': ['py.typed'], 'gyro_ctl': ['py.typed']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name, 'resource/gyro_ctl']),
        # `ros2 run gyro_sim simulator` and `ros2 run gyro_ctl controller` (gyro_ctl is indexed as a
        # package of its own, with its own manifest)
        ('lib/' + package_name, ['scripts/simulator']),
        ('lib/gyro_ctl', ['scripts/controller']),
        ('share/gyro_ctl', ['resource/gyro_ctl_manifest/package.xml']),
        ('share/' + package_name, ['package.xml']),
        # the scenes, the nodes' parameter files and the Foxglove layout (config/foxglove_layout.json)
        ('share/' + package_name + '/config', sorted(glob('config/*.yaml')) + sorted(glob('config/*.json'))),
        ('share/' + package_name + '/launch', sorted(glob('launch/*.launch.py'))),
    ],
    python_requires='>=3.10',
    install_requires=[
        'numpy>=1.24',
        'scipy>=1.10',
        'numba>=0.59',
        'pyyaml>=6',
        'pydantic>=2.5',
        'matplotlib>=3.7',
        'rosbags>=0.10',
        'mcap>=1.1',
    ],
    extras_require={
        # PyPI wheels of ROS 2 for machines without a ROS install. The lower bounds
        # are the oldest wheels published (ROS 2 Jazzy); newer ones are Kilted.
        'ros': [
            'ros-rclpy>=7.1',
            'ros-rmw-fastrtps-cpp>=8.4',
            'ros-std-msgs>=5.3',
            'ros-geometry-msgs>=5.3',
            'ros-sensor-msgs>=5.3',
            'ros-rosgraph-msgs>=2.0',
            'ros-builtin-interfaces>=2.0',
            'ros-diagnostic-msgs>=5.3',  # /diagnostics
            'ros-std-srvs>=5.3',  # pause / resume / step / reset services
        ],
        # ros2/examples declare test deps as the 'test' extra (tests_require is gone
        # from setuptools).
        'test': [
            'pytest>=7',
            'hypothesis>=6',
            'mpmath>=1.3',  # 50-digit reference values of [M] (2.13) in test_conductor
            'mcap-ros2-support>=0.5',  # independent reader of recorded bags in test_recording
            # `colcon build` of this package in test_packaging (colcon-ros: ament_python packages)
            'colcon-core>=0.21',
            'colcon-ros>=0.5',
            'colcon-python-setup-py>=0.2.9',
            'colcon-package-information>=0.4',  # `colcon list`
            'websockets>=15',  # the test client of the live view (Foxglove WebSocket protocol; proxy=None needs 15)
            # lint and types in CI (test/test_lint.py against test/lint_baseline.json; config in pyproject.toml).
            # The findings depend on the versions: the baseline was made with ruff 0.17 and mypy 2.4.
            'ruff>=0.17',
            'mypy>=2.4',
        ],
        # RunResult.to_dataframe() / to_xarray() (gyro_sim/results.py)
        'data': [
            'pandas>=2.0',
            'xarray>=2024.1',
        ],
        # `gyro-sim run SCENE --live`: the run served over the Foxglove WebSocket protocol
        'live': [
            'foxglove-sdk>=0.14',
        ],
        # the API reference (docs/api, `gyro-sim api-docs`)
        'docs': [
            'pdoc>=14',
        ],
        # `gyro-sim sweep` (gyro_sim/sweep.py): runs on a Dask cluster (local or by scheduler
        # address), results as Parquet, progress bar. The core imports none of these.
        'sweep': [
            'dask[distributed]>=2024.8',
            'pyarrow>=15',
            'tqdm>=4.66',
        ],
    },
    # numba's on-disk cache (cache=True) writes next to the modules: never zipped.
    zip_safe=False,
    maintainer='gyro_sim maintainers',
    maintainer_email='maintainers@example.com',
    description='Simulator of an electrodynamically controlled gyroscope (ROS 2, Python).',
    long_description=_read('README.md'),
    long_description_content_type='text/markdown',
    license='Apache-2.0',
    license_files=['LICENSE'],
    entry_points={
        'console_scripts': [
            'gyro-sim = gyro_sim.apps.cli:main',
            'gyro-sim-simulator = gyro_sim.ros.simulator_node:main',
            'gyro-ctl-controller = gyro_ctl.ros.controller_node:main',
        ],
        # the gyro_bench fixture for a user's own tests of a controller (gyro_sim/apps/testing.py)
        'pytest11': ['gyro_sim = gyro_sim.apps.testing'],
    },
)
