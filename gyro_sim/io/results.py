"""A run's results for the scientific Python tools: :class:`~gyro_sim.simulate.RunResult` as a pandas DataFrame or
an xarray Dataset (units and frames as metadata), its short repr, and a RunResult read back from any recorded bag.

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

from gyro_sim.common.extras import MissingExtra, require

if TYPE_CHECKING:  # pragma: no cover
    from gyro_sim.io.recording import BagData
    from gyro_sim.engine.simulate import RunResult

__all__ = ["to_dataframe", "to_xarray", "result_repr", "read_bag", "result_from_bag", "MissingExtraError",
           "SERIES", "EFFECTS", "INSTALL_DATA"]

INSTALL_DATA = "pip install 'gyro_sim[data]'"
#: the time series of a RunResult: attribute → (unit, frame, description). The frame of omega_b, spin_rate and
#: modes is the case frame in a run without attitude (:func:`_frame`).
SERIES = {
    "L": ("N m s", "case", "angular momentum L"),
    "q": ("1", "body to case", "attitude quaternion (w, x, y, z), body to case"),
    "omega_b": ("rad/s", "body", "angular velocity of the rotor"),
    "euler": ("rad", "L-frame", "Euler angles psi, theta, phi of the body in the L-frame"),
    "torque": ("N m", "case", "electrodynamic torque on the rotor"),
    "energy": ("J", "", "rotational kinetic energy"),
    "spin_rate": ("rad/s", "body", "spin rate about the polar axis x3 (|Omega| without attitude)"),
    "current": ("A", "", "stator current amplitude"),
    "field_rate": ("rad/s", "", "signed rotation rate of the stator's field"),
    "field_phase": ("rad", "", "phase of the stator's field"),
    "modes": ("T", "body", "eddy-mode states e_n"),
}
#: the outputs of the effects that are on (RunResult.effects; Simulator.effect_outputs): key → (unit, frame, text)
EFFECTS = {
    "flywheel_speed": ("rad/s", "", "flywheel speed"),
    "flywheel_angle": ("rad", "", "flywheel angle"),
    "damper_offset": ("m", "body", "damper mass offset"),
    "damper_velocity": ("m/s", "body", "damper mass velocity"),
    "vertical_angle": ("rad", "", "angle between x3 and the unbalance's vertical"),
}
XYZ = ("x", "y", "z")
WXYZ = ("w", "x", "y", "z")
ANGLES = ("psi", "theta", "phi")


#: an optional dependency of the ``data`` extra (pandas, xarray) is not importable (gyro_sim.extras' one-line error)
MissingExtraError = MissingExtra


def _need(module: str, what: str):
    """The module ``module`` of the ``data`` extra, imported; else MissingExtraError naming ``what`` needs it
    (checked before any work: :func:`gyro_sim.extras.require`)."""
    require("data", what, (module,))
    import importlib

    return importlib.import_module(module)


def _frame(res: "RunResult", name: str) -> str:
    """The frame of series ``name`` of ``res`` ("" where none): without attitude omega_b and the modes are in the
    case frame and spin_rate is |Ω| (no frame)."""
    frame = (SERIES.get(name) or EFFECTS.get(name) or ("", "", ""))[1]
    if res.attitude or name not in ("omega_b", "modes", "spin_rate"):
        return frame
    return "" if name == "spin_rate" else "case"


def _run_attrs(res: "RunResult") -> dict:
    """The run's metadata (netCDF-storable: str, int, float): scene, attitude (1/0), steps, end time (s), and the
    error estimate (relative error of L, attitude rad, tolerances, met 1/0) where the run has one."""
    from gyro_sim.engine.simulate import error_summary

    attrs = {"scene": res.scene.name, "attitude": int(bool(res.attitude)), "steps": int(res.steps),
             "t_end": float(res.t[-1]) if len(res.t) else 0.0}
    est = res.error_estimate
    if est is not None:
        for key, value in error_summary(est).items():
            attrs[key] = int(value) if isinstance(value, bool) else float(value)
        attrs["error_estimate"] = est.text()
    return attrs


def _columns(res: "RunResult") -> list:
    """(column name, values (n,), series) of the DataFrame, in order: vectors ``<series>_<component>``, Euler
    angles ``psi``/``theta``/``phi``, per stator ``<series>_<stator name>``, then the effects' outputs."""
    cols = []
    for name, comps in (("L", XYZ), ("q", WXYZ), ("omega_b", XYZ)):
        a = getattr(res, name)
        cols += [(f"{name}_{c}", a[:, i], name) for i, c in enumerate(comps)]
    eul = res.euler
    cols += [(c, eul[:, i], "euler") for i, c in enumerate(ANGLES)]
    cols += [(f"torque_{c}", res.torque[:, i], "torque") for i, c in enumerate(XYZ)]
    cols += [("energy", res.energy, "energy"), ("spin_rate", res.spin_rate, "spin_rate")]
    for name in ("current", "field_rate", "field_phase"):
        a = getattr(res, name)
        cols += [(f"{name}_{s}", a[:, k], name) for k, s in enumerate(res.stator_names)]
    for name, a in (res.effects or {}).items():
        a = np.asarray(a)
        cols += ([(name, a, name)] if a.ndim == 1 else [(f"{name}_{c}", a[:, i], name) for i, c in enumerate(XYZ)])
    return cols


