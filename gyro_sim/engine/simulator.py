"""The :class:`Simulator`: the full model of a scene (conductor modes, stators, effects, the step plan of its
accuracy) advanced in time by the compiled steppers under piecewise-constant stator commands.
"""
from __future__ import annotations

import math
import time
from typing import Optional

import numpy as np

from gyro_sim.compiled import effects, frozen_flow, kernels, qs_flow
from gyro_sim.engine.model import (FROZEN_FLOW_COST, _case_flag, _initial_attitude, _tableau, body_rates,
                                   integrates_attitude, lawson8_cost, stator_triad)
from gyro_sim.physics.conductor import DEFAULT_N_MODES, conductor_model
from gyro_sim.physics.frames import euler_angles, quat_to_matrix
from gyro_sim.scenes.accuracy import (PHASE_REL_MIN, RATE_KNOB, SHADOW_RATIO, STEPS_WARN, auto_plan,
                                      field_rates, is_legacy, mode_plan, spin_reach, step_plan, truncated_model)
from gyro_sim.scenes.accuracy import warn as accuracy_warning
from gyro_sim.scenes.limits import command_problem, stator_limits
from gyro_sim.scenes.scene import Scene, check_valid
from gyro_sim.scenes.tolerance import has_symmetry_axis


#: the wall time (s) one stepper call of :meth:`Simulator.advance` aims at: a long advance is made of calls of about
#: this length, and Python handles a signal (SIGINT, SIGTERM) between two of them
CALL_WALL = 0.1
#: steps of the first call of a long advance, and the bounds the calls' steps are tuned within (:meth:`Simulator.
#: _tune_call`); where the calls are cut does not change a bit of the result
CALL_STEPS = (4096, 16, 1 << 24)


