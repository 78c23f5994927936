"""The optional dependencies of gyro_sim (the pip extras of setup.py) and the one-line message for a missing one.

The core (scenes, runs, recording, plots) needs none of them. A command or function that needs an extra
checks for it **before it does any work** and, where a module is missing, stops with one line naming the
extra to install::

    from gyro_sim.common.extras import require

    require("live", "gyro-sim run --live")   # raises MissingExtra if foxglove is not importable
    # MissingExtra: gyro-sim run --live needs the 'live' extra: pip install 'gyro_sim[live]' (missing: foxglove)

The check finds modules without importing them (``importlib.util.find_spec``: fast, no side effects), so it
can run before anything else. ``gyro-sim`` (gyro_sim/apps/cli.py) turns a :class:`MissingExtra` into
``error: <message>`` on stderr and exit status 2; library code lets it propagate (it is an ``ImportError``).
"""
from __future__ import annotations

import importlib.util
from typing import Optional, Sequence

__all__ = ["EXTRAS", "MissingExtra", "extra_of", "missing", "missing_message", "require"]

#: extra of setup.py → the top-level modules the code imports from it (not every distribution it installs)
EXTRAS: dict[str, tuple[str, ...]] = {
    "ros": ("rclpy",),
    "sweep": ("dask", "distributed", "pyarrow"),  # (tqdm too, but a sweep without it runs, without a progress bar)
    "live": ("foxglove", "websockets"),  # foxglove-sdk (the server) and websockets (its relay: gyro_sim.io.live_relay)
    "data": ("pandas", "xarray"),
    "docs": ("pdoc",),
}

#: other top-level modules an extra brings that the code imports (the ROS 2 wheels' interfaces and tools)
_ALSO = {"ros": ("rcl_interfaces", "std_msgs", "geometry_msgs", "sensor_msgs", "rosgraph_msgs", "builtin_interfaces",
                 "diagnostic_msgs", "std_srvs", "tf2_msgs", "ament_index_python", "launch", "launch_ros")}

#: how the message names an extra whose modules are better known by another name, and what else provides it
_NAMED = {"ros": ("the ROS 2 Python packages (rclpy)", " (or source a ROS 2 install)")}


class MissingExtra(ImportError):
    """An optional dependency is not installed; the message is the one line to show (names the extra)."""

    def __init__(self, message: str, extra: str, modules: Sequence[str]):
        super().__init__(message, name=modules[0] if modules else None)
        self.extra = extra
        self.modules = tuple(modules)


def extra_of(module: str):
    """The extra that brings the top-level module ``module``, or None (not an optional dependency)."""
    for extra, modules in EXTRAS.items():
        if module in modules or module in _ALSO.get(extra, ()):
            return extra
    return None


def _found(module: str) -> bool:
    """True if ``module`` can be imported (found on the path, not hidden by ``sys.modules[module] = None``)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a parent package missing, or a module without a spec
        return False


def missing(extra: str, modules: Optional[Sequence[str]] = None) -> list[str]:
    """The modules of ``extra`` (or the given subset of them) that cannot be imported, in order."""
    if extra not in EXTRAS:
        raise ValueError(f"unknown extra {extra!r}; known: {', '.join(EXTRAS)}")
    return [m for m in (EXTRAS[extra] if modules is None else modules) if not _found(m)]


def missing_message(extra: str, what: str, modules: Optional[Sequence[str]] = None, hint: str = "") -> Optional[str]:
    """The one line to show if ``what`` (a command or function) cannot run for want of ``extra``, else None.

    ``modules`` narrows the check to the modules ``what`` imports (default: all of the extra's); ``hint`` is
    appended (e.g. ``"; or --workers 0 to run without Dask"``)."""
    gone = missing(extra, modules)
    if not gone:
        return None
    if extra in _NAMED:
        name, alt = _NAMED[extra]
        return f"{what} needs {name}: pip install 'gyro_sim[{extra}]'{alt}{hint}"
    return f"{what} needs the '{extra}' extra: pip install 'gyro_sim[{extra}]' (missing: {', '.join(gone)}){hint}"


def require(extra: str, what: str, modules: Optional[Sequence[str]] = None, hint: str = "") -> None:
    """Raise :class:`MissingExtra` (one-line message naming the extra) if a module of ``extra`` is missing.

    Call it first thing in whatever needs the extra, so nothing is done before it fails."""
    message = missing_message(extra, what, modules, hint)
    if message is not None:
        raise MissingExtra(message, extra, missing(extra, modules))
