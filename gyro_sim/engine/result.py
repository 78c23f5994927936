"""The result of a run: :class:`RunResult` (time series as NumPy arrays, its summary and error estimate), and its
views for the scientific Python tools: a pandas DataFrame or an xarray Dataset (units and frames as metadata) and
its short repr.

pandas and xarray are the optional extra ``data`` (``pip install 'gyro_sim[data]'``): imported on first use only,
and where they are missing :class:`MissingExtraError` (an ImportError) says so before any work is done. Units are
UDUNITS/CF strings (``"N m s"``, ``"rad/s"``), readable by pint-xarray and cf-xarray and storable in netCDF.
A RunResult read back from a bag is :func:`gyro_sim.io.results.read_bag`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from gyro_sim.common.extras import MissingExtra, require
from gyro_sim.physics.frames import euler_angles, quat_to_matrix
from gyro_sim.scenes.accuracy import ErrorEstimate
from gyro_sim.scenes.scene import Scene


@dataclass
class RunResult:
    """Time series of a run (rows = output samples). Frames: L, torque case; omega_b body.

    A run without attitude (``attitude`` False, :func:`integrates_attitude`) has q, ``euler`` and ``theta``
    NaN, ``omega_b`` = Ω in the case frame (= L/J; the body frame is unknown, the magnitude is the same),
    ``spin_rate`` = |Ω| and its eddy modes in the case frame."""

    scene: Scene
    t: np.ndarray  # (n,) s
    L: np.ndarray  # (n,3) N·m·s, case frame
    q: np.ndarray  # (n,4) quaternion (w,x,y,z) body → case (NaN without attitude)
    omega_b: np.ndarray  # (n,3) rad/s, body frame (case frame without attitude)
    torque: np.ndarray  # (n,3) N·m, case frame (electrodynamic)
    # (n,) J, mechanical energy of the rotor and its internal bodies: ½ Ω·J Ω, plus a flywheel's and a damper mass's
    # kinetic energy and the damper spring's (gyro_sim.engine.model.system_energy)
    energy: np.ndarray
    stator_names: list[str]
    current: np.ndarray  # (n,k) A
    field_rate: np.ndarray  # (n,k) rad/s (signed)
    field_phase: np.ndarray  # (n,k) rad
    modes: np.ndarray  # (n,3N) eddy-mode states e_n, body frame (case frame without attitude), T
    wall_time: float = 0.0  # s, the run's wall time less its numba compile time
    compile_time: float = 0.0  # s of numba compilation during the run (a first use; gyro_sim.compile_watch)
    steps: int = 0
    commands: Sequence = field(default_factory=list)  # (t s, names, currents A|None, rates rad/s|None) as applied
    averaged_segments: list = field(default_factory=list)  # (t0, t1) s run with the averaged model
    averaged_models: list = field(default_factory=list)  # the model of each stretch: "spin-up", "[M]", "[K]"
    averaged_rhs_evaluations: int = 0
    effects: dict = field(default_factory=dict)  # outputs of the effects that are on (Simulator.effect_outputs)
    attitude: bool = True  # whether q was integrated (integrates_attitude)
    # the run's estimated error over its duration, against the scene's accuracy (gyro_sim.accuracy.ErrorEstimate)
    error_estimate: Optional[ErrorEstimate] = None  # None where the run failed (failure)
    failure: Optional[str] = None  # "failed: <what> at t = … s" where the run's state broke (Runner), else None
    _euler: Optional[np.ndarray] = field(default=None, repr=False)
    _load: Optional[object] = field(default=None, repr=False, compare=False)  # see lazy()
    _preview: Optional["RunResult"] = field(default=None, repr=False, compare=False)

    @classmethod
    def lazy(cls, load, preview: "RunResult", **known) -> "RunResult":
        """A result whose time series are read when first used: ``load()`` returns them as a dict of fields
        (a streamed run too long to keep in memory reads them back from its bag: :func:`gyro_sim.recording.
        record_run`). ``known``: the fields known without reading (scene, stator_names, wall_time, steps, ...);
        ``preview``: a decimated copy in memory (:meth:`preview`)."""
        obj = cls.__new__(cls)
        obj.__dict__.update({"averaged_segments": [], "averaged_models": [], "averaged_rhs_evaluations": 0,
                             "attitude": True, "error_estimate": None, "failure": None, "_euler": None},
                            **known)
        obj._load, obj._preview = load, preview
        return obj

    def __getattr__(self, name: str):
        # called only when an attribute is missing: the series of a lazy() result, read on first use
        d = self.__dict__
        load = d.get("_load")
        if load is not None and not name.startswith("__"):
            d["_load"] = None
            d.update(load())
            if name in d:
                return d[name]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def preview(self) -> "RunResult":
        """A result cheap to summarise and plot: this one when its series are in memory; for a :meth:`lazy` one
        not read yet, the decimated copy kept during the run (every k-th output row and the last one, so
        :meth:`summary` gives the same final values)."""
        d = self.__dict__
        return d["_preview"] if d.get("_load") is not None and d.get("_preview") is not None else self

    @property
    def euler(self) -> np.ndarray:
        """(n,3) ψ, θ, φ rad (body in the L-frame): computed from L and q when first read (a run whose
        Euler angles no one reads does no Euler-angle work). Inside averaged stretches ψ and φ are NaN:
        the averaged model has averaged those fast phases out. NaN everywhere in a run without attitude."""
        if self._euler is None and not self.attitude:
            self._euler = np.full((self.t.size, 3), np.nan)
        if self._euler is None:
            eul = euler_angles(quat_to_matrix(self.q), self.L)
            for t0, t1 in self.averaged_segments:  # the rows an averaged stretch wrote: t0 < t ≤ t1
                inside = (self.t > t0 + 1e-12) & (self.t <= t1 + 1e-12)
                eul[inside, 0] = np.nan
                eul[inside, 2] = np.nan
            self._euler = eul
        return self._euler

    @property
    def spin_rate(self) -> np.ndarray:
        """Body angular velocity about the polar axis x3, rad/s; without attitude (no body axis to project
        on) |Ω|, the rate of the isotropic rotor about L."""
        if not self.attitude:
            return np.linalg.norm(self.omega_b, axis=1)
        return self.omega_b[:, 2]

    @property
    def theta(self) -> np.ndarray:
        """Nutation angle θ (rad) between x3 and L."""
        return self.euler[:, 1]

    def to_dataframe(self):
        """The run as a pandas DataFrame: index ``t`` (s), one flat column per component (``L_x``, ``q_w``,
        ``psi``, ``current_z1``, ...), units and frames in ``df.attrs`` (:func:`gyro_sim.results.to_dataframe`).
        Needs the optional extra ``data`` (``pip install 'gyro_sim[data]'``)."""
        return to_dataframe(self)

    def to_xarray(self):
        """The run as an xarray Dataset: dims ``time`` (s), ``component`` (x, y, z), ``stator``, ...; units, frames
        and the run's scene and error estimate as attrs (:func:`gyro_sim.results.to_xarray`). Needs the optional
        extra ``data`` (``pip install 'gyro_sim[data]'``)."""
        return to_xarray(self)

    def __repr__(self) -> str:
        # a few lines (scene, duration, samples, final values, error estimate), not the arrays
        return result_repr(self)

    def summary(self) -> dict:
        """Final values and cost of the run (SI units; θ in degrees, NaN without attitude; spin_rate: see
        :attr:`spin_rate`) and its estimated error (``error_L`` relative, ``error_attitude`` rad, NaN where not a
        result; ``accuracy_met``: within the scene's ``accuracy``; ``failure``: ``failed: <what> at t = … s`` where the
        run's state broke and it stopped there, with no error estimate, else None)."""
        t_end = float(self.t[-1])
        return {
            "scene": self.scene.name,
            "spin_rate": float(self.spin_rate[-1]),
            "spin_rev_s": float(self.spin_rate[-1] / (2 * math.pi)),
            "theta_deg": float(np.degrees(self.theta[-1])),
            "L_norm": float(np.linalg.norm(self.L[-1])),
            "energy": float(self.energy[-1]),
            "t_end": t_end,
            "wall_time": self.wall_time,
            "compile_time": self.compile_time,
            "steps": int(self.steps),
            "realtime_factor": t_end / self.wall_time if self.wall_time > 0 else float("inf"),
            "attitude": self.attitude,
            "failure": self.failure,
            **error_summary(self.error_estimate),
        }


def error_summary(est: Optional[ErrorEstimate]) -> dict:
    """The summary's error keys of an estimate (NaN and None where the run has none)."""
    if est is None:
        return {"error_L": math.nan, "error_attitude": math.nan, "error_phase": math.nan, "accuracy_met": None}
    return {"error_L": est.L, "error_attitude": est.attitude, "error_phase": est.phase, "accuracy_met": est.met,
            "accuracy_rtol": est.rtol, "accuracy_attitude": est.atol, "accuracy_phase": est.phase_tol}


# --- views: DataFrame, Dataset, repr --------------------------------------------------------------------

INSTALL_DATA = "pip install 'gyro_sim[data]'"
#: the time series of a RunResult: attribute → (unit, frame, description). The frame of omega_b, spin_rate and
#: modes is the case frame in a run without attitude (:func:`_frame`).
SERIES = {
    "L": ("N m s", "case", "kinetic moment (angular momentum) L"),
    "q": ("1", "body to case", "attitude quaternion (w, x, y, z), body to case"),
    "omega_b": ("rad/s", "body", "angular velocity of the rotor"),
    "euler": ("rad", "L-frame", "Euler angles psi, theta, phi of the body in the L-frame"),
    "torque": ("N m", "case", "electrodynamic torque on the rotor"),
    "energy": ("J", "", "mechanical energy of the rotor with its internal bodies (flywheel, damper mass and spring)"),
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