class Simulator:
    """The full model of a scene, advanced in time under piecewise-constant stator commands.

    State: ``t`` (s) and ``y`` (see :mod:`gyro_sim.kernels`). Field phases σ_k are continuous
    across command changes. ``attitude``: see :func:`integrates_attitude`; without it y[3:7] is NaN and the
    eddy modes are in the case frame (``self.attitude`` False).
    """

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
        J = scene.inertia
        self.J = J
        self.Jinv = 1.0 / J
        # the run's accuracy plan (gyro_sim/scenes/accuracy.py): made for ``horizon`` s (default: the scene's duration),
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
        # each stator's largest current (A) and |field rate| (rad/s): a command beyond is refused (scenes/limits.py)
        self.max_current, self.max_rate = stator_limits(scene)
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
        self.call_steps = CALL_STEPS[0]  # most steps of one stepper call (advance: tuned to CALL_WALL s a call)
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
        # --- the step knobs for the scene's accuracy over the horizon (gyro_sim/scenes/accuracy.py): turns of the
        # fastest rotation the run can meet (spin it can reach, field rates, an effect's rate) and of the free body
        # motion
        Lmag0 = float(np.linalg.norm(self.y[0:3]))
        om_plan = max(om_reach, field_rates(scene), self._effect_rate())
        L_bound = Lmag0 if om_reach <= Lmag0 * float(np.max(self.Jinv)) * (1 + 1e-12) else float(np.max(J)) * om_reach
        self.L_bound = L_bound  # the largest |L| the run can reach (N m s; gyro_sim.accuracy.ErrorControl)
        om_free = L_bound * float(np.max(np.abs(self.Jinv - self._inv_ref))) if self._free_axis == -1 else 0.0
        self._rates = (om_plan, om_free)  # (plan_for: the plan at other tolerances)
        self.step_plan = step_plan(scene, self.horizon, self.attitude, om_plan, om_free)
        self._auto_plan = auto_plan(self.step_plan, scene)
        self._knob_warned: set = set()
        if not quiet and not is_legacy() and warn_plan:  # (warn_plan False: the caller warns, _warn_plan, once the
            self._warn_plan(om_plan)                     # step budget has passed the plan: Runner)

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
        stators are named in). A current or rate that is not finite, a negative current, or one beyond the stator's
        ``max_current`` / ``max_rate`` (:mod:`gyro_sim.scenes.limits`) is refused with one ValueError naming the
        stator, the value and the limit, before anything changes."""
        n = len(self.stator_names)
        if not all(type(k) is int and 0 <= k < n for k in commands):  # (the Runner's: indices in range already)
            commands = {self.stator_index(k): c for k, c in commands.items()}
        for k, (current, rate) in commands.items():
            why = command_problem(self, k, current, rate)
            if why:
                raise ValueError(why)
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
                    # the quasi-static model: the quasi-static flow step instead (gyro_sim/compiled/qs_flow.py)
                    m = "qs_flow" if self._qs_applies() else "frozen_flow"
                    self._check_knob(m)
                    return m, self._frozen_flow_step(self.step_plan.knob(m))
            self._check_knob(m)
            return m, h
        self._check_knob(m)
        return m, self._max_step(False, m)

    def _qs_applies(self) -> bool:
        """Whether ``auto`` takes the quasi-static flow step (gyro_sim/compiled/qs_flow.py) where it would take
        frozen_flow: on the quasi-static torque model (not in the old defaults' runs, gyro_sim.accuracy.legacy). Its
        step is as long (the same error model), costs a third (0.8 µs against 2.3 µs, one phasor), and its error
        measured no larger on every quasi-static scene (docs/numerics.md). Where frozen_flow does not pay, lawson8
        stays: its error is the predictable one (it resolves the field's ripple): on reorient_L qs_flow takes 403 699
        steps (2.6 s CPU) against lawson8's 10 319 (0.18 s), docs/accuracy.md."""
        return not is_legacy() and qs_flow.applies(self.scene, self.J, self.eff[effects.ON] != 0.0)

    def planned_steps(self, plan=None) -> float:
        """The steps the run's plan predicts over its horizon (the accuracy's own knobs, :attr:`_auto_plan`, or
        ``plan``: :meth:`plan_for`): turns of the fastest rotation times lawson8's or ETDRK4's steps per turn, or the
        horizon over the frozen-flow step where that stepper applies, the fewest of them. An estimate made before
        any step (the error control then changes the step); :data:`gyro_sim.scenes.step_control.STEP_BUDGET` bounds
        it (:mod:`gyro_sim.engine.budget`)."""
        plan = self._auto_plan if plan is None else plan
        steps = min(plan.turns * plan.steps_per_turn["lawson8"], plan.turns * plan.steps_per_turn["etdrk4"])
        if frozen_flow.supported(self.J) >= 0 and self.eff[effects.ON] == 0.0 and self.c_m > 0:
            steps = min(steps, self.horizon / self._frozen_flow_step(plan.rate_change))
        return float(steps)

    def plan_for(self, rtol: float, attitude: Optional[float], **accuracy):
        """The plan (as :attr:`_auto_plan`: the accuracy's own knobs) this run would take at tolerances ``rtol`` and
        ``attitude`` (rad, None: none) instead of the scene's; for :meth:`planned_steps` (what to loosen)."""
        alt = self.scene.model_copy(update={"accuracy": self.scene.accuracy.model_copy(
            update={"rtol": rtol, "attitude": attitude, **accuracy})})
        return auto_plan(step_plan(alt, self.horizon, self.attitude, *self._rates), alt)

    def _warn_plan(self, om_plan: float) -> None:
        """Warn where the scene's attitude tolerance is below the floor a plan takes (PHASE_REL_MIN of the spin
        phase), and where the plan predicts a very long run (more than STEPS_WARN steps)."""
        acc, T = self.scene.accuracy, self.horizon
        floor = PHASE_REL_MIN * om_plan * T
        if self.attitude and acc.attitude is not None and acc.attitude < floor and not has_symmetry_axis(self.J):
            accuracy_warning(
                f"scene {self.scene.name!r}: accuracy.attitude = {acc.attitude:g} rad cannot be held over {T:g} s: "
                f"the phase the run can turn through is {om_plan * T:.3g} rad, and a run holds it to about "
                f"{PHASE_REL_MIN:g} of itself; planning for {floor:.2g} rad (the estimate reports what is reached; "
                f"set accuracy.attitude to at least that, or output.attitude: false where only L matters)")
        if self.attitude and acc.phase_atol is not None and acc.phase_atol < floor:
            accuracy_warning(
                f"scene {self.scene.name!r}: accuracy.phase_atol = {acc.phase_atol:g} rad cannot be held over "
                f"{T:g} s: the spin phase the run can turn through is {om_plan * T:.3g} rad, and a run holds it to "
                f"about {PHASE_REL_MIN:g} of itself; planning for {floor:.2g} rad (set accuracy.phase_atol to at "
                f"least that, or leave it out: accuracy.phase holds the phase relative to itself)")
        plan = self._auto_plan
        steps = self.planned_steps()
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
        if eL > plan.tol_L or eq > plan.plan_q:
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
        # the stepper is called for at most self.call_steps steps at a time and resumes where it stopped (the same
        # steps, the same bits: gyro_sim.compiled.kernels.integrate): between calls Python runs, so SIGINT / SIGTERM
        # are handled within about CALL_WALL s however long the advance
        pos = np.zeros(3)
        t0 = self.t
        case = _case_flag(self.attitude)
        ax = frozen_flow.supported(self.J) if method in ("frozen_flow", "qs_flow") else 0
        tab = None if method in ("frozen_flow", "qs_flow") or free else _tableau(method)
        n = stops.size
        while True:
            budget = self.call_steps
            w0 = time.perf_counter()
            if method == "frozen_flow":
                k_out, steps = frozen_flow.integrate_frozen(
                    self.y, t0, t_seg, stops, record, h_max, Bre, Bim, om, self.Jinv, self.J[(ax + 1) % 3],
                    self.J[ax], ax, self.c_m, self.w, self.tail, 1.0 / self.tau, out_y, out_N, k_out, *case, pos,
                    budget)
            elif method == "qs_flow":
                k_out, steps = qs_flow.integrate_qs(
                    self.y, t0, t_seg, stops, record, h_max, Bre, Bim, om, self.Jinv, self.J[(ax + 1) % 3],
                    self.J[ax], ax, self.c_m, self.w, self.tail, out_y, out_N, k_out, *case, pos, budget)
            elif free:
                k_out, steps = kernels.integrate_free(
                    self.y, t0, stops, record, h_max, self.Jinv, self._inv_ref, self._free_axis, self.tau,
                    out_y, out_N, k_out, pos, budget)
            else:
                k_out, steps = kernels.integrate(
                    self.y, t0, t_seg, stops, record, h_max, Bre, Bim, om, self.Jinv, self.c_m, self.w,
                    self.tail, self.lam, out_y, out_N, k_out, self.eff, *tab, *case, pos, budget)
            self.steps += steps
            if pos[0] >= n:
                break
            self._tune_call(time.perf_counter() - w0, steps)
            t0 = float(pos[2])
        self.phase = np.mod(self.phase + self.rate * (t_end - self.t), 2 * math.pi)
        self.t = t_end
        self._seg_t_end = t_end
        return k_out

    def _tune_call(self, wall: float, steps: int) -> None:
        """Tune the steps of the next stepper calls after a call cut at ``self.call_steps`` that took ``wall`` s:
        towards :data:`CALL_WALL` s a call (double where it took less than a quarter of it, in proportion where it
        took more; the first call of a process also compiles the stepper), within :data:`CALL_STEPS`."""
        if steps < self.call_steps:
            return
        if wall < 0.25 * CALL_WALL:
            n = 2 * self.call_steps
        elif wall > CALL_WALL:
            n = int(self.call_steps * 0.5 * CALL_WALL / wall)
        else:
            return
        self.call_steps = min(max(n, CALL_STEPS[1]), CALL_STEPS[2])

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
        if lead is not None and math.isfinite(h_max):
            h_max = min(h_max, SHADOW_RATIO[method] * self.lead_gap)
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
        eff = self.eff if self.eff[effects.ON] != 0.0 else None  # (None: as the frozen / quasi-static flow record)
        kernels.record_sample(0.0, self.y, Bre, Bim, om, self.Jinv, self.c_m, self.w, self.tail, self.tau.size,
                              eff, np.empty(om.size), np.empty(om.size), F, np.zeros(25),
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


