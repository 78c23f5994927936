"""A run's results for the scientific Python tools: :class:`~gyro_sim.engine.result.RunResult` as a pandas DataFrame
or an xarray Dataset (units and frames as metadata, :mod:`gyro_sim.engine.result`), its short repr, and a RunResult
read back from any recorded bag (here).

pandas and xarray are the optional extra ``data`` (``pip install 'gyro_sim[data]'``): imported on first use only,
and where they are missing :class:`MissingExtraError` (an ImportError) says so before any work is done. Units are
UDUNITS/CF strings (``"N m s"``, ``"rad/s"``), readable by pint-xarray and cf-xarray and storable in netCDF.

Use::

    res = gyro_sim.run(gyro_sim.load_scene("spinup_thin_shell"), duration=10.0)
    df = res.to_dataframe()          # index t (s); columns L_x … current_z1; df.attrs["units"]["L_x"] == "N m s"
    ds = res.to_xarray()             # ds.L.sel(component="z"); ds.current.sel(stator="z1"); ds.attrs["scene"]
    res = gyro_sim.read_bag("runs/bag1")   # a RunResult of a bag (in-process --record or the ROS node)
"""
from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING, Optional, Union

import numpy as np

from gyro_sim.engine.result import (EFFECTS, INSTALL_DATA, SERIES, MissingExtraError, result_repr, to_dataframe,
                                    to_xarray)

if TYPE_CHECKING:  # pragma: no cover
    from gyro_sim.engine.result import RunResult
    from gyro_sim.scenes.accuracy import ErrorEstimate
    from gyro_sim.io.recording import BagData

__all__ = ["to_dataframe", "to_xarray", "result_repr", "read_bag", "result_from_bag", "bag_commands",
           "parse_error_estimate", "MissingExtraError",
           "SERIES", "EFFECTS", "INSTALL_DATA"]

# --- a RunResult from a bag --------------------------------------------------------------------------

def _bag_scene(data: "BagData", scene):
    """The Scene of a bag: ``scene`` (a Scene, a built-in name or a path), else the scene text the bag holds."""
    from gyro_sim.scenes.scene import Scene, load_scene, parse_scene_text, scene_from_dict

    if isinstance(scene, Scene):
        return scene
    if scene is not None:
        return load_scene(scene)
    if not data.scene_text:
        raise ValueError("read_bag: the bag holds no scene (not recorded by gyro_sim?); give scene=")
    return scene_from_dict(parse_scene_text(data.scene_text, "the bag's scene"), where="the bag's scene",
                           default_name=data.scene_name or "scene")


def _custom_float(custom: dict, key: str) -> Optional[float]:
    """custom_data ``key`` as a float, None where absent or not a number."""
    try:
        return float(custom[key])
    except (KeyError, TypeError, ValueError):
        return None


def _grid(scene, data: "BagData", duration: Optional[float], control_period: Optional[float]) -> dict:
    """ns stamp → the Runner's sample time (s) of the run the bag holds: its exact float instants, not ns / 1e9."""
    from gyro_sim.io.messages import stamp_ns
    from gyro_sim.engine.simulate import controller_period, output_times

    T = duration or _custom_float(data.custom, "gyro_sim.planned_duration") or scene.duration
    try:
        t_out, _ = output_times(scene, float(T), control_period or controller_period(scene))
        return {stamp_ns(x): x for x in t_out.tolist()}
    except Exception:  # noqa: BLE001 - a scene or duration the Runner would not take here: the stamps as they are
        return {}


def bag_commands(data: "BagData", grid: Optional[dict] = None) -> list:
    """The commands a bag holds as RunResult.commands: (t s, names, currents A | None, rates rad/s | None); a
    NaN column is a stator the command does not set. ``grid`` (ns stamp → the run's exact instant, :func:`_grid`)
    gives the times their float bits; without it they are the stamps in s."""
    grid = grid or {}
    names = list(data.stator_names)
    out = []
    for i, tc in enumerate(data.command_t.tolist()):
        cur, rate = data.command_current[i], data.command_rate[i]
        cols = [j for j in range(len(names)) if not (math.isnan(cur[j]) and math.isnan(rate[j]))]
        currents = [None if math.isnan(cur[j]) else float(cur[j]) for j in cols]
        rates = [None if math.isnan(rate[j]) else float(rate[j]) for j in cols]
        out.append((grid.get(int(round(tc * 1e9)), tc), [names[j] for j in cols],
                    None if all(c is None for c in currents) else currents,
                    None if all(x is None for x in rates) else rates))
    return out


