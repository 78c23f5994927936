"""The :class:`Simulator`: the state of a run of a scene (t, y, the stators' commands) and the composition of the
engine's parts that advance it — the model's terms (:mod:`gyro_sim.engine.terms`), the controller of the step
(:mod:`gyro_sim.engine.step_size`) and the steppers (:mod:`gyro_sim.engine.steppers`) — under piecewise-constant
stator commands.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from gyro_sim.compiled import effects
from gyro_sim.engine import steppers
from gyro_sim.engine.model import integrates_attitude
from gyro_sim.engine.step_size import Lead, State, StepSize
from gyro_sim.engine.steppers import CALL_STEPS, CALL_WALL  # noqa: F401  (their home: gyro_sim.engine.steppers)
from gyro_sim.engine.terms import Terms
from gyro_sim.physics.frames import euler_angles, norm3, quat_to_matrix
from gyro_sim.scenes.accuracy import is_legacy, mode_plan, spin_reach
from gyro_sim.scenes.limits import command_problem
from gyro_sim.scenes.scene import Scene, check_valid


_NO_RECORD = np.array([False])  # (advance to one stop, recording nothing: read only)


def _model(name: str, doc: str) -> property:
    """A read-only view of the model's attribute ``name`` (:class:`~gyro_sim.engine.terms.Terms`)."""
    return property(lambda self: getattr(self.terms, name), doc=doc)


