"""The parts of the build that pyproject.toml cannot say (PEP 621 metadata and dependencies are there).

colcon's ament_python runs this file (``setup.py build install`` / ``setup.py develop``), pip runs it through the
backend named in pyproject.toml. It adds, in the style of ros2/examples:

* data_files: the ament index markers, the manifests, config/*.yaml|json and the launch file under
  ``<prefix>/share``, the ``ros2 run`` executables under ``<prefix>/lib`` (setup.cfg puts the console scripts
  there too), so ``ros2 run gyro_sim ...``, ``ros2 launch gyro_sim gyro_sim.launch.py`` and
  ``get_package_share_directory`` work with either tool (with ``pip install -e``, ``gyro-sim ros-index`` lays
  them out: gyro_sim/ros/index.py);
* the compile of the numba kernels into the package at build time (build_support/precompile_kernels.py): after
  ``pip install .``, ``colcon build`` (plain or ``--symlink-install``) the first run compiles nothing.
"""
from glob import glob
import os
import sys

from setuptools import find_packages, setup
from setuptools.command.build_py import build_py
from setuptools.command.develop import develop

# realpath: colcon build --symlink-install runs a symlink to this file from the build folder
here = os.path.dirname(os.path.realpath(__file__))
sys.path.insert(0, os.path.join(here, 'build_support'))
from precompile_kernels import precompile  # noqa: E402  (build_support/precompile_kernels.py)

package_name = 'gyro_sim'

# colcon build --symlink-install runs `setup.py develop` in a build folder of links to setup.py, setup.cfg and the
# packages, but not to pyproject.toml, where the metadata is: link it there too
if not os.path.exists('pyproject.toml') and os.path.isfile(os.path.join(here, 'pyproject.toml')):
    os.symlink(os.path.join(here, 'pyproject.toml'), 'pyproject.toml')


class BuildPyWithKernels(build_py):
    """build_py, then the kernels compiled into the built tree (their numba cache ships in the wheel)."""

    def run(self):
        super().run()
        if not getattr(self, 'editable_mode', False):  # (an editable install compiles where the sources are)
            precompile(os.path.abspath(self.build_lib))


class DevelopWithKernels(develop):
    """``setup.py develop`` (colcon build --symlink-install), then the kernels compiled next to the sources."""

    def run(self):
        super().run()
        precompile(os.path.abspath(self.egg_path or os.getcwd()))


setup(
    packages=find_packages(include=['gyro_sim', 'gyro_sim.*', 'gyro_ctl', 'gyro_ctl.*']),
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
    python_requires='>=3.10',  # (pyproject.toml: dynamic, for colcon)
    # numba's on-disk cache (cache=True) is next to the modules: never zipped
    zip_safe=False,
    cmdclass={'build_py': BuildPyWithKernels, 'develop': DevelopWithKernels},
)
