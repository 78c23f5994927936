"""pytest options: ``--stress`` runs the long stress versions (marker ``slow``); ``--fuzz-long`` runs the
property-based tests of test/test_fuzz_limits.py with thousands of examples (default: a few hundred in all)."""
import pytest

# the gyro_bench fixture (gyro_sim's pytest plugin is opt-in: gyro_sim/testing.py)
pytest_plugins = ["gyro_sim.testing"]


def pytest_addoption(parser):
    parser.addoption("--stress", action="store_true", default=False, help="also run the long (slow) stress tests")
    parser.addoption("--fuzz-long", action="store_true", default=False,
                     help="run the fuzz tests of test_fuzz_limits.py with thousands of examples")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--stress"):
        return
    skip = pytest.mark.skip(reason="long stress version: run with --stress")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
