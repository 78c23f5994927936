"""PEP 517 backend: setuptools' own, run on a copy of the source tree.

setuptools builds in place: ``pip install .`` would leave ``build/`` and ``gyro_sim.egg-info`` in the checkout, and
setup.py's kernel compile (build_support/precompile_kernels.py) would start from the developer's own numba cache.
Here a wheel or sdist is built from a fresh copy of the files a release holds (:data:`TREE`) in a temporary folder,
and the checkout is left as it was. Editable installs (``pip install -e .``) build in place: they are the checkout."""
import os
import shutil
import tempfile
from contextlib import contextmanager

from setuptools import build_meta as _orig

from precompile_kernels import scenes_asked

__all__ = ["build_wheel", "build_sdist", "get_requires_for_build_wheel", "get_requires_for_build_sdist",
           "prepare_metadata_for_build_wheel", "build_editable", "get_requires_for_build_editable",
           "prepare_metadata_for_build_editable"]

#: what a release is made of (files and folders of the checkout)
TREE = ["setup.py", "setup.cfg", "pyproject.toml", "MANIFEST.in", "package.xml", "README.md", "LICENSE",
        "build_support", "gyro_sim", "gyro_ctl", "config", "launch", "resource", "scripts"]
#: what the kernel compile of a wheel build imports (the bounds of pyproject.toml's dependencies): asked for by
#: the wheel build alone, so an editable install (which compiles nothing) does not fetch them into its build env
KERNEL_REQUIRES = ("numpy>=2.0", "scipy>=1.13.1", "numba>=0.60", "pyyaml>=6", "pydantic>=2.5")
_SKIP = shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc", "*.egg-info")


@contextmanager
def _copy():
    """A temporary copy of the tree, made the working folder."""
    src = os.getcwd()
    with tempfile.TemporaryDirectory(prefix="gyro_sim-build-") as tmp:
        for name in TREE:
            p = os.path.join(src, name)
            if os.path.isdir(p):
                shutil.copytree(p, os.path.join(tmp, name), ignore=_SKIP)
            elif os.path.exists(p):
                shutil.copy2(p, tmp)
        os.chdir(tmp)
        try:
            yield
        finally:
            os.chdir(src)


def _out(directory):
    return os.path.abspath(directory)


def get_requires_for_build_wheel(config_settings=None):
    """setuptools' needs, and what the kernel compile imports (none with GYRO_SIM_PRECOMPILE=0)."""
    with _copy():
        own = _orig.get_requires_for_build_wheel(config_settings)
    return own + (list(KERNEL_REQUIRES) if scenes_asked() is not None else [])


def get_requires_for_build_sdist(config_settings=None):
    with _copy():
        return _orig.get_requires_for_build_sdist(config_settings)


def prepare_metadata_for_build_wheel(metadata_directory, config_settings=None):
    d = _out(metadata_directory)
    with _copy():
        return _orig.prepare_metadata_for_build_wheel(d, config_settings)


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    d = _out(wheel_directory)
    m = _out(metadata_directory) if metadata_directory else None
    with _copy():
        return _orig.build_wheel(d, config_settings, m)


def build_sdist(sdist_directory, config_settings=None):
    d = _out(sdist_directory)
    with _copy():
        return _orig.build_sdist(d, config_settings)


# editable installs: in place (setuptools' own hooks)
build_editable = _orig.build_editable
get_requires_for_build_editable = _orig.get_requires_for_build_editable
prepare_metadata_for_build_editable = _orig.prepare_metadata_for_build_editable