class Simulator:
    """A run's state advanced in time under piecewise-constant stator commands.

    State: ``t`` (s) and ``y`` (see :mod:`gyro_sim.compiled.kernels`), the stators' ``current`` (A), ``rate``
    (rad/s) and ``phase`` (rad); field phases σ_k are continuous across command changes. ``attitude``: see
    :func:`integrates_attitude`; without it y[3:7] is NaN and the eddy modes are in the case frame. Parts:
    ``terms`` (the model, :class:`~gyro_sim.engine.terms.Terms`; its arrays are read here as ``J``, ``tau``,
    ``eff``, ...), ``step_size`` (the controller of the step, :class:`~gyro_sim.engine.step_size.StepSize`); the
    steppers are called through :func:`gyro_sim.engine.steppers.integrate`.
    """

    J = _model("J", "Principal moments of inertia (3,), kg m².")
    Jinv = _model("Jinv", "1/J (3,), 1/(kg m²).")
    conductor = _model("conductor", "The conductor's eddy-mode model (None without a torque model).")
    tau = _model("tau", "The eddy modes' time constants (N,), s.")
    w = _model("w", "The eddy modes' weights (N,).")
    tail = _model("tail", "The modes' tail time constant (s; τ_eff of the quasi-static model).")
    c_m = _model("c_m", "The conductor's moment scale.")
    tau_min = _model("tau_min", "The fastest eddy mode's time constant (s; inf without modes).")
    lam = _model("lam", "The linear part's rates λ of y (1/s).")
    eff = _model("eff", "The effects' parameter vector (gyro_sim.compiled.effects.pack_effects).")
    n_extra = _model("n_extra", "The effects' states in y.")
    stator_names = _model("stator_names", "The stators' names, in the scene's order.")
    e1 = _model("e1", "The stators' first field axes (k, 3), case frame.")
    e2 = _model("e2", "The stators' second field axes (k, 3), case frame.")
    axes = _model("axes", "The stators' unit axes u = e1 × e2 (k, 3), case frame.")
    b = _model("b", "The stators' coil constants (k,), T/A.")
    max_current = _model("max_current", "Each stator's largest current (k,), A (gyro_sim.scenes.limits).")
    max_rate = _model("max_rate", "Each stator's largest |field rate| (k,), rad/s (gyro_sim.scenes.limits).")
    field_B = _model("field_B", "The general field's complex amplitudes B_p (n, 3), T.")
    field_om = _model("field_om", "The general field's angular frequencies ω_p (n,), rad/s.")

    def __init__(self, scene: Scene, attitude: Optional[bool] = None, horizon: Optional[float] = None,
                 quiet: bool = False, warn_plan: bool = True):
        check_valid(scene)  # (a copy made by model_copy(update=...) is not validated: refused here in one line)
        self.scene = scene
        self.quiet = quiet  # no accuracy warnings (a shadow run: gyro_sim.accuracy.ErrorControl)
        # the step is the plan's divided by step_div (the run's error control changes it at its checks); a shadow
        # run follows its ``leader``: the same stepper, steps SHADOW_RATIO times the leader's
        self.step_div = 1.0
        self.leader: Optional["Simulator"] = None
        #: a shadow's step is at most SHADOW_RATIO times this (s): the leader's longest span between stops
        self.lead_gap = math.inf
        self.attitude = integrates_attitude(scene, attitude)
        # the run's accuracy plan (gyro_sim/scenes/accuracy.py): made for ``horizon`` s (default: the scene's duration),
        # the same in-process and in the ROS node
        self.horizon = float(scene.duration if horizon is None else horizon)
        om_reach = spin_reach(scene, self.horizon)  # the fastest spin the run can reach (rad/s)
        self.mode_plan = mode_plan(scene, self.horizon, self.attitude, quiet=quiet, reach=om_reach)
        self.terms = terms = Terms(scene, self.attitude, self.mode_plan)
        # --- the stators' commands
        st = scene.stators
        self.current = np.array([s.current for s in st], dtype=float)
        self.rate = np.array([s.rate for s in st], dtype=float)
        self.phase = np.array([s.phase for s in st], dtype=float)
        # --- initial state
        self.y = terms.initial_state()
        self.t = 0.0
        self._seg, self._seg_t_end = None, math.nan  # see _segment
        # the fields are switched on at t = 0 on a rotor free of eddy currents
        # Σ |ΔB| |B_after|, Σ t |ΔB| |B_after|, Σ |ΔB × B_before|, Σ t |ΔB × B_before| of the field steps (T², T² s:
        # the modes left out answer them, modal_truncation.step_times)
        self.field_steps = np.zeros(4)
        if terms.tau.size:
            self._field_step(np.zeros(3), self.field_now())
        self._no_rows = (np.zeros((1, self.y.size)), np.zeros((1, 3)))  # (advance's rows where it records nothing)
        self.steps = 0
        self.call_steps = steppers.CALL_STEPS[0]  # most steps of one stepper call (tuned to CALL_WALL s a call)
        self._nu_max = max([abs(s.rate) for s in st] + [abs(c.rate) for c in scene.commands if c.rate is not None]
                           + [0.0])
        # --- the step plan for the scene's accuracy over the horizon (gyro_sim/engine/step_size.py)
        self.step_size = StepSize(scene, terms, self.attitude, self.horizon, om_reach, self.mode_plan, self.y,
                                  quiet=quiet)
        # (warn_plan False: the caller warns, StepSize.warn_plan, once the step budget has passed the plan: Runner)
        if not quiet and not is_legacy() and warn_plan:
            self.step_size.warn_plan(self.state())

    def follower(self) -> "Simulator":
        """A shadow run of this one (the error control's: :class:`gyro_sim.engine.shadow.ErrorEstimator`): the same
        scene, model and plan, its own state (a copy of this one's now) and its own step notes, following this
        simulator (``leader``), quiet. Built from this simulator's parts instead of from the scene (no second
        validation, mode plan, model or step plan: the same numbers, ~0.1 ms instead of ~0.5 ms)."""
        sh = object.__new__(Simulator)
        sh.__dict__.update(self.__dict__)
        sh.quiet, sh.step_div, sh.leader, sh.lead_gap = True, 1.0, self, math.inf
        sh.terms = self.terms.copy()
        sh.current, sh.rate, sh.phase, sh.y = self.current.copy(), self.rate.copy(), self.phase.copy(), self.y.copy()
        sh.field_steps = self.field_steps.copy()  # (its own sums: _field_step adds to them in place)
        sh._seg, sh._seg_t_end = None, math.nan
        sh.steps, sh.call_steps = 0, steppers.CALL_STEPS[0]
        sh.step_size = self.step_size.copy(sh.terms, quiet=True)
        return sh

    def state(self) -> State:
        """The state a step is planned from (:class:`gyro_sim.engine.step_size.State`; its arrays are this
        simulator's, not copies)."""
        return State(self.t, self.y, self.current, self.rate, self.phase, self._nu_max)

    # --- the step plan (gyro_sim/engine/step_size.py) ------------------------------------------------
    @property
    def step_plan(self):
        """The step knobs in force (:class:`gyro_sim.scenes.step_control.StepPlan`)."""
        return self.step_size.step_plan

    @property
    def _auto_plan(self):
        return self.step_size.auto_plan

    @property
    def _rates(self) -> tuple:
        return self.step_size.rates

    @property
    def slip_met(self) -> float:
        """The largest slip bound met at a step plan (rad/s): the modes' error is judged there."""
        return self.step_size.slip_met

    def planned_steps(self, plan=None) -> float:
        """The steps the run's plan predicts over its horizon (:meth:`gyro_sim.engine.step_size.StepSize.
        planned_steps`; ``plan``: :meth:`plan_for`)."""
        return self.step_size.planned_steps(self.state(), plan)

    def plan_for(self, rtol: float, attitude: Optional[float], **accuracy):
        """The plan this run would take at tolerances ``rtol`` and ``attitude`` (rad, None: none) instead of the
        scene's (:meth:`gyro_sim.engine.step_size.StepSize.plan_for`)."""
        return self.step_size.plan_for(rtol, attitude, **accuracy)

    def _method(self) -> str:
        """The stepper a field step would take now (:meth:`gyro_sim.engine.step_size.StepSize.choose`)."""
        return self.step_size.choose(False, self.state())[0]

    def _max_step(self, free: bool, method: str, spt: Optional[int] = None) -> float:
        return self.step_size.max_step(free, method, self.state(), spt)

    def _frozen_flow_step(self, eps: Optional[float] = None) -> float:
        return self.step_size.frozen_flow_step(self.state(), eps)

    def _h_for(self, method: str) -> float:
        return self.step_size.h_for(method, self.state())

    def _effect_rate(self) -> float:
        return self.terms.effect_rate(self.t, self.y)

    # --- named views of the state -------------------------------------------------------------
    @property
    def L(self) -> np.ndarray:
        """Kinetic moment (angular momentum) L now, (3,) N·m·s, case frame (a copy of y[0:3]: the state moves on)."""
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
        names = self.terms.stator_names
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
        stators are named in). A current or rate that is not finite, a negative current, or one beyond the stator's
        ``max_current`` / ``max_rate`` (:mod:`gyro_sim.scenes.limits`) is refused with one ValueError naming the
        stator, the value and the limit, before anything changes."""
        n = len(self.terms.stator_names)
        if not all(type(k) is int and 0 <= k < n for k in commands):  # (the Runner's: indices in range already)
            commands = {self.stator_index(k): c for k, c in commands.items()}
        for k, (current, rate) in commands.items():
            why = command_problem(self.terms, k, current, rate)  # (its stator_names, max_current, max_rate)
            if why:
                raise ValueError(why)
        self._set_checked(commands)

    def _set_checked(self, commands: dict) -> None:
        """:meth:`set_stators` of commands ``{stator index: (current A | None, rate rad/s | None)}`` already checked
        (a shadow run takes its leader's, which its leader's set_stators passed: the same limits)."""
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
        """The eddy modes' instant answer to a field step (:meth:`gyro_sim.engine.terms.Terms.field_step`)."""
        self.terms.field_step(self.y, before, after)
        d = after - before
        # (|d| |after| and |d × before| as np.linalg.norm and np.cross compute them, the same bits, without their
        # ~20 µs at every command that changes a current: a law that sets the currents at every tick)
        c = np.array([d[1] * before[2] - d[2] * before[1], d[2] * before[0] - d[0] * before[2],
                      d[0] * before[1] - d[1] * before[0]])
        a, p = float(norm3(d) * norm3(after)), norm3(c)
        self.field_steps += (a, a * self.t, p, p * self.t)

    def phasors(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(Bre, Bim, ω) of the field from now on, referred to s = t − self.t (case frame, T): read them, do not
        write into them (:meth:`gyro_sim.engine.terms.Terms.phasors`)."""
        return self.terms.phasors(self.t, self.current, self.rate, self.phase)

    # --- time stepping -----------------------------------------------------------------------
    def advance(self, t_end: float, sample_times: Optional[np.ndarray] = None,
                out_y: Optional[np.ndarray] = None, out_N: Optional[np.ndarray] = None, k_out: int = 0) -> int:
        """Integrate to ``t_end`` (s) under the present commands, recording at ``sample_times``.

        Sample times must lie in (t, t_end]; states and torques are written to out_y/out_N
        from row k_out. Returns the next free row. The segment's stepper and step: :meth:`_segment`; the stepper
        is called in pieces a signal can interrupt (:func:`gyro_sim.engine.steppers.integrate`).
        """
        if t_end < self.t:
            raise ValueError(f"advance: t_end = {t_end} is before the present time {self.t}")
        if sample_times is None or len(sample_times) == 0:
            stops = np.array([t_end])
            record = _NO_RECORD
            out_y, out_N = self._no_rows  # (nothing is recorded into them)
        else:
            stops = np.asarray(sample_times, dtype=float)
            n = stops.size
            if stops[-1] < t_end:  # (np.append's arrays, made at once)
                s2 = np.empty(n + 1)
                s2[:n] = stops
                s2[n] = t_end
                stops = s2
                record = np.ones(n + 1, dtype=np.bool_)
                record[n] = False
            else:
                record = np.ones(n, dtype=np.bool_)
        assert out_y is not None and out_N is not None  # (rows to write the samples into)
        seg = self._segment()
        calls = steppers.integrate(self.terms, self.y, self.t, t_end, seg, stops, record, out_y, out_N, k_out,
                                   self.call_steps)
        for row, steps, call_steps in calls:  # (call by call: a run interrupted between two calls counts its steps)
            self.steps += steps
            self.call_steps, k_out = call_steps, row
        self.phase = np.mod(self.phase + self.rate * (t_end - self.t), 2 * math.pi)
        self.t = t_end
        self._seg_t_end = t_end
        return k_out

    def _tune_call(self, wall: float, steps: int) -> None:
        """Tune :attr:`call_steps` after a stepper call (:func:`gyro_sim.engine.steppers.tune_call`)."""
        self.call_steps = steppers.tune_call(self.call_steps, wall, steps)

    def _segment(self) -> tuple:
        """(t_seg, Bre, Bim, ω, free, stepper, h_max) for the next advance: the phasors referred to t_seg and
        the step plan (:meth:`gyro_sim.engine.step_size.StepSize.plan`), kept from the previous advance while the
        commands are the same and the time goes on from where it ended, so a run gives the same bits whether its
        output samples are breaks or not; computed afresh otherwise, and at every advance when an effect is on
        (its rates change in time). The plan is made for the rates at the start of a command segment:
        ``steps_per_turn`` and ``rate_change`` hold there. Within a segment a spin-up below the field's rates keeps
        it (the fastest rate is the field's), but a rotor braking from above them keeps the step of its start:
        frozen_flow's step, which grows with the rate, is then up to (start rate / present rate) times
        longer than ``rate_change`` asks (a braking run forced to frozen_flow measured 5x the error of a
        re-planned one); give such scenes a ``max_step`` or commands that re-plan."""
        key = (self.current.tobytes(), self.rate.tobytes())
        seg = self._seg
        eff = self.terms.eff
        if seg is not None and seg[0] == key and self.t == self._seg_t_end and eff[effects.ON] == 0.0:
            return seg[1]
        Bre, Bim, om = self.phasors()
        st = self.state()
        self.step_size.check_slip(om, st)
        # no field (or no torque model) and no effect: the geometric free stepper
        free = (om.size == 0 or (self.terms.c_m == 0.0 and eff[effects.MAG] == 0.0)) and eff[effects.ON] == 0.0
        ld = self.leader
        lead = None if ld is None else Lead(ld._seg[1][5] if ld._seg is not None else None, ld.step_div, self.lead_gap)
        method, h_max = self.step_size.plan(free, st, self.step_div, lead)
        self._seg = (key, (self.t, Bre, Bim, om, free, method, h_max))
        return self._seg[1]

    def replan(self) -> None:
        """Make the step plan afresh at the next advance (the error control changed ``step_div``)."""
        self._seg = None

    # --- what the state gives (gyro_sim/engine/terms.py) ---------------------------------------
    def torque(self) -> np.ndarray:
        """Electrodynamic torque now (case frame, N·m)."""
        return self.terms.torque(self.t, self.y, self.phasors())

    def effect_outputs(self, t: np.ndarray, Y: np.ndarray) -> dict:
        """Outputs of the effects that are on, for states ``Y`` (rows) at times ``t`` (s), SI
        (:meth:`gyro_sim.engine.terms.Terms.effect_outputs`)."""
        return self.terms.effect_outputs(t, Y)

    def body_rates(self, t: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """Ω_b (rad/s, body frame) of states ``Y`` (rows) at times ``t`` (s), effects included; without attitude
        Ω = L/J in the case frame (:meth:`gyro_sim.engine.terms.Terms.body_rates`)."""
        return self.terms.body_rates(t, Y)
