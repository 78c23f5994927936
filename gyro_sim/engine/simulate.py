"""Running a scene: the :class:`Simulator` (advance in time, take stator commands) and :func:`run`.

The simulator is the one piece of code every front end drives: :func:`run` (in-process, the
fastest), the ROS simulator node (lockstep / real-time) and the tests. Units SI, L in the case
frame, attitude quaternion body → case.

A run without attitude (:func:`integrates_attitude` False: ``output.attitude: false`` on an isotropic
rotor without effects, full fidelity, no controller law that reads the attitude) integrates L and the eddy
modes in the case frame only (gyro_sim/kernels.py): q, the Euler angles and θ are NaN, ``omega_b`` holds
Ω = L/J in the case frame (the body frame is not known; |Ω| is the same) and ``spin_rate`` is |Ω|.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Optional, Sequence

import numpy as np

from gyro_sim.compiled import effects, frozen_flow, kernels, qs_flow
from gyro_sim.scenes.accuracy import (PHASE_REL_MIN, R_MEASURABLE, RATE_KNOB, SHADOW_RATIO, STEPS_WARN, STIFF, ErrorControl,
                       ErrorEstimate, auto_plan, field_rates, is_legacy, mode_plan, spin_reach, step_plan,
                       truncated_model)
from gyro_sim.scenes.accuracy import warn as accuracy_warning
from gyro_sim.compiled.compile_watch import CompileClock
from gyro_sim.physics.conductor import DEFAULT_N_MODES
from gyro_sim.physics.conductor import conductor_model
from gyro_sim.physics.frames import attitude_from_euler, euler_angles, quat_to_matrix
from gyro_sim.io.messages import stamp_ns
from gyro_sim.scenes.scene import Scene, SceneError, merge_times

__all__ = ["Simulator", "RunResult", "run", "stator_triad", "integrates_attitude"]

#: the fixed step knobs of the runs before the accuracy plan (issue 19): steps per turn of the fastest rotation and
#: the frozen-flow rate_change. Runs now choose their knobs from the scene's ``accuracy`` (gyro_sim/accuracy.py,
#: ``Simulator.step_plan``); these stay as the benchmark's "today's defaults" (gyro_sim/bench.py)
DEFAULT_STEPS_PER_TURN = {"lawson8": 12, "etdrk4": 48, "free": 48}
DEFAULT_RATE_CHANGE = 1e-4
#: a frozen-flow step costs about this many lawson8 steps per (1 + number of eddy modes): 8 µs against
#: 1.9 µs with one phasor and one mode, 17–28 µs with ten modes (measured on the default scene and
#: spinup_solid_sphere); ``auto`` takes it where its step is that many times longer
FROZEN_FLOW_COST = 2.0
#: control laws that read only t, L and the stators (not q, θ or Ω_b): with one of them (or none) a scene may
#: run without attitude; any other law (psi_switching, reorient: θ and the polar axis) keeps it
LAWS_WITHOUT_ATTITUDE = frozenset({"spinup", "off", "hold", "manual"})
#: (A, b, c) of each field stepper for kernels.integrate: DOP853's for lawson8, empty for ETDRK4 (made on first use:
#: a process that runs no lawson8 step reads no table)
_TABLEAU: dict = {}


def _tableau(method: str) -> tuple:
    """(A, b, c) of ``method`` ('lawson8' or 'etdrk4') for kernels.integrate, kept once made."""
    if method not in _TABLEAU:
        _TABLEAU[method] = (kernels.dop853_tableau() if method == "lawson8"
                            else (np.empty((0, 0)), np.empty(0), np.empty(0)))
    return _TABLEAU[method]


def integrates_attitude(scene: Scene, attitude: Optional[bool] = None) -> bool:
    """Whether a run of ``scene`` integrates the attitude q. ``attitude``: what the caller needs (None: the
    scene's ``output.attitude``; True: always, as the ROS node and a recorded run do).

    Without attitude only where nothing needs it: the rotor isotropic (J1 = J2 = J3: Ω = L/J does not depend
    on q, and the spherical conductor's eddy-mode filter is rotation-covariant, so the modes can be carried
    in the case frame), no effect on (their torques and states need the body frame), ``fidelity: full``
    (fidelity.py's hand-overs read and rebuild q) and no controller law outside :data:`LAWS_WITHOUT_ATTITUDE`.
    Elsewhere ``output.attitude: false`` is accepted and changes nothing."""
    want = scene.output.attitude if attitude is None else bool(attitude)
    if want:
        return True
    J = scene.rotor.inertia
    ctl = scene.controller
    return not (J[0] == J[1] == J[2] and not scene.effects.any and scene.fidelity == "full"
                and (ctl is None or ctl.law in LAWS_WITHOUT_ATTITUDE))


@lru_cache(maxsize=64)
def _initial_attitude(direction: tuple, psi: float, theta: float, phi: float) -> np.ndarray:
    """:func:`attitude_from_euler` of a scene's initial state (L direction, Euler angles rad), kept per value: a pure
    function, the same bits, ~15 µs each Simulator made of a scene spent once. Read only."""
    q = attitude_from_euler(np.array(direction), psi, theta, phi)
    q.flags.writeable = False
    return q


def controller_period(scene: Scene) -> Optional[float]:
    """s between the ticks of the scene's controller: its ``period``, else one per output sample; None without a
    controller section."""
    ctl = scene.controller
    return (ctl.period or 1.0 / scene.output.rate) if ctl is not None else None


def _case_flag(attitude: bool) -> tuple:
    """The trailing ``case`` argument of the compiled integrators and :func:`kernels.record_sample`: None with
    the attitude (numba prunes the case-frame code: it compiles only what the scene runs), True without."""
    return (None,) if attitude else (True,)


def stator_triad(u: Sequence[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Right-handed triad (e1, e2, u) of a stator axis u: e1 = next case axis (cyclic) ⟂ u. (Scalar code: a
    Simulator makes one per stator, and np.cross costs ~5 µs a call.)"""
    a = [float(v) for v in u]
    n = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    u0, u1, u2 = a[0] / n, a[1] / n, a[2] / n
    i = max(range(3), key=lambda k: abs((u0, u1, u2)[k]))  # (the first of equal ones, as np.argmax)
    z = [0.0, 0.0, 0.0]
    z[(i + 1) % 3] = 1.0
    d = z[0] * u0 + z[1] * u1 + z[2] * u2
    e = [z[0] - d * u0, z[1] - d * u1, z[2] - d * u2]
    m = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    e0, e1, e2 = e[0] / m, e[1] / m, e[2] / m
    return (np.array([e0, e1, e2]), np.array([u1 * e2 - u2 * e1, u2 * e0 - u0 * e2, u0 * e1 - u1 * e0]),
            np.array([u0, u1, u2]))


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
    energy: np.ndarray  # (n,) J, rotational kinetic energy
    stator_names: list[str]
    current: np.ndarray  # (n,k) A
    field_rate: np.ndarray  # (n,k) rad/s (signed)
    field_phase: np.ndarray  # (n,k) rad
    modes: np.ndarray  # (n,3N) eddy-mode states e_n, body frame (case frame without attitude), T
    wall_time: float = 0.0  # s, the run's wall time less its numba compile time
    compile_time: float = 0.0  # s of numba compilation during the run (a first use; gyro_sim.compile_watch)
    steps: int = 0
    commands: list = field(default_factory=list)  # (t s, names, currents A|None, rates rad/s|None) as applied
    averaged_segments: list = field(default_factory=list)  # (t0, t1) s run with the averaged model
    averaged_models: list = field(default_factory=list)  # the model of each stretch: "spin-up", "[M]", "[K]"
    averaged_rhs_evaluations: int = 0
    effects: dict = field(default_factory=dict)  # outputs of the effects that are on (Simulator.effect_outputs)
    attitude: bool = True  # whether q was integrated (integrates_attitude)
    # the run's estimated error over its duration, against the scene's accuracy (gyro_sim.accuracy.ErrorEstimate)
    error_estimate: Optional[ErrorEstimate] = None
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
                             "attitude": True, "error_estimate": None, "_euler": None}, **known)
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
        from gyro_sim.io.results import to_dataframe

        return to_dataframe(self)

    def to_xarray(self):
        """The run as an xarray Dataset: dims ``time`` (s), ``component`` (x, y, z), ``stator``, ...; units, frames
        and the run's scene and error estimate as attrs (:func:`gyro_sim.results.to_xarray`). Needs the optional
        extra ``data`` (``pip install 'gyro_sim[data]'``)."""
        from gyro_sim.io.results import to_xarray

        return to_xarray(self)

    def __repr__(self) -> str:
        # a few lines (scene, duration, samples, final values, error estimate), not the arrays
        from gyro_sim.io.results import result_repr

        return result_repr(self)

    def summary(self) -> dict:
        """Final values and cost of the run (SI units; θ in degrees, NaN without attitude; spin_rate: see
        :attr:`spin_rate`) and its estimated error (``error_L`` relative, ``error_attitude`` rad, NaN where not a
        result; ``accuracy_met``: within the scene's ``accuracy``)."""
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
            **error_summary(self.error_estimate),
        }