def to_dataframe(res: "RunResult"):
    """``res`` as a pandas DataFrame: index ``t`` (s), one float column per component (the arrays' values, not
    copies of other numbers): ``L_x, L_y, L_z`` (N m s, case frame), ``q_w … q_z`` (body to case), ``omega_b_x …``
    (rad/s, body frame), ``psi, theta, phi`` (rad, L-frame), ``torque_x …`` (N m, case frame), ``energy`` (J),
    ``spin_rate`` (rad/s), ``current_<stator>`` (A), ``field_rate_<stator>`` (rad/s), ``field_phase_<stator>`` (rad)
    and the effects' outputs (``flywheel_speed``, ``damper_offset_x`` …). The eddy modes are left out (see
    :func:`to_xarray`).

    ``df.attrs``: ``units`` and ``frames`` (column → unit string / frame, "" where none) and the run's metadata
    (``scene``, ``attitude``, ``steps``, ``t_end``, the error estimate: :func:`to_xarray`)."""
    pd = _need("pandas", "RunResult.to_dataframe()")
    cols = _columns(res)
    index = pd.Index(np.asarray(res.t, dtype=float), name="t")
    df = pd.DataFrame({name: np.asarray(v, dtype=float) for name, v, _ in cols}, index=index)
    units = {name: (SERIES.get(s) or EFFECTS.get(s, ("",)))[0] for name, _, s in cols}
    frames = {name: _frame(res, s) for name, _, s in cols}
    df.attrs.update(_run_attrs(res), units={"t": "s", **units}, frames=frames)
    return df


def _var(res: "RunResult", name: str, dims: tuple, values):
    """(dims, values, attrs) of one Dataset variable: units, long name, frame."""
    unit, _, text = SERIES.get(name) or EFFECTS.get(name, ("", "", name))
    attrs = {"units": unit, "long_name": text}
    frame = _frame(res, name)
    if frame:
        attrs["frame"] = frame
    return dims, np.asarray(values, dtype=float), attrs


def to_xarray(res: "RunResult"):
    """``res`` as an xarray Dataset. Dims: ``time`` (s), ``component`` (x, y, z), ``quaternion`` (w, x, y, z),
    ``angle`` (psi, theta, phi), ``stator`` (the stator names), ``mode`` (1 … N). Variables, each with attrs
    ``units``, ``long_name`` and ``frame``: L (N m s, case), q (body to case), omega_b (rad/s, body; case without
    attitude), euler (rad, L-frame), torque (N m, case), energy (J), spin_rate (rad/s), current (A), field_rate
    (rad/s), field_phase (rad) per stator, modes (T, body; (time, mode, component)), and the effects' outputs.

    Dataset attrs: ``scene`` (name), ``attitude`` (1/0), ``steps``, ``t_end`` (s) and, where the run has an error
    estimate, ``error_L`` (relative), ``error_attitude`` (rad), ``accuracy_rtol``, ``accuracy_attitude``,
    ``accuracy_met`` (1/0) and ``error_estimate`` (one line of text)."""
    xr = _need("xarray", "RunResult.to_xarray()")
    T = ("time",)
    n_modes = res.modes.shape[1] // 3
    data = {
        "L": _var(res, "L", T + ("component",), res.L),
        "q": _var(res, "q", T + ("quaternion",), res.q),
        "omega_b": _var(res, "omega_b", T + ("component",), res.omega_b),
        "euler": _var(res, "euler", T + ("angle",), res.euler),
        "torque": _var(res, "torque", T + ("component",), res.torque),
        "energy": _var(res, "energy", T, res.energy),
        "spin_rate": _var(res, "spin_rate", T, res.spin_rate),
        "current": _var(res, "current", T + ("stator",), res.current),
        "field_rate": _var(res, "field_rate", T + ("stator",), res.field_rate),
        "field_phase": _var(res, "field_phase", T + ("stator",), res.field_phase),
        "modes": _var(res, "modes", T + ("mode", "component"), np.asarray(res.modes).reshape(-1, n_modes, 3)),
    }
    for name, a in (res.effects or {}).items():
        a = np.asarray(a)
        data[name] = _var(res, name, T if a.ndim == 1 else T + ("component",), a)
    coords = {"time": ("time", np.asarray(res.t, dtype=float), {"units": "s", "long_name": "simulation time"}),
              "component": list(XYZ), "quaternion": list(WXYZ), "angle": list(ANGLES),
              "stator": list(res.stator_names), "mode": np.arange(1, n_modes + 1)}
    return xr.Dataset(data, coords=coords, attrs=_run_attrs(res))


# --- repr -----------------------------------------------------------------------------------------------

