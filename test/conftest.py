"""pytest options: ``--stress`` runs the long stress versions (marker ``slow``)."""
import pytest


def pytest_addoption(parser):
    parser.addoption("--stress", action="store_true", default=False, help="also run the long (slow) stress tests")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--stress"):
        return
    skip = pytest.mark.skip(reason="long stress version: run with --stress")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
