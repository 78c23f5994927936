"""Test your controller against the simulator in your own pytest suite: the ``gyro_bench`` fixture and its kit.

A pytest plugin, opt-in: ``pytest -p gyro_sim.testing``, or in a ``conftest.py``::

    pytest_plugins = ["gyro_sim.testing"]

(a pytest session that does not ask for it imports nothing of gyro_sim). This is
:mod:`gyro_sim.apps.testing` under its public name: the same module object.
"""
import importlib
import sys

sys.modules[__name__] = importlib.import_module("gyro_sim.apps.testing")