def error_summary(est: Optional[ErrorEstimate]) -> dict:
    """The summary's error keys of an estimate (NaN and None where the run has none)."""
    if est is None:
        return {"error_L": math.nan, "error_attitude": math.nan, "accuracy_met": None}
    return {"error_L": est.L, "error_attitude": est.attitude, "accuracy_met": est.met,
            "accuracy_rtol": est.rtol, "accuracy_attitude": est.atol}


class Simulator:
    """The full model of a scene, advanced in time under piecewise-constant stator commands.

    State: ``t`` (s) and ``y`` (see :mod:`gyro_sim.kernels`). Field phases σ_k are continuous
    across command changes. ``attitude``: see :func:`integrates_attitude`; without it y[3:7] is NaN and the
    eddy modes are in the case frame (``self.attitude`` False).
    """

    def __init__(self, scene: Scene, attitude: Optional[bool] = None, horizon: Optional[float] = None,
                 quiet: bool = False):
        self.scene = scene
        self.quiet = quiet  # no accuracy warnings (a shadow run: gyro_sim.accuracy.ErrorControl)
        # the step is the plan's divided by step_div (the run's error control changes it at its checks); a shadow
        # run follows its ``leader``: the same stepper, steps SHADOW_RATIO times the leader's
        self.step_div = 1.0
        self.leader: Optional["Simulator"] = None
        self.attitude = integrates_attitude(scene, attitude)
        J = scene.inertia
        self.J = J
        self.Jinv = 1.0 / J
        # the run's accuracy plan (gyro_sim/accuracy.py): made for ``horizon`` s (default: the scene's duration),
        # the same in-process and in the ROS node
        self.horizon = float(scene.duration if horizon is None else horizon)
        om_reach = spin_reach(scene, self.horizon)  # the fastest spin the run can reach (rad/s)
        self.mode_plan = mode_plan(scene, self.horizon, self.attitude, quiet=quiet, reach=om_reach)
        self.slip_met = 0.0  # largest slip bound met at a step plan (rad/s): the modes' error is judged there
        self._slip_warned = False
        # --- eddy-current model (physics.md §3)
        cond = scene.rotor.conductor
        self.conductor = None
        tau = np.zeros(0)
        w = np.zeros(0)
        tail = 0.0
        c_m = 0.0
        if cond is not None and scene.torque_model == "lag" and scene.effects.magnetizable is not None:
            # the magnetizable body replaces the modes; the conductor gives its default P1, P2 (effects.py)
            self.conductor = conductor_model(cond.kind, cond.outer_radius, cond.conductivity, thickness=cond.thickness,
                                             n_modes=scene.modes or DEFAULT_N_MODES)
        elif cond is not None and scene.torque_model == "lag":
            mp = self.mode_plan
            self.conductor = truncated_model(cond.kind, cond.outer_radius, cond.conductivity, cond.thickness, mp.n,
                                             mp.tail)
        elif cond is not None and scene.torque_model != "none":
            self.conductor = conductor_model(cond.kind, cond.outer_radius, cond.conductivity,
                                             thickness=cond.thickness)  # quasi-static: τ_eff alone (exact)
        if self.conductor is not None:
            c_m = float(self.conductor.moment_scale)
            if scene.torque_model == "quasi_static":
                tail = float(self.conductor.tau_eff)  # [K] (1.2)
            else:
                tau = np.asarray(self.conductor.tau, dtype=float)
                w = np.asarray(self.conductor.weight, dtype=float)
                tail = float(self.conductor.tail_tau)
        # --- effects (physics.md §4, [BS]); the magnetizable body replaces the eddy-mode model
        self.eff = effects.pack_effects(scene, self.conductor)
        self.n_extra = int(self.eff[effects.NE])
        if scene.effects.magnetizable is not None:
            tau, w, tail, c_m = np.zeros(0), np.zeros(0), 0.0, 0.0
            if scene.torque_model == "none":
                self.eff[effects.MAG] = 0.0
        self.tau, self.w, self.tail, self.c_m = tau, w, tail, c_m
        self.tau_min = float(np.min(tau)) if tau.size else math.inf  # the fastest eddy mode's time constant, s
        self.lam = np.concatenate([np.zeros(7), np.repeat(-1.0 / tau, 3) if tau.size else np.zeros(0),
                                   np.zeros(self.n_extra)])
        # --- stators
        st = scene.stators
        self.stator_names = [s.name for s in st]
        triads = [stator_triad(s.axis) for s in st]
        self.e1 = np.array([t[0] for t in triads]).reshape(-1, 3)
        self.e2 = np.array([t[1] for t in triads]).reshape(-1, 3)
        self.axes = np.array([t[2] for t in triads]).reshape(-1, 3)  # unit stator axes u = e1 × e2
        self.b = np.array([s.coil_constant for s in st], dtype=float)
        self.current = np.array([s.current for s in st], dtype=float)
        self.rate = np.array([s.rate for s in st], dtype=float)
        self.phase = np.array([s.phase for s in st], dtype=float)
        # --- general field B(t) = Re Σ B_p exp(−i ω_p t)
        self.field_B = np.array([np.array(f.real) + 1j * np.array(f.imag) for f in scene.field]).reshape(-1, 3)
        self.field_om = np.array([f.frequency for f in scene.field], dtype=float)
        # --- initial state
        ini = scene.initial
        d = np.asarray(ini.L_direction, dtype=float)
        d /= np.linalg.norm(d)
        Lmag = ini.kinetic_moment if ini.kinetic_moment is not None else J[2] * (ini.spin or 0.0)
        self.y = np.zeros(7 + 3 * tau.size + self.n_extra)
        self.y[0:3] = Lmag * d
        self.y[3:7] = (_initial_attitude(tuple(d.tolist()), float(ini.psi), float(ini.theta), float(ini.phi))
                       if self.attitude else math.nan)
        if scene.effects.damper is not None:
            k0 = 7 + 3 * tau.size
            self.y[k0:k0 + 3] = scene.effects.damper.offset
            self.y[k0 + 3:k0 + 6] = scene.effects.damper.velocity
        self.t = 0.0
        self._seg, self._seg_t_end = None, math.nan  # see _segment
        # the fields are switched on at t = 0 on a rotor free of eddy currents
        if self.tau.size:
            self._field_step(np.zeros(3), self.field_now())
        self.steps = 0
        # free-rotor geometry: reference inertia and the axis carrying H_r
        if J[0] == J[1] == J[2]:
            self._free_axis, ref = -2, J[0]
        elif J[0] == J[1]:
            self._free_axis, ref = 2, J[0]
        elif J[1] == J[2]:
            self._free_axis, ref = 0, J[1]
        elif J[0] == J[2]:
            self._free_axis, ref = 1, J[0]
        else:
            self._free_axis, ref = -1, J[0]
        if not self.attitude:
            self._free_axis = -3  # isotropic, modes in the case frame (kernels.free_step)
        self._inv_ref = 1.0 / ref
        self._nu_max = max([abs(s.rate) for s in st] + [abs(c.rate) for c in scene.commands if c.rate is not None] + [0.0])
        # --- the step knobs for the scene's accuracy over the horizon (gyro_sim/accuracy.py): turns of the fastest
        # rotation the run can meet (spin it can reach, field rates, an effect's rate) and of the free body motion
        Lmag0 = float(np.linalg.norm(self.y[0:3]))
        om_plan = max(om_reach, field_rates(scene), self._effect_rate())
        L_bound = Lmag0 if om_reach <= Lmag0 * float(np.max(self.Jinv)) * (1 + 1e-12) else float(np.max(J)) * om_reach
        self.L_bound = L_bound  # the largest |L| the run can reach (N m s; gyro_sim.accuracy.ErrorControl)
        om_free = L_bound * float(np.max(np.abs(self.Jinv - self._inv_ref))) if self._free_axis == -1 else 0.0
        self.step_plan = step_plan(scene, self.horizon, self.attitude, om_plan, om_free)
        self._auto_plan = auto_plan(self.step_plan, scene)
        self._knob_warned: set = set()
        if not quiet and not is_legacy():
            self._warn_plan(om_plan)

    # --- named views of the state -------------------------------------------------------------
    @property
    def L(self) -> np.ndarray:
        """Angular momentum L now, (3,) N·m·s, case frame (a copy of y[0:3]: the state moves on)."""
        return self.y[0:3].copy()

    @property
    def q(self) -> np.ndarray:
        """Attitude quaternion now, (4,) (w, x, y, z) body → case (a copy of y[3:7]); NaN without attitude."""
        return self.y[3:7].copy()

    @property
    def omega_b(self) -> np.ndarray:
        """Angular velocity Ω_b now, (3,) rad/s, body frame, effects included (:meth:`body_rates`); without
        attitude Ω = L/J in the case frame."""
        return self.body_rates(self.t, self.y)[0]

    @property
    def euler(self) -> np.ndarray:
        """Euler angles (ψ, θ, φ) now, (3,) rad, of the body in the L-frame; NaN without attitude."""
        if not self.attitude:
            return np.full(3, np.nan)
        return euler_angles(quat_to_matrix(self.y[3:7]), self.y[0:3])

    @property
    def modes(self) -> np.ndarray:
        """Eddy-mode states now, (3N,) T: e_1 (x, y, z), e_2, ... in the body frame (case frame without attitude),
        laid out as a row of :attr:`RunResult.modes` (a copy; no columns where the scene has no eddy modes)."""
        return self.y[7:7 + 3 * self.tau.size].copy()

    # --- commands --------------------------------------------------------------------------
    def stator_index(self, stator) -> int:
        """The index of a stator given by name (``'z1'``) or index (0 … k−1); anything else raises one
        ValueError naming the value and the stator names."""
        names = self.stator_names
        if isinstance(stator, str) and stator in names:
            return names.index(stator)
        if not isinstance(stator, (str, bool)) and isinstance(stator, (int, np.integer)) \
                and 0 <= int(stator) < len(names):
            return int(stator)
        allowed = (f"{', '.join(names)} (or an index 0–{len(names) - 1})" if names
                   else "none (the scene has no stators)")
        raise ValueError(f"stator {stator!r}: no such stator; allowed: {allowed}")

    def set_stator(self, stator, current: Optional[float] = None, rate: Optional[float] = None) -> None:
        """Command a stator from now on: current amplitude (A, ≥ 0) and signed field rate (rad/s). ``stator``: its
        name (``'z1'``) or index (:meth:`stator_index`).

        A current step makes a field step ΔB; each eddy mode answers it instantly with its
        high-frequency limit (ĝ → −1), e_n → e_n − ΔB_b (:meth:`_field_step`).
        """
        self.set_stators({stator: (current, rate)})

    def set_stators(self, commands: dict) -> None:
        """Command several stators at once, ``{stator: (current A | None, rate rad/s | None)}`` (a stator by name
        or index): one field step for all the current changes (the result does not depend on the order the
        stators are named in)."""
        n = len(self.stator_names)
        if not all(type(k) is int and 0 <= k < n for k in commands):  # (the Runner's: indices in range already)
            commands = {self.stator_index(k): c for k, c in commands.items()}
        for k, (current, rate) in commands.items():
            if current is not None and not (math.isfinite(current) and current >= 0):
                raise ValueError(f"stator {self.stator_names[k]!r}: current = {current}: must be finite and ≥ 0 A")
            if rate is not None and not math.isfinite(rate):
                raise ValueError(f"stator {self.stator_names[k]!r}: rate = {rate}: must be finite (rad/s)")
        changed = {k: c for k, (c, _) in commands.items() if c is not None and c != self.current[k]}
        if changed:
            before = self.field_now()
            for k, c in changed.items():
                self.current[k] = c
            self._field_step(before, self.field_now())
        for k, (_, rate) in commands.items():
            if rate is not None:
                self.rate[k] = rate
                self._nu_max = max(self._nu_max, abs(rate))

    # --- fields ----------------------------------------------------------------------------
    def field_now(self) -> np.ndarray:
        """Field B (case frame, T) at the present time."""
        Bre, _, _ = self.phasors()
        return Bre.sum(axis=0)

    def _field_step(self, before: np.ndarray, after: np.ndarray) -> None:
        """Instant response of the eddy modes to a field step: e_n −= Rᵀ ΔB (τ_n ė_n + e_n = −τ_n dB_b/dt);
        without attitude (modes in the case frame) e_n −= ΔB."""
        if self.tau.size == 0:
            return
        dBb = quat_to_matrix(self.y[3:7]).T @ (after - before) if self.attitude else after - before
        self.y[7:7 + 3 * self.tau.size] -= np.tile(dBb, self.tau.size)

    def phasors(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(Bre, Bim, ω) of the field from now on, referred to s = t − self.t (case frame, T). Kept while the time,
        currents, rates and phases are the same (a run asks for them at its start, its first sample and its step
        plan): read them, do not write into them."""
        key = (self.t, self.current.tobytes(), self.rate.tobytes(), self.phase.tobytes())
        kept = self.__dict__.get("_ph")
        if kept is not None and kept[0] == key:
            return kept[1]
        self._ph = (key, self._phasors())
        return self._ph[1]

    def _phasors(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        on = self.current > 0
        c, s = np.cos(self.phase[on]), np.sin(self.phase[on])
        amp = (self.b * self.current)[on][:, None]
        e1, e2 = self.e1[on], self.e2[on]
        # b I (e1 cos(σ + ν s) + e2 sin(σ + ν s))
        Bre = amp * (e1 * c[:, None] + e2 * s[:, None])
        Bim = amp * (-e1 * s[:, None] + e2 * c[:, None])
        om = self.rate[on]
        if self.field_om.size:
            # Re(B_p e^{−iω t}) = Re(B̃) cos ωs + Im(B̃) sin ωs with B̃ = B_p e^{−iω t_now}
            Bt = self.field_B * np.exp(-1j * self.field_om * self.t)[:, None]
            Bre = np.vstack([Bre, Bt.real])
            Bim = np.vstack([Bim, Bt.imag])
            om = np.concatenate([om, self.field_om])
        return np.ascontiguousarray(Bre).reshape(-1, 3), np.ascontiguousarray(Bim).reshape(-1, 3), np.asarray(om, float)

    def _step_plan(self, free: bool) -> tuple[str, float]:
        """(stepper, largest step s) from now on. With fields: ``lawson8`` (8th-order Lawson–Dormand–Prince,
        RKMK attitude) unless an eddy mode is stiff at the lawson8 step (h > 2 τ_n: the integrating
        factor then loses the order), else ``etdrk4``; ``auto`` takes ``frozen_flow`` instead where it
        applies (axisymmetric rotor, no effects) and its step is long enough to be cheaper
        (:data:`FROZEN_FLOW_COST`); ``free`` for the torque-free stepper."""
        if free:
            self._check_knob("free")
            return "free", self._max_step(True, "free")
        m = self.scene.integrator.method
        if m == "frozen_flow":
            self._check_knob(m)
            return m, self._frozen_flow_step()
        if m == "qs_flow":
            self._check_knob(m)
            return m, self._frozen_flow_step(self.step_plan.qs_rate_change)
        if m == "auto":
            m, h = "lawson8", self._max_step(False, "lawson8")
            held = False
            if h > 2.0 * self.tau_min:
                # a mode is stiff at lawson8's step: ETDRK4 at its own step, or lawson8 held at τ_min (where its
                # order holds, its shadow's step within 2 τ_min) where that costs less (lawson8_cost)
                h_etd = self._max_step(False, "etdrk4")
                if self.tau_min >= lawson8_cost(self.tau.size) * h_etd:
                    h, held = self.tau_min, True
                else:
                    m, h = "etdrk4", h_etd
            if frozen_flow.supported(self.J) >= 0 and self.eff[effects.ON] == 0.0:
                # decided at both steppers' settings for the scene's accuracy (the choice follows the physics
                # and the tolerance; the scene's explicit knobs then set the chosen stepper's accuracy)
                ap = self._auto_plan
                h_ff = self._frozen_flow_step(ap.rate_change)
                h_def = self._max_step(False, m, ap.steps_per_turn[m])
                if held:
                    h_def = min(h_def, self.tau_min)
                if h_ff >= FROZEN_FLOW_COST * (1 + self.tau.size) * h_def:
                    # the quasi-static model: the quasi-static flow step instead (gyro_sim/qs_flow.py)
                    m = "qs_flow" if self._qs_applies() else "frozen_flow"
                    self._check_knob(m)
                    return m, self._frozen_flow_step(self.step_plan.knob(m))
            self._check_knob(m)
            return m, h
        self._check_knob(m)
        return m, self._max_step(False, m)

    def _qs_applies(self) -> bool:
        """Whether ``auto`` takes the quasi-static flow step (gyro_sim/qs_flow.py) where it would take frozen_flow:
        on the quasi-static torque model (not in the old defaults' runs, gyro_sim.accuracy.legacy). Its step is as
        long (the same error model), costs a third (0.8 µs against 2.3 µs, one phasor), and its error measured no
        larger on every quasi-static scene (docs/numerics.md). Where frozen_flow does not pay, lawson8 stays: its
        error is the predictable one (it resolves the field's ripple): on reorient_L qs_flow takes 403 699 steps
        (2.6 s CPU) against lawson8's 10 319 (0.18 s), docs/accuracy.md."""
        return not is_legacy() and qs_flow.applies(self.scene, self.J, self.eff[effects.ON] != 0.0)

    def _warn_plan(self, om_plan: float) -> None:
        """Warn where the scene's attitude tolerance is below the floor a plan takes (PHASE_REL_MIN of the spin
        phase), and where the plan predicts a very long run (more than STEPS_WARN steps)."""
        acc, T = self.scene.accuracy, self.horizon
        floor = PHASE_REL_MIN * om_plan * T
        if self.attitude and acc.attitude is not None and acc.attitude < floor:
            accuracy_warning(
                f"scene {self.scene.name!r}: accuracy.attitude = {acc.attitude:g} rad cannot be held over {T:g} s: "
                f"the spin phase the run can turn through is {om_plan * T:.3g} rad, and a run holds it to about "
                f"{PHASE_REL_MIN:g} of itself; planning for {floor:.2g} rad (the estimate reports what is reached; "
                f"set accuracy.attitude to at least that, or output.attitude: false where only L matters)")
        plan = self._auto_plan
        steps = min(plan.turns * plan.steps_per_turn["lawson8"], plan.turns * plan.steps_per_turn["etdrk4"])
        if frozen_flow.supported(self.J) >= 0 and self.eff[effects.ON] == 0.0 and self.c_m > 0:
            steps = min(steps, T / self._frozen_flow_step(plan.rate_change))
        if steps > STEPS_WARN:
            accuracy_warning(
                f"scene {self.scene.name!r}: accuracy (rtol {acc.rtol:g}, attitude {acc.attitude} rad) over "
                f"{T:g} s needs about {steps:.2g} steps ({plan.turns:.3g} turns of the fastest rotation); a looser "
                f"accuracy runs faster")

    def _check_knob(self, method: str) -> None:
        """Warn once per stepper where the scene's explicit knob misses its accuracy by the error model
        (gyro_sim.accuracy.StepPlan.predicted); note the stepper as used (``methods_used``)."""
        used = self.__dict__.setdefault("methods_used", set())
        used.add(method)
        plan = self.step_plan
        knob = "rate_change" if method in RATE_KNOB else "steps_per_turn"
        if knob not in plan.explicit or method in self._knob_warned or self.quiet:
            return
        if method == "free" and self._free_axis != -1:
            return  # exact steps
        self._knob_warned.add(method)
        eL, eq = plan.predicted(method)
        if eL > plan.tol_L or eq > plan.tol_q:
            want, val = self._auto_plan.knob(method), plan.knob(method)
            acc = self.scene.accuracy
            accuracy_warning(
                f"scene {self.scene.name!r}: integrator.{knob} = {val:g} cannot meet accuracy (rtol {acc.rtol:g}, "
                f"attitude {acc.attitude} rad) with {method} over {self.horizon:g} s by the error model: about "
                f"{eL:.2g} in L, {eq:.2g} rad in the attitude; {knob} = {want:g} would (leave it out to let the run "
                f"choose)")

    def _method(self) -> str:
        """The stepper a field step would take now (see :meth:`_step_plan`)."""
        return self._step_plan(False)[0]

    def _max_step(self, free: bool, method: str, spt: Optional[int] = None) -> float:
        """Largest lawson8/etdrk4/free step (s) at ``spt`` steps per turn (default: the step plan's: the scene's
        knob, else chosen for its accuracy) of the fastest rotation, bounded by ``integrator.max_step``."""
        spt = spt or self.step_plan.steps_per_turn[method]
        L = math.sqrt(float(self.y[0]) ** 2 + float(self.y[1]) ** 2 + float(self.y[2]) ** 2)
        if free:
            if self._free_axis != -1:
                h = math.inf  # the free step is exact
            else:
                rate = L * np.max(np.abs(self.Jinv - self._inv_ref))
                h = 2 * math.pi / (spt * rate) if rate > 0 else math.inf
        else:
            om = max(L * max(self.Jinv), self._nu_max, max(self.field_om, default=0.0), self._effect_rate())
            h = 2 * math.pi / (spt * om) if om > 0 else math.inf
        if self.scene.integrator.max_step is not None:
            h = min(h, self.scene.integrator.max_step)
        return h

    def _frozen_flow_step(self, eps: Optional[float] = None) -> float:
        """Largest frozen-flow step (s): the body rate may change by ``rate_change`` of the fastest rate Ω
        (spin or field) per step at the torque's scale N = c|B|²(½Σ|w_n| + T_tail(Ω + ν_max)), the largest
        |m||B| the conductor gives at a slip up to Ω + ν_max (J_min Ω ε / N); ε = ``eps``, else the scene's
        ``integrator.rate_change``, else the one chosen for the scene's accuracy (``step_plan``)."""
        eps = eps or self.step_plan.rate_change
        h = eps * self._torque_time()
        if self.scene.integrator.max_step is not None:
            h = min(h, self.scene.integrator.max_step)
        return h

    def _local_torque_scale(self, ax: int) -> float:
        """Mean torque scale (N m) at the present slips (:func:`gyro_sim.frozen_flow.torque_scale`) for an
        axisymmetric or isotropic rotor with symmetry axis ``ax`` (:func:`gyro_sim.frozen_flow.supported`)."""
        Jt, Ja = float(self.J[(ax + 1) % 3]), float(self.J[ax])
        e_a = quat_to_matrix(self.y[3:7])[:, ax] if self.attitude and Jt != Ja else None
        return frozen_flow.torque_scale(*self.phasors(), self.y[0:3], Jt, Ja, e_a, self.c_m, self.w, self.tau,
                                        self.tail)

    def _torque_time(self) -> float:
        """J_min Ω / N (s): the time the torque's scale N takes to change the fastest rate Ω by itself (inf without
        torque or rate). N: the mean torque at the present slips (:meth:`_local_torque_scale`), no larger than the
        bound c|B|²(½Σ|w_n| + T_tail(Ω + ν_max)) at the largest slip and no smaller than LOCAL_SCALE_MIN of it.
        Kept while the commands, the rates met, L and q are the same (a step plan asks for it for several knobs)."""
        # (q only where it is integrated: without attitude it is NaN, and NaN != NaN would never find the kept one)
        key = (self.current.tobytes(), self.rate.tobytes(), self._nu_max, *self.y[0:7 if self.attitude else 3].tolist())
        kept = self.__dict__.get("_tt")
        if kept is not None and kept[0] == key:
            return kept[1]
        # |B| summed over the phasors: √2 b_k I_k a stator (its Bre, Bim are b_k I_k times two orthonormal vectors),
        # |B_p| a general field term (scalar code: this is asked once per command segment)
        B = sum(math.sqrt(2.0) * b * c for b, c in zip(self.b.tolist(), self.current.tolist()) if c > 0)
        B += sum(float(np.linalg.norm(f)) for f in self.field_B) if self.field_B.size else 0.0
        y = self.y
        om = max(math.sqrt(float(y[0]) ** 2 + float(y[1]) ** 2 + float(y[2]) ** 2) * max(self.Jinv.tolist()),
                 self._nu_max, max((abs(f) for f in self.field_om.tolist()), default=0.0))
        N = self.c_m * B * B * (0.5 * sum(abs(v) for v in self.w.tolist()) + self.tail * (om + self._nu_max))
        ax = frozen_flow.supported(self.J)
        if N > 0 and self.w.size and ax >= 0:
            # the mean torque at the present slips, no larger than the bound: a spin-up's step grows as its slip falls
            # (the eddy-mode models; qs_flow's plan and auto's choice of it were measured at the bound: on
            # nutation_slow the local scale made auto take qs_flow, whose ticks are not compiled, at 1.2x the cost)
            N = min(N, max(self._local_torque_scale(ax), frozen_flow.LOCAL_SCALE_MIN * N))
        tt = min(self.J.tolist()) * om / N if N > 0 and om > 0 else math.inf
        self._tt = (key, tt)
        return tt

    def _effect_rate(self) -> float:
        """Fastest rate (rad/s) an effect brings: the body rate the flywheel drives, the damper's spring."""
        if self.eff[effects.ON] == 0.0:
            return 0.0
        ef = self.scene.effects
        rate = float(np.linalg.norm(self.body_rates(self.t, self.y)[0]))
        if ef.flywheel is not None:
            fw = ef.flywheel
            rate += fw.inertia * max(abs(v) for v in fw.profile.speed) * float(np.linalg.norm(self.Jinv * fw.axis))
        if ef.damper is not None:
            d = ef.damper
            rate = max(rate, math.sqrt(d.stiffness / d.mass), d.damping / d.mass)
        return rate

    # --- time stepping -----------------------------------------------------------------------
    def advance(self, t_end: float, sample_times: Optional[np.ndarray] = None,
                out_y: Optional[np.ndarray] = None, out_N: Optional[np.ndarray] = None, k_out: int = 0) -> int:
        """Integrate to ``t_end`` (s) under the present commands, recording at ``sample_times``.

        Sample times must lie in (t, t_end]; states and torques are written to out_y/out_N
        from row k_out. Returns the next free row.
        """
        if t_end < self.t:
            raise ValueError(f"advance: t_end = {t_end} is before the present time {self.t}")
        if sample_times is None or len(sample_times) == 0:
            stops = np.array([t_end])
            record = np.array([False])
            out_y = np.zeros((1, self.y.size))
            out_N = np.zeros((1, 3))
        else:
            stops = np.asarray(sample_times, dtype=float)
            record = np.ones(stops.size, dtype=np.bool_)
            if stops[-1] < t_end:
                stops = np.append(stops, t_end)
                record = np.append(record, False)
        t_seg, Bre, Bim, om, free, method, h_max = self._segment()
        if not math.isfinite(h_max):
            h_max = max(t_end - self.t, 1e-300)
        if method == "frozen_flow":
            ax = frozen_flow.supported(self.J)
            k_out, steps = frozen_flow.integrate_frozen(
                self.y, self.t, t_seg, stops, record, h_max, Bre, Bim, om, self.Jinv, self.J[(ax + 1) % 3],
                self.J[ax], ax, self.c_m, self.w, self.tail, 1.0 / self.tau, out_y, out_N, k_out, self.eff,
                *_case_flag(self.attitude))
        elif method == "qs_flow":
            ax = frozen_flow.supported(self.J)
            k_out, steps = qs_flow.integrate_qs(
                self.y, self.t, t_seg, stops, record, h_max, Bre, Bim, om, self.Jinv, self.J[(ax + 1) % 3],
                self.J[ax], ax, self.c_m, self.w, self.tail, out_y, out_N, k_out, self.eff, *_case_flag(self.attitude))
        elif free:
            k_out, steps = kernels.integrate_free(
                self.y, self.t, stops, record, h_max, self.Jinv, self._inv_ref, self._free_axis, self.tau,
                out_y, out_N, k_out)
        else:
            k_out, steps = kernels.integrate(
                self.y, self.t, t_seg, stops, record, h_max, Bre, Bim, om, self.Jinv, self.c_m, self.w,
                self.tail, self.lam, out_y, out_N, k_out, self.eff, *_tableau(method), *_case_flag(self.attitude))
        self.steps += steps
        self.phase = np.mod(self.phase + self.rate * (t_end - self.t), 2 * math.pi)
        self.t = t_end
        self._seg_t_end = t_end
        return k_out

    def _segment(self) -> tuple:
        """(t_seg, Bre, Bim, ω, free, stepper, h_max) for the next advance: the phasors referred to t_seg and
        the step plan, kept from the previous advance while the commands are the same and the time goes on
        from where it ended, so a run gives the same bits whether its output samples are breaks or not;
        computed afresh otherwise, and at every advance when an effect is on (its rates change in time).
        The plan is made for the rates at the start of a command segment: ``steps_per_turn`` and
        ``rate_change`` hold there. Within a segment a spin-up below the field's rates keeps it (the
        fastest rate is the field's), but a rotor braking from above them keeps the step of its start:
        frozen_flow's step, which grows with the rate, is then up to (start rate / present rate) times
        longer than ``rate_change`` asks (a braking run forced to frozen_flow measured 5x the error of a
        re-planned one); give such scenes a ``max_step`` or commands that re-plan."""
        key = (self.current.tobytes(), self.rate.tobytes())
        seg = self._seg
        if seg is not None and seg[0] == key and self.t == self._seg_t_end and self.eff[effects.ON] == 0.0:
            return seg[1]
        Bre, Bim, om = self.phasors()
        self._check_slip(om)
        # no field (or no torque model) and no effect: the geometric free stepper
        free = (om.size == 0 or (self.c_m == 0.0 and self.eff[effects.MAG] == 0.0)) and self.eff[effects.ON] == 0.0
        method, h_max = self._step_plan(free)
        lead = self.leader
        if lead is not None:  # a shadow: the leader's stepper (decided on its state), SHADOW_RATIO times its step
            lm = lead._seg[1][5] if lead._seg is not None else method
            if lm != method:
                method, h_max = lm, self._h_for(lm)
            div = lead.step_div / SHADOW_RATIO[method]
        else:
            div = self.step_div
        if div != 1.0 and math.isfinite(h_max):
            h_max /= div
            if self.scene.integrator.max_step is not None:
                h_max = min(h_max, self.scene.integrator.max_step)
        self._seg = (key, (self.t, Bre, Bim, om, free, method, h_max))
        return self._seg[1]

    def _h_for(self, method: str) -> float:
        """The largest step (s) of ``method`` now, at the plan's knobs (lawson8 in auto mode: held at τ_min where
        a mode is stiff at its step, as :meth:`_step_plan` does)."""
        if method == "free":
            return self._max_step(True, "free")
        if method in RATE_KNOB:
            return self._frozen_flow_step(self.step_plan.knob(method))
        h = self._max_step(False, method)
        if method == "lawson8" and self.scene.integrator.method == "auto" and h > 2.0 * self.tau_min:
            h = self.tau_min
        return h

    def replan(self) -> None:
        """Make the step plan afresh at the next advance (the error control changed ``step_div``)."""
        self._seg = None

    def _check_slip(self, om: np.ndarray) -> None:
        """Note the slip bound of a new command segment (fastest field rate + |Ω| now, rad/s) in ``slip_met``; warn
        once where it passes the slip the eddy modes were chosen for (a command or law beyond the scene's rates:
        gyro_sim.accuracy.mode_plan) and the modes then miss the tolerance."""
        slip = float(np.max(np.abs(om), initial=0.0)) + float(np.linalg.norm(self.y[0:3])) * float(np.max(self.Jinv))
        self.slip_met = max(self.slip_met, slip)
        mp = self.mode_plan
        if (self._slip_warned or self.quiet or mp.kind in (None, "thin_shell") or mp.n == 0
                or slip <= mp.slip * (1 + 1e-9)):
            return
        e_g, e_im = mp.error_at(slip)
        if e_g > mp.tol_g or e_im > mp.tol_im:
            self._slip_warned = True
            accuracy_warning(
                f"scene {self.scene.name!r}: at t = {self.t:.6g} s the slip reaches {slip:.4g} rad/s, beyond the "
                f"{mp.slip:.4g} rad/s the {mp.n} eddy modes were chosen for (a command or law faster than the "
                f"scene's rates): their truncation error there is {e_g:.2g} of ĝ, {e_im:.2g} of Im ĝ against "
                f"tolerances {mp.tol_g:.2g}, {mp.tol_im:.2g}; give the rate in the scene (a stator, command or law "
                f"parameter) or set modes")

    def torque(self) -> np.ndarray:
        """Electrodynamic torque now (case frame, N·m)."""
        Bre, Bim, om = self.phasors()
        F = np.zeros(self.y.size)
        if not self.attitude:  # the phasors are referred to now: cos, sin(ω_p · 0)
            kernels.nonlinear_part_case(np.ones(om.size), np.zeros(om.size), self.y, Bre, Bim, om, self.Jinv,
                                        self.c_m, self.w, self.tail, self.tau.size, F, np.zeros(25))
            return F[0:3].copy()
        self.eff[effects.T0] = self.t
        out_N = np.zeros((1, 3))  # (record_sample: the steppers' own torque, compiled once for both)
        kernels.record_sample(0.0, self.y, Bre, Bim, om, self.Jinv, self.c_m, self.w, self.tail, self.tau.size,
                              self.eff, np.empty(om.size), np.empty(om.size), F, np.zeros(25),
                              np.empty((1, self.y.size)), out_N, 0, None)
        return out_N[0].copy()

    def effect_outputs(self, t: np.ndarray, Y: np.ndarray) -> dict:
        """Outputs of the effects that are on, for states ``Y`` (rows) at times ``t`` (s), SI:

        ``flywheel_speed`` Ω_f (rad/s), ``flywheel_angle`` ∫Ω_f dt (rad); ``damper_offset`` u and
        ``damper_velocity`` u̇ (body frame, m, m/s); ``vertical_angle`` Θ between x3 and the unbalance's
        vertical (rad).
        """
        ef, out = self.scene.effects, {}
        t = np.asarray(t, float)
        if ef.flywheel is not None:
            out["flywheel_speed"] = np.array([effects.flywheel_speed(float(x), self.eff)[0] for x in t])
            out["flywheel_angle"] = effects.flywheel_angle(t, self.eff)
        if ef.damper is not None:
            k0 = 7 + 3 * self.tau.size
            out["damper_offset"] = Y[:, k0:k0 + 3].copy()
            out["damper_velocity"] = Y[:, k0 + 3:k0 + 6].copy()
        if ef.unbalance is not None:
            x3 = quat_to_matrix(Y[:, 3:7])[:, :, 2]
            out["vertical_angle"] = np.arccos(np.clip(x3 @ np.asarray(ef.unbalance.vertical), -1.0, 1.0))
        return out

    def body_rates(self, t: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """Ω_b (rad/s, body frame) of states ``Y`` (rows) at times ``t`` (s), effects included; without attitude
        Ω = L/J in the case frame."""
        Y = np.atleast_2d(Y)
        if not self.attitude:
            return Y[:, 0:3] * self.Jinv
        if self.eff[effects.ON] == 0.0:
            return body_rates(self.J, Y[:, 0:3], Y[:, 3:7])[1]
        Lb, _ = body_rates(self.J, Y[:, 0:3], Y[:, 3:7])
        k0 = 7 + 3 * self.tau.size
        return np.array([effects.body_rate(float(ti), *Lb[i], Y[i], k0, self.Jinv, self.eff)
                         for i, ti in enumerate(np.broadcast_to(t, (Y.shape[0],)))]).reshape(-1, 3)


def lawson8_cost(n_modes: int) -> float:
    """A lawson8 step's CPU time in ETDRK4 steps with ``n_modes`` eddy modes: measured 2.1 (one mode), 3.3 (50),
    4.7 (200) on constant_field and spinup_solid_sphere (1.6, 2.7, 7.2 µs against 0.8, 0.8, 1.6 µs)."""
    return 2.0 + 0.013 * n_modes


def body_rates(J: np.ndarray, L: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """L_b = Rᵀ L (N·m·s) and Ω_b = J⁻¹ L_b (rad/s) of states (..., 3), (..., 4).

    Written element by element (no BLAS) so a row gives the same bits alone or in a batch:
    the in-process controller and the controller node see identical numbers.
    """
    R = quat_to_matrix(q)
    Lb = R[..., 0, :] * L[..., 0:1] + R[..., 1, :] * L[..., 1:2] + R[..., 2, :] * L[..., 2:3]
    return Lb, Lb / J


def kinetic_energy(J: np.ndarray, omega_b: np.ndarray) -> np.ndarray:
    """Rotational kinetic energy ½ Ω_b·J Ω_b (J) of body rates (n, 3) rad/s, J the principal moments (kg·m²)."""
    return 0.5 * np.einsum("ni,i,ni->n", omega_b, J, omega_b)


def output_times(scene: Scene, T: float, period: Optional[float] = None) -> tuple[np.ndarray, np.ndarray]:
    """(output instants, tick instants), s, sorted, of a run of ``scene`` over ``T`` s: the scene's output grid with
    a tick every ``period`` s (None: no ticks) merged in (a tick is exact: a sample within round-off is it). The
    :class:`Runner`'s grid; a bag's reader maps the ns stamps back onto it (:func:`gyro_sim.results.read_bag`)."""
    ticks = np.arange(int(math.ceil(T / period - 1e-9))) * period if period is not None else np.zeros(0)
    return merge_times(scene.output.sample_times(T), ticks), ticks


class Runner:
    """Advances a :class:`Simulator` break by break over a scene's duration, collecting the outputs.

    Breaks are the output instants (unless ``sample_breaks`` is False), the scene's command instants and
    the controller ticks. At each
    break the scene's due commands are applied; at a controller tick the caller supplies the
    commands (in-process: the law; ROS node: the command message). The sample recorded at time t
    shows the state at t and the field that acted up to t. Used by :func:`run` and by the
    simulator node, so both produce the same numbers. ``attitude``: see :func:`integrates_attitude` (the
    ROS node passes True: it publishes /gyro/imu and /gyro/euler).

    Accuracy (gyro_sim/accuracy.py): the simulator's modes and step knobs are planned for the scene's
    ``accuracy`` over ``horizon`` s (default: the duration). With ``estimate`` (default) a shadow simulator runs
    alongside (same commands, same stops, longer steps) and the error control (:class:`gyro_sim.accuracy.
    ErrorControl`) compares the two at its check instants, which are breaks of every run (so the ROS node and
    an in-process run decide alike), estimates the error and corrects the step; :meth:`error_estimate` gives the
    run's estimate. ``estimate=False`` (a run that locates switching events: its bisection re-integrates stretches
    the shadow cannot follow) runs the plan alone and estimates by the plan's model.
    """

    def __init__(self, scene: Scene, duration: Optional[float] = None, sample_breaks: bool = True,
                 attitude: Optional[bool] = None, control_period: Optional[float] = None,
                 buffer_rows: Optional[int] = None, horizon: Optional[float] = None,
                 estimate: Optional[bool] = None):
        T = scene.duration if duration is None else float(duration)
        if not (math.isfinite(T) and T > 0):
            raise SceneError(f"duration = {duration}: must be a finite number of seconds > 0")
        if control_period is not None and not (math.isfinite(control_period) and control_period > 0):
            raise SceneError(f"control_period = {control_period}: must be a finite number of seconds > 0")
        self.scene, self.T = scene, T
        # the accuracy plan is made for the run's duration (``horizon``: another, e.g. a re-run of an interrupted
        # bag planned for its whole duration)
        H = T if horizon is None else float(horizon)
        self.sim = Simulator(scene, attitude, horizon=H)
        # the error control and its shadow run (gyro_sim/accuracy.py); checks at fixed fractions of the horizon
        plan = self.sim.step_plan
        if estimate is None:  # (a law sampled at its switching events: no shadow; nor the old defaults' runs)
            estimate = (scene.controller is None or scene.controller.sampling != "events") and not is_legacy()
        self.control = ErrorControl(plan, self.sim.attitude, H, adapt=not plan.explicit and estimate,
                                    J_min=float(np.min(self.sim.J)), L_bound=self.sim.L_bound)
        self.shadow = None
        if estimate:
            self.shadow = Simulator(scene, attitude, horizon=H, quiet=True)
            self.shadow.leader = self.sim
        self._checks = self.control.checks[self.control.checks < T] if estimate else np.zeros(0)
        self._ck = 0  # the next check
        self._at_check = (self.sim.y[0:3].copy(), 0.0, 0, 0)  # (L, t, steps, shadow steps) at the previous check
        self._steps_seen = 0
        self._impulse = 0.0  # ∫|N| dt over the output samples (N·m·s): the modes' error of L
        self._spin_dev = 0.0  # ∫ | |Ω| − |Ω0| | dt (rad): the modes' error of the spin phase
        self._last_t = 0.0
        self._om0 = float(np.linalg.norm(self.sim.y[0:3])) * float(np.max(self.sim.Jinv))
        self.averaged_eps: list = []  # the averaged models' ε of each stretch (fidelity.py)
        # ticks: the controller's (its period, else one per output sample); control_period sets them for any
        # scene (the ROS node: external commands are taken at ticks, also where the scene has no controller)
        self.period = control_period or controller_period(scene)
        # every controller tick is an output sample too: the controller (node) sees the published state
        self.t_out, self._ticks = t_out, ticks = output_times(scene, T, self.period)
        self._cmds = sorted((c for c in scene.commands if c.time < T), key=lambda c: c.time)
        fly = scene.effects.flywheel  # the kinks of its speed profile are breaks: steps never straddle one
        knots = {t for t in fly.profile.time if 0 < t < T} if fly is not None else set()
        # output samples are breaks where a caller acts on each (the ROS node publishes and paces); in-process
        # they are recorded inside one advance (the same bits: Simulator._segment)
        # (with an effect on the step plan is made afresh at every advance: the samples stay breaks)
        if self.sim.eff[effects.ON] != 0.0:
            sample_breaks = True
        # (NumPy arrays, 8 bytes an instant: a long run's breaks are not a Python list of floats)
        # the breaks of every run, samples or not: where the shadow follows (Runner._follow)
        self._common = np.unique(np.concatenate([np.array([c.time for c in self._cmds], dtype=float), ticks,
                                                 np.array([T], dtype=float), np.array(sorted(knots), dtype=float),
                                                 self._checks]))
        self.breaks = np.unique(np.concatenate([t_out if sample_breaks else np.zeros(0), self._common]))
        # output rows held in memory: all of them, or a buffer of ``buffer_rows`` that release() empties (a
        # streamed run: its rows go to a bag as they come, memory stays flat however long the run)
        if buffer_rows is not None and buffer_rows < 2:
            raise ValueError(f"buffer_rows = {buffer_rows}: must be at least 2")
        n = t_out.size if buffer_rows is None else min(t_out.size, int(buffer_rows))
        self._base = 0  # the output row (of the whole run) held in buffer row 0
        k = len(self.sim.stator_names)
        self.out_y = np.empty((n, self.sim.y.size))
        self.out_N = np.empty((n, 3))
        self.cur = np.empty((n, k))
        self.rate = np.empty((n, k))
        self.phase = np.empty((n, k))
        self.row = 0
        self.command_log: list = []  # every command applied: (t, names, currents|None, rates|None)
        self._bi = 0  # index of the next break to reach
        self._ci = 0
        self.wall_time = 0.0  # s in advance(), numba compile time left out (compile_time)
        self.compile_time = 0.0

    # --- the loop, one break at a time ---------------------------------------------------------
    @property
    def done(self) -> bool:
        return self._bi >= len(self.breaks) and self.row > 0

    @property
    def is_control_tick(self) -> bool:
        """Whether the present time is a controller tick (commands are due before advancing)."""
        t = self.sim.t
        i = int(np.searchsorted(self._ticks, t))
        return i < self._ticks.size and self._ticks[i] == t

    def _buf(self, rows: slice) -> slice:
        """Buffer rows of output rows ``rows`` (of the whole run); refused if :meth:`release` dropped them."""
        if rows.start < self._base:
            raise ValueError(f"output rows {rows.start}..{rows.stop}: rows before {self._base} were released")
        return slice(rows.start - self._base, rows.stop - self._base)

    def release(self) -> None:
        """Forget the output rows written so far (the caller has taken them): the buffer starts afresh at the
        present row, and commands logged so far are dropped (:meth:`take_commands` hands them over first)."""
        self._base = self.row
        self.command_log.clear()

    def take_commands(self) -> list:
        """The commands applied since the last call (or the start), ``(t, names, currents|None, rates|None)``."""
        out, self.command_log[:] = list(self.command_log), []
        return out

    def apply_scene_commands(self) -> None:
        """Apply the scene's scheduled commands due at or before the present time."""
        due: dict = {}
        while self._ci < len(self._cmds) and self._cmds[self._ci].time <= self.sim.t:
            c = self._cmds[self._ci]
            cur, rate = due.get(c.stator, (None, None))
            due[c.stator] = (c.current if c.current is not None else cur, c.rate if c.rate is not None else rate)
            self._ci += 1
        self.apply_commands(due)  # one command message per instant

    def record_initial(self) -> slice:
        """Record the sample at t = 0 (after the scene's commands of t = 0). Returns its row slice."""
        self.apply_scene_commands()
        self.out_y[0], self.out_N[0] = self.sim.y, self.sim.torque()
        self.cur[0], self.rate[0], self.phase[0] = self.sim.current, self.sim.rate, self.sim.phase
        self.row = 1
        if self.breaks.size and self.breaks[0] == 0.0:
            self._bi = 1
        return slice(0, 1)

    def control_input(self):
        """The state a control law sees now (gyro_ctl.laws.ControlInput)."""
        from gyro_ctl.laws import ControlInput

        sim = self.sim
        L, q = sim.y[0:3].copy(), sim.y[3:7].copy()
        if sim.eff[effects.ON] or not sim.attitude:
            omega_b = sim.body_rates(sim.t, sim.y)[0]
        else:
            omega_b = body_rates(sim.J, L, q)[1]
        if not hasattr(self, "_axes"):
            self._axes = (tuple(sim.stator_names), np.cross(sim.e1, sim.e2))
        return ControlInput(t=stamp_ns(sim.t) * 1e-9, L=L, q=q, omega_b=omega_b, stator_names=self._axes[0], stator_axes=self._axes[1])

    def apply_commands(self, commands: dict) -> None:
        """Apply ``{stator name: (current A, rate rad/s)}`` now (unknown names raise ValueError)."""
        for name in commands:
            if name not in self.sim.stator_names:
                raise ValueError(f"unknown stator {name!r}; allowed: {self.sim.stator_names}")
        self.sim.set_stators({self.sim.stator_names.index(n): c for n, c in commands.items()})
        if self.shadow is not None:
            self.shadow.set_stators({self.sim.stator_names.index(n): c for n, c in commands.items()})
        if commands:
            names = list(commands)
            self.command_log.append((self.sim.t, names, [commands[n][0] for n in names], [commands[n][1] for n in names]))

    def advance(self, until: Optional[float] = None) -> slice:
        """Integrate to the next break (or to ``until`` if that comes first); returns the output rows written."""
        if self.row == 0:
            return self.record_initial()
        tb = float(self.breaks[self._bi])
        if until is not None and until < tb:
            tb = until
        else:
            self._bi += 1
        t_out, row = self.t_out, self.row
        sel = t_out[row:][t_out[row:] <= tb + 1e-12 * max(1.0, tb)]
        sim = self.sim
        t_seg, ph0, r0, c0 = sim.t, sim.phase.copy(), sim.rate.copy(), sim.current.copy()
        out = slice(row, row + sel.size)
        rows = self._buf(out)
        if rows.stop > self.out_y.shape[0]:
            raise RuntimeError(f"output buffer of {self.out_y.shape[0]} rows is full: release() the rows taken")
        with CompileClock() as clock:
            self.row = sim.advance(tb, sel, self.out_y, self.out_N, rows.start) + self._base
            self._accumulate(sel, rows)
            if self.shadow is not None:
                self._follow(tb, sel)
        self.wall_time += clock.wall
        self.compile_time += clock.compile
        self.cur[rows] = c0
        self.rate[rows] = r0
        self.phase[rows] = np.mod(ph0 + r0 * (sel[:, None] - t_seg), 2 * math.pi)
        self.apply_scene_commands()
        return out

    # --- accuracy: the shadow run, the checks, the estimate ----------------------------------------
    def _follow(self, tb: float, sel: np.ndarray) -> None:
        """Advance the shadow to ``tb`` where that is a break of every run (not an output sample made a break:
        the ROS node's samples are breaks, an in-process run's are not, and the shadow must take the same steps in
        both); at a check instant compare and maybe change the step."""
        sim, sh = self.sim, self.shadow
        j = int(np.searchsorted(self._common, tb))
        if j < self._common.size and self._common[j] == tb or not (np.searchsorted(self.breaks, tb) < self.breaks.size
                                                                   and self.breaks[np.searchsorted(self.breaks, tb)] == tb):
            method, free, h = sim._seg[1][5], sim._seg[1][4], sim._seg[1][6]
            s0 = sh.steps
            sh.advance(tb)
            self.control.note_method(method, sim.steps - self._steps_seen, sh.steps - s0,
                                     exact=free and sim._free_axis != -1,
                                     stiff=h > sim.tau_min)
            self._steps_seen = sim.steps
        else:
            return
        if self._ck < self._checks.size and tb == self._checks[self._ck]:
            self._ck += 1
            # |N| now and its mean since the previous check; whether the shadow's steps were longer there
            # (from the states at the checks alone: the same in every run, whatever its samples)
            n_now = float(np.linalg.norm(sim.torque())) if not sim._seg[1][4] else 0.0
            L0, t0, st0, sst0 = self._at_check
            n_mean = float(np.linalg.norm(sim.y[0:3] - L0)) / (tb - t0) if tb > t0 else n_now
            meas = sim.steps - st0 >= R_MEASURABLE * (sh.steps - sst0)
            self._at_check = (sim.y[0:3].copy(), tb, sim.steps, sh.steps)
            f = self.control.check(tb, sim, sh, method, n_now, n_mean, meas)
            if f is not None:
                sim.step_div *= f
            if f is not None or method in RATE_KNOB:  # (their step is J Ω / N of the state now: re-planned here)
                sim.replan()
                sh.replan()

    def _accumulate(self, sel: np.ndarray, rows: slice) -> None:
        """∫|N| dt and ∫ | |Ω| − |Ω0| | dt over the new output samples (the modes' error bound, error_estimate)."""
        if not sel.size:
            return
        r = slice(rows.start, rows.start + sel.size)
        Ln = np.linalg.norm(self.out_y[r, 0:3], axis=1)
        self.control.note_L(float(np.max(Ln)))
        if self.sim.mode_plan.kind in (None, "thin_shell"):  # no truncation error to weigh (ModePlan.error_at: 0)
            self._last_t = float(sel[-1])
            return
        dt = np.diff(np.concatenate([[self._last_t], sel]))
        N = np.linalg.norm(self.out_N[r], axis=1)
        om = Ln * float(np.max(self.sim.Jinv))
        # (sequential sums, as one sample at a time would give: the same bits whether samples are breaks or not)
        self._impulse = float(np.cumsum(np.concatenate([[self._impulse], N * dt]))[-1])
        self._spin_dev = float(np.cumsum(np.concatenate([[self._spin_dev], np.abs(om - self._om0) * dt]))[-1])
        self._last_t = float(sel[-1])

    def resync_shadow(self) -> None:
        """The run's state was set from outside (a fidelity hand-over): keep the errors so far and start the
        shadow afresh from the run's state."""
        if self.shadow is None:
            return
        sim, sh = self.sim, self.shadow
        self.control.measure(sim, sh)
        self.control.bank()
        sh.y[:] = sim.y
        sh.t, sh.phase, sh.current, sh.rate = sim.t, sim.phase.copy(), sim.current.copy(), sim.rate.copy()
        sh._nu_max = sim._nu_max
        sh.replan()

    def error_estimate(self) -> ErrorEstimate:
        """The run's estimated error so far (over the whole duration once it is done): the steps' (from the shadow,
        else the plan's model), the eddy modes' truncation at the largest slip met, the averaged models' O(ε)."""
        sim, acc = self.sim, self.scene.accuracy
        ctl = self.control
        L_max = max(ctl.L_max, float(np.linalg.norm(sim.y[0:3])), 1e-300)
        if self.shadow is not None:
            sL, sq, how = *ctl.measure(sim, self.shadow)[2:], "richardson"
            # steppers whose stretches the shadow could not measure (its steps no longer than the run's: stops
            # closer than the step): the plan's model at the knob they ran
            for m, k in ctl.weights.items():
                if not k or k >= R_MEASURABLE * ctl.shadow_steps.get(m, 0):
                    continue  # (measured)
                m = "etdrk4" if m == STIFF else m
                knob = (sim.step_plan.knob(m) / sim.step_div if m in RATE_KNOB
                        else sim.step_plan.knob(m) * sim.step_div)
                pL, pq = sim.step_plan.predicted(m, knob)
                sL, sq, how = sL + pL, sq + pq, "richardson+model"
        else:
            used = sorted(getattr(sim, "methods_used", set()) or {"free"})
            pred = [sim.step_plan.predicted(m) for m in used if m != "free" or sim._free_axis == -1]
            sL = max([p[0] for p in pred] + [0.0])
            sq = max([p[1] for p in pred] + [0.0])
            how = "model"
        e_g, e_im = sim.mode_plan.error_at(max(sim.slip_met, 0.0))
        mL = max(e_g, e_im) * self._impulse / L_max
        mq = e_im * self._spin_dev
        aL = 0.0
        if self.averaged_eps:  # (only a hybrid run has averaged stretches: gyro_sim.fidelity imports SciPy's solvers)
            from gyro_sim.engine.fidelity import AVERAGED_ERROR

            aL = AVERAGED_ERROR * max(self.averaged_eps)
        att = sim.attitude and not self.averaged_eps
        return ErrorEstimate(L=sL + mL + aL, attitude=(sq + mq) if att else math.nan, steps_L=sL,
                             steps_attitude=sq if att else math.nan, modes_L=mL, modes_attitude=mq if att else math.nan,
                             averaged_L=aL, steps_method=how, rtol=acc.rtol,
                             atol=math.nan if acc.attitude is None else acc.attitude)

    # --- exact switching instants ------------------------------------------------------------
    def _snapshot(self) -> tuple:
        sim = self.sim
        return (sim.y.copy(), sim.t, sim.phase.copy(), sim.current.copy(), sim.rate.copy(), sim._nu_max,
                self.row, self._bi, self._ci, len(self.command_log))

    def _restore(self, snap: tuple) -> None:
        sim = self.sim
        sim.y[:], sim.t, sim.phase[:], sim.current[:], sim.rate[:], sim._nu_max = snap[:6]
        self.row, self._bi, self._ci = snap[6:9]
        del self.command_log[snap[9]:]

    def advance_located(self, law, switching) -> slice:
        """:meth:`advance` to the next break, switching the law's commands at the exact zeros of its
        switching functions in between (bisection to 1e-12 relative in time on re-integrated states).

        ``switching(x)`` returns the law's switching functions; a sign change of a non-zero one is a
        switch. Integration work of the search counts in ``steps``.
        """
        first = self.row
        for _ in range(10_000):  # a sliding mode would switch without end: then the tick's sampling takes over
            snap = self._snapshot()
            s0 = switching(self.control_input())
            t0 = self.sim.t
            self.advance()
            s1 = switching(self.control_input())
            if not np.any((np.sign(s0) * np.sign(s1)) < 0):
                return slice(first, self.row)
            lo_t, hi_t, lo = t0, self.sim.t, snap
            for _ in range(200):
                if hi_t - lo_t <= 1e-12 * max(1.0, hi_t):
                    break
                mid = 0.5 * (lo_t + hi_t)
                self._restore(lo)
                self.sim.advance(mid)
                s = switching(self.control_input())
                if np.any((np.sign(s0) * np.sign(s)) < 0):
                    hi_t = mid
                else:
                    lo_t, lo = mid, self._snapshot()
            self._restore(snap)
            self.advance(until=hi_t)  # records the samples before the switch
            # the re-integrated path may end a hair before the zero: step on until the sign has turned,
            # so the same switch is never found twice
            dt = 1e-12 * max(1.0, hi_t)
            while (not np.any(np.sign(s0) * np.sign(switching(self.control_input())) < 0)
                   and self.sim.t + dt < float(self.breaks[self._bi])):
                self.advance(until=self.sim.t + dt)
                dt *= 2.0
            self.apply_commands(law(self.control_input()))
        self.advance()  # to the break, sampled
        return slice(first, self.row)

    def samples(self, rows: slice, euler: bool = True) -> dict:
        """Output rows as arrays: t, L, q, omega_b, euler (None unless ``euler``), torque, energy, current,
        rate, phase, modes, effects (without attitude: q and euler NaN, omega_b in the case frame). ``rows``: output rows of the
        whole run (not yet released)."""
        t_rows, rows = self.t_out[rows], self._buf(rows)
        L, q = self.out_y[rows, 0:3], self.out_y[rows, 3:7]
        extra = {}
        if not self.sim.attitude:
            omega_b = self.sim.body_rates(t_rows, self.out_y[rows])
            energy = kinetic_energy(self.sim.J, omega_b)  # isotropic: frame-free
        elif self.sim.eff[effects.ON]:
            t = t_rows
            omega_b = self.sim.body_rates(t, self.out_y[rows])
            energy = kinetic_energy(self.sim.J, omega_b)  # the rigid body's own
            extra = self.sim.effect_outputs(t, self.out_y[rows])
        else:
            _, omega_b = body_rates(self.sim.J, L, q)
            energy = kinetic_energy(self.sim.J, omega_b)
        eul = None
        if euler:
            eul = euler_angles(quat_to_matrix(q), L) if self.sim.attitude else np.full((L.shape[0], 3), np.nan)
        return {"t": t_rows, "L": L, "q": q, "omega_b": omega_b, "euler": eul, "torque": self.out_N[rows],
                "energy": energy, "current": self.cur[rows], "rate": self.rate[rows], "phase": self.phase[rows],
                "modes": self.out_y[rows, 7:7 + 3 * self.sim.tau.size], "effects": extra}

    def result(self) -> RunResult:
        """The whole run as a :class:`RunResult` (refused once rows were released: a streamed run's result is read
        back from its bag)."""
        if self._base:
            raise RuntimeError("Runner.result: output rows were released (a streamed run); read its bag back")
        s = self.samples(slice(0, self.row), euler=False)
        return RunResult(scene=self.scene, t=s["t"], L=s["L"], q=s["q"], omega_b=s["omega_b"],
                         torque=s["torque"], energy=s["energy"], stator_names=list(self.sim.stator_names),
                         current=s["current"], field_rate=s["rate"], field_phase=s["phase"],
                         modes=self.out_y[: self.row, 7:7 + 3 * self.sim.tau.size], wall_time=self.wall_time,
                         compile_time=self.compile_time,
                         steps=self.sim.steps, commands=list(self.command_log), effects=s["effects"],
                         attitude=self.sim.attitude, error_estimate=self.error_estimate())


def run(scene: Scene, duration: Optional[float] = None, on_samples=None, attitude: Optional[bool] = None,
        estimate: Optional[bool] = None) -> RunResult:
    """Run a scene in-process (no ROS) and return its time series at the scene's output rate.

    A scene with a ``controller`` runs its law (gyro_ctl) at every tick, and with ``sampling: events``
    also at the exact zeros of the law's switching functions between ticks. ``on_samples(dict)``, if
    given, is called with each new chunk of output rows (see :meth:`Runner.samples`). ``attitude``: None
    = the scene's ``output.attitude``, True = integrate it anyway (:func:`integrates_attitude`).
    ``estimate``: False runs without the error control's shadow run (:class:`Runner`; the estimate is then the
    step plan's model), e.g. to time the integrator alone at given knobs; None: with it where it can follow.
    """
    if scene.fidelity != "full":
        from gyro_sim.engine.fidelity import run_hybrid

        return run_hybrid(scene, duration, estimate=estimate)
    ctl = scene.controller
    switching = ctl is not None and ctl.sampling == "events"
    # samples are breaks where a caller acts on them, and where switching events are looked for between
    # breaks (the node does the same: the same events, the same bits)
    r = Runner(scene, duration, sample_breaks=on_samples is not None or switching, attitude=attitude,
               estimate=estimate)
    drive(r, on_samples)
    return r.result()


def drive(r: Runner, on_samples=None, release: bool = False) -> None:
    """Run a :class:`Runner` to its end with the scene's controller law (if any; at the exact switching instants
    with ``sampling: events``), calling ``on_samples(dict)`` with each new chunk of output rows
    (:meth:`Runner.samples`). ``release``: after each call the rows (and logged commands) are released, so
    memory stays flat (a streamed run: the caller took them). ``r.wall_time`` / ``r.compile_time`` are set even
    when the run is interrupted (KeyboardInterrupt), up to the interruption. Ticks and samples between the other
    breaks go through the compiled tick loop where it applies (gyro_sim/ticks.py: the same numbers)."""
    from gyro_ctl.laws import make_law, make_switching

    from gyro_sim.engine import ticks

    ctl = r.scene.controller
    law = make_law(ctl) if ctl is not None else None
    switching = make_switching(ctl) if ctl is not None and ctl.sampling == "events" else None
    loop = ticks.tick_loop(r, law) if switching is None else None  # ticks in compiled code where they can be
    clock = CompileClock()
    try:
        with clock:
            while not r.done:
                if r.row > 0 and law is not None and r.is_control_tick:
                    r.apply_commands(law(r.control_input()))
                rows = (r.advance_located(law, switching) if switching is not None and r.row > 0
                        else ticks.advance(r, loop))
                if on_samples is not None and rows.stop > rows.start:
                    on_samples(r.samples(rows))
                    if release:
                        r.release()
    finally:
        r.wall_time, r.compile_time = clock.wall, clock.compile