def parse_error_estimate(text) -> "Optional[ErrorEstimate]":
    """A bag's ``gyro_sim.error_estimate`` custom data as an ErrorEstimate; None where absent or unreadable (a bag
    of another version: no estimate rather than no result)."""
    from gyro_sim.scenes.accuracy import ErrorEstimate

    if not text:
        return None
    try:
        return ErrorEstimate.from_json(str(text))
    except (ValueError, TypeError, KeyError):
        return None


def read_bag(bag: Union[str, os.PathLike, "BagData"], scene=None, duration: Optional[float] = None,
             control_period: Optional[float] = None) -> "RunResult":
    """A :class:`~gyro_sim.simulate.RunResult` of a gyro_sim bag: recorded in-process (``gyro-sim run --record``,
    :func:`~gyro_sim.recording.record_result`, :func:`~gyro_sim.recording.record_run`) or by the ROS simulator node.
    ``bag``: a bag directory, its .mcap file, or its :class:`~gyro_sim.recording.BagData` (the raw topics:
    :func:`gyro_sim.recording.read_bag`).

    ``scene``: a Scene, a built-in name or a path (default: the scene text in the bag). The sample times are the
    simulation's own grid (the Runner's for ``duration`` and ``control_period`` as the run had them; defaults from
    the bag's custom data, else the scene's): the same bits as the in-process run, not the ns stamps rounded.
    ``energy`` is the rotor's with its internal bodies (:func:`gyro_sim.engine.model.system_energy`); ``commands``
    are those the bag holds (the controller's, the scene's schedule and the watchdog's zeroing as applied: not the
    scene's initial settings); ``modes`` (not recorded) has no columns; ``wall_time``, ``steps`` and the error
    estimate come from the bag's custom data (``compile_time`` too where the recorder wrote it). Bags always hold
    the attitude (``attitude`` True)."""
    from gyro_sim.io.bag_reader import bag_effects
    from gyro_sim.io.recording import BagData
    from gyro_sim.io.recording import read_bag as read_bag_data
    from gyro_sim.engine.simulate import RunResult, system_energy

    data = bag if isinstance(bag, BagData) else read_bag_data(bag)
    scene = _bag_scene(data, scene)
    custom = data.custom
    if control_period is None:
        control_period = _custom_float(custom, "gyro_sim.control_period")
    grid = _grid(scene, data, duration, control_period)
    t = np.array([grid.get(ns, ns / 1e9) for ns in data.t_ns.tolist()], dtype=float)
    est = parse_error_estimate(custom.get("gyro_sim.error_estimate"))
    end = str(custom.get("gyro_sim.end") or "")  # (a run whose state broke: "failed: <what> at t = … s")
    return RunResult(scene=scene, t=t, L=data.L, q=data.q, omega_b=data.omega_b, torque=data.torque,
                     energy=system_energy(scene, data.omega_b, bag_effects(data)), stator_names=list(data.stator_names),
                     current=data.current, field_rate=data.rate, field_phase=data.phase, modes=np.zeros((t.size, 0)),
                     wall_time=_custom_float(custom, "gyro_sim.wall_time") or 0.0,
                     compile_time=_custom_float(custom, "gyro_sim.compile_time") or 0.0,
                     steps=int(_custom_float(custom, "gyro_sim.steps") or 0), commands=bag_commands(data, grid),
                     effects=bag_effects(data), attitude=True, error_estimate=est,
                     failure=end if end.startswith("failed:") else None)


#: the name gyro_sim.testing has used (the pytest kit's BenchRun.result)
result_from_bag = read_bag