def result_repr(res: "RunResult") -> str:
    """A few lines: scene, simulated time, samples, steps, attitude; final spin rate, θ, |L|; the error estimate.
    A result whose series are still in its bag (:meth:`RunResult.lazy`) is not read: its preview gives the finals."""
    d = res.__dict__
    unread = d.get("_load") is not None
    p = res.preview()
    n = len(p.t)
    samples = "samples in its bag (read on first use)" if unread else f"{n} samples"
    if n == 0:
        return f"<RunResult {p.scene.name!r}: no samples>"
    t_end = float(p.t[-1])
    head = (f"<RunResult {p.scene.name!r}: {t_end:g} s, {samples}, {int(p.steps)} steps, "
            f"attitude {'yes' if p.attitude else 'no'}")
    spin = float(p.spin_rate[-1])
    theta = f"θ {math.degrees(float(p.theta[-1])):.4g}°" if p.attitude else "θ n/a (no attitude)"
    final = (f" final: spin {spin:.6g} rad/s ({spin / (2 * math.pi):.4g} rev/s), {theta}, "
             f"|L| {float(np.linalg.norm(p.L[-1])):.6g} N·m·s")
    est = p.error_estimate
    err = (" error estimate: " + est.text() + (", met" if est.met else ", NOT met")) if est is not None \
        else " error estimate: none"
    return "\n".join((head, final, err)) + ">"


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


def _bag_commands(data: "BagData", grid: dict) -> list:
    """The commands a bag holds as RunResult.commands: (t s, names, currents A | None, rates rad/s | None)."""
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


def _bag_effects(data: "BagData") -> dict:
    """RunResult.effects of the /gyro/effects channels a bag holds (flywheel, damper)."""
    effects = {}
    if "flywheel" in data.effects:
        effects["flywheel_angle"] = data.effects["flywheel"][:, 0].copy()
        effects["flywheel_speed"] = data.effects["flywheel"][:, 1].copy()
    if all(f"damper_{a}" in data.effects for a in "xyz"):
        effects["damper_offset"] = np.stack([data.effects[f"damper_{a}"][:, 0] for a in "xyz"], axis=1)
        effects["damper_velocity"] = np.stack([data.effects[f"damper_{a}"][:, 1] for a in "xyz"], axis=1)
    return effects


def read_bag(bag: Union[str, os.PathLike, "BagData"], scene=None, duration: Optional[float] = None,
             control_period: Optional[float] = None) -> "RunResult":
    """A :class:`~gyro_sim.simulate.RunResult` of a gyro_sim bag: recorded in-process (``gyro-sim run --record``,
    :func:`~gyro_sim.recording.record_result`, :func:`~gyro_sim.recording.record_run`) or by the ROS simulator node.
    ``bag``: a bag directory, its .mcap file, or its :class:`~gyro_sim.recording.BagData` (the raw topics:
    :func:`gyro_sim.recording.read_bag`).

    ``scene``: a Scene, a built-in name or a path (default: the scene text in the bag). The sample times are the
    simulation's own grid (the Runner's for ``duration`` and ``control_period`` as the run had them; defaults from
    the bag's custom data, else the scene's): the same bits as the in-process run, not the ns stamps rounded.
    ``energy`` is ½ Ω_b·J Ω_b of the scene's inertia; ``commands`` are those the bag holds (the controller's, the
    scene's schedule and the watchdog's zeroing as applied: not the scene's initial settings); ``modes`` (not
    recorded) has no columns; ``wall_time``, ``steps`` and the error estimate come from the bag's custom data
    (``compile_time`` too where the recorder wrote it). Bags always hold the attitude (``attitude`` True)."""
    from gyro_sim.scenes.accuracy import ErrorEstimate
    from gyro_sim.io.recording import BagData
    from gyro_sim.io.recording import read_bag as read_bag_data
    from gyro_sim.engine.simulate import RunResult, kinetic_energy

    data = bag if isinstance(bag, BagData) else read_bag_data(bag)
    scene = _bag_scene(data, scene)
    custom = data.custom
    if control_period is None:
        control_period = _custom_float(custom, "gyro_sim.control_period")
    grid = _grid(scene, data, duration, control_period)
    t = np.array([grid.get(ns, ns / 1e9) for ns in data.t_ns.tolist()], dtype=float)
    est = custom.get("gyro_sim.error_estimate")
    try:
        est = ErrorEstimate.from_json(est) if est else None
    except (ValueError, TypeError):  # (a bag of another version: no estimate rather than no result)
        est = None
    return RunResult(scene=scene, t=t, L=data.L, q=data.q, omega_b=data.omega_b, torque=data.torque,
                     energy=kinetic_energy(scene.inertia, data.omega_b), stator_names=list(data.stator_names),
                     current=data.current, field_rate=data.rate, field_phase=data.phase, modes=np.zeros((t.size, 0)),
                     wall_time=_custom_float(custom, "gyro_sim.wall_time") or 0.0,
                     compile_time=_custom_float(custom, "gyro_sim.compile_time") or 0.0,
                     steps=int(_custom_float(custom, "gyro_sim.steps") or 0), commands=_bag_commands(data, grid),
                     effects=_bag_effects(data), attitude=True, error_estimate=est)


#: the name gyro_sim.testing has used (the pytest kit's BenchRun.result)
result_from_bag = read_bag
