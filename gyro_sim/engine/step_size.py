"""The controller of the step (diffrax's ``_step_size_controller``): which stepper a command segment takes and its
largest step, from the run's accuracy plan.

The knobs come from the scene's tolerance (:func:`gyro_sim.scenes.step_control.step_plan`: steps per turn of the
fastest rotation for lawson8, ETDRK4 and the free stepper, the relative rate change a frozen-flow or quasi-static
flow step may make); :class:`StepSize` turns them into a step for the state a segment starts from (the fastest rate
it can meet, the torque's time scale), chooses the stepper where the scene says ``auto``, divides the step by the
error control's factor (``step_div``: :class:`gyro_sim.scenes.step_control.ErrorControl` measures the error at its
checks and sets it; the runner applies it) and makes a shadow's step ``SHADOW_RATIO`` times its leader's. It also
predicts a plan's steps (the step budget, :mod:`gyro_sim.engine.budget`) and warns where a plan cannot hold the
tolerance.

It reads the model (:class:`gyro_sim.engine.terms.Terms`) and the state it is given (:class:`State`); it holds no
state of the run but its own notes (the steppers used, the warnings given, the slip met).
"""
from __future__ import annotations

import copy
import math
from typing import NamedTuple, Optional

import numpy as np

from gyro_sim.compiled import effects, frozen_flow, qs_flow
from gyro_sim.engine.model import frozen_flow_cost, lawson8_cost
from gyro_sim.physics.frames import _column, norm3
from gyro_sim.scenes.accuracy import (PHASE_REL_MIN, RATE_KNOB, SHADOW_RATIO, STEPS_WARN, auto_plan, field_rates,
                                      is_legacy, step_plan)
from gyro_sim.scenes.accuracy import warn as accuracy_warning
from gyro_sim.scenes.tolerance import has_symmetry_axis

__all__ = ["State", "Lead", "StepSize"]

_ZERO3 = np.zeros(3)  # (no axis: frozen_flow.torque_scale's; read only)


class State(NamedTuple):
    """The run's state a step is planned from: time ``t`` (s), ``y`` (L, q, eddy modes, effects' states), the
    stators' ``current`` (A), ``rate`` and ``phase`` (rad/s, rad) and ``nu_max`` (rad/s, the fastest field rate
    commanded so far). Read only."""
    t: float
    y: np.ndarray
    current: np.ndarray
    rate: np.ndarray
    phase: np.ndarray
    nu_max: float


class Lead(NamedTuple):
    """What a shadow run follows of its leader: the stepper of the leader's segment (None before it has one), its
    ``step_div`` and ``gap`` (s, its longest span between stops)."""
    method: Optional[str]
    step_div: float
    gap: float


class StepSize:
    """The step plan of one simulator of ``scene`` (model ``terms``) over ``horizon`` s, planned for the fastest
    spin ``om_reach`` (rad/s) the run can reach from ``y0``; ``mode_plan``: its eddy modes' plan (the slip they
    were chosen for); ``quiet``: no warnings (a shadow run).

    Attributes: ``step_plan`` (the knobs in force: the scene's explicit ones win), ``auto_plan`` (the accuracy's
    own knobs: what ``auto`` chooses by), ``rates`` ((fastest rate resolved, free rotor's body-frame rate), rad/s),
    ``L_bound`` (N m s, the largest |L| the run can reach), ``methods_used``, ``slip_met`` (rad/s)."""

    def __init__(self, scene, terms, attitude: bool, horizon: float, om_reach: float, mode_plan, y0: np.ndarray,
                 quiet: bool = False):
        self.scene, self.terms, self.attitude, self.horizon, self.quiet = scene, terms, attitude, horizon, quiet
        self.mode_plan = mode_plan
        self.slip_met = 0.0  # largest slip bound met at a step plan (rad/s): the modes' error is judged there
        self._slip_warned = False
        self.methods_used: set = set()
        self._knob_warned: set = set()
        self._tt: Optional[tuple] = None  # (torque_time: the last one, with its key)
        self._qs: Optional[bool] = None  # (qs_applies: the scene's part)
        self._ea = np.empty(3)  # (local_torque_scale's symmetry axis, case frame)
        # --- the step knobs for the scene's accuracy over the horizon (gyro_sim/scenes/accuracy.py): turns of the
        # fastest rotation the run can meet (spin it can reach, field rates, an effect's rate) and of the free body
        # motion
        J, Jinv = terms.J, terms.Jinv
        Lmag0 = float(np.linalg.norm(y0[0:3]))
        om_plan = max(om_reach, field_rates(scene), terms.effect_rate(0.0, y0))
        L_bound = Lmag0 if om_reach <= Lmag0 * float(np.max(Jinv)) * (1 + 1e-12) else float(np.max(J)) * om_reach
        self.L_bound = L_bound
        om_free = L_bound * float(np.max(np.abs(Jinv - terms.inv_ref))) if terms.free_axis == -1 else 0.0
        self.rates = (om_plan, om_free)  # (plan_for: the plan at other tolerances)
        self.step_plan = step_plan(scene, self.horizon, self.attitude, om_plan, om_free)
        self.auto_plan = auto_plan(self.step_plan, scene)

    def copy(self, terms, quiet: bool) -> "StepSize":
        """The same plan for another simulator of the same run (a shadow) with model ``terms``: its own notes
        (steppers used, slip met, warnings, the kept torque time), ``quiet`` or not."""
        other = copy.copy(self)
        other.terms, other.quiet = terms, quiet
        other.slip_met, other._slip_warned, other.methods_used, other._knob_warned = 0.0, False, set(), set()
        other._tt = None
        other._ea = np.empty(3)
        return other

    # --- a segment's stepper and step ----------------------------------------------------------------
    def plan(self, free: bool, st: State, step_div: float = 1.0, lead: Optional[Lead] = None) -> tuple[str, float]:
        """(stepper, largest step s) of a command segment starting at state ``st`` (:meth:`choose`), the step
        divided by ``step_div`` (the error control's); a shadow (``lead``: its leader's) takes its leader's stepper
        and SHADOW_RATIO times its leader's step, within SHADOW_RATIO times the leader's longest span."""
        if lead is not None and lead.method is not None:
            # a shadow: the leader's stepper (decided on its state), at its own step from its state (what choose
            # gives for that stepper, without weighing the others: the frozen-flow step's torque scale)
            method, h_max = lead.method, self.h_for(lead.method, st)
            self.methods_used.add(method)
        else:
            method, h_max = self.choose(free, st)
        if lead is not None:  # a shadow: SHADOW_RATIO times its leader's step
            div = lead.step_div / SHADOW_RATIO[method]
        else:
            div = step_div
        if div != 1.0 and math.isfinite(h_max):
            h_max /= div
            if self.scene.integrator.max_step is not None:
                h_max = min(h_max, self.scene.integrator.max_step)
        if lead is not None and math.isfinite(h_max):
            h_max = min(h_max, SHADOW_RATIO[method] * lead.gap)
        return method, h_max

    def choose(self, free: bool, st: State) -> tuple[str, float]:
        """(stepper, largest step s) from state ``st`` on. With fields: ``lawson8`` (8th-order Lawson–Dormand–Prince,
        RKMK attitude) unless an eddy mode is stiff at the lawson8 step (h > 2 τ_n: the integrating
        factor then loses the order), else ``etdrk4``; ``auto`` takes ``frozen_flow`` instead where it
        applies (axisymmetric rotor, no effects) and its step is long enough to be cheaper
        (:func:`gyro_sim.engine.model.frozen_flow_cost`: its cost grows with the field phasors); ``free`` for the
        torque-free stepper."""
        terms = self.terms
        if free:
            self._check_knob("free")
            return "free", self.max_step(True, "free", st)
        m = self.scene.integrator.method
        if m == "frozen_flow":
            self._check_knob(m)
            return m, self.frozen_flow_step(st)
        if m == "qs_flow":
            self._check_knob(m)
            return m, self.frozen_flow_step(st, self.step_plan.qs_rate_change)
        if m == "auto":
            m, h = "lawson8", self.max_step(False, "lawson8", st)
            held = False
            if h > 2.0 * terms.tau_min:
                # a mode is stiff at lawson8's step: ETDRK4 at its own step, or lawson8 held at τ_min (where its
                # order holds, its shadow's step within 2 τ_min) where that costs less (lawson8_cost)
                h_etd = self.max_step(False, "etdrk4", st)
                if terms.tau_min >= lawson8_cost(terms.tau.size) * h_etd:
                    h, held = terms.tau_min, True
                else:
                    m, h = "etdrk4", h_etd
            if terms.sym_axis >= 0 and terms.eff[effects.ON] == 0.0:
                # decided at both steppers' settings for the scene's accuracy (the choice follows the physics
                # and the tolerance; the scene's explicit knobs then set the chosen stepper's accuracy)
                ap = self.auto_plan
                h_ff = self.frozen_flow_step(st, ap.rate_change)
                h_def = self.max_step(False, m, st, ap.steps_per_turn[m])
                if held:
                    h_def = min(h_def, terms.tau_min)
                if h_ff >= frozen_flow_cost(terms.tau.size, self.phasor_count(st)) * h_def:
                    # the quasi-static model: the quasi-static flow step instead (gyro_sim/compiled/qs_flow.py)
                    m = "qs_flow" if self.qs_applies() else "frozen_flow"
                    self._check_knob(m)
                    return m, self.frozen_flow_step(st, self.step_plan.knob(m))
            self._check_knob(m)
            return m, h
        self._check_knob(m)
        return m, self.max_step(False, m, st)

    def phasor_count(self, st: State) -> int:
        """Field phasors of a segment from state ``st`` (the stators with current, the general field's terms), at
        least one; one in the old defaults' runs (:func:`gyro_sim.scenes.tolerance.legacy`: their rule, which
        counted none)."""
        if is_legacy():
            return 1
        return max(1, sum(1 for c in st.current.tolist() if c > 0) + int(self.terms.field_om.size))

    def qs_applies(self) -> bool:
        """Whether ``auto`` takes the quasi-static flow step (gyro_sim/compiled/qs_flow.py) where it would take
        frozen_flow: on the quasi-static torque model (not in the old defaults' runs, gyro_sim.accuracy.legacy). Its
        step is as long (the same error model), costs a third (0.8 µs against 2.3 µs, one phasor), and its error
        measured no larger on every quasi-static scene (docs/numerics.md). Where frozen_flow does not pay, lawson8
        stays: its error is the predictable one (it resolves the field's ripple): on reorient_L qs_flow takes 403 699
        steps (2.6 s CPU) against lawson8's 10 319 (0.18 s), docs/accuracy.md."""
        if self._qs is None:  # (the scene's and the model's part: fixed over the run)
            self._qs = qs_flow.applies(self.scene, self.terms.J, self.terms.eff[effects.ON] != 0.0)
        return not is_legacy() and self._qs

    def h_for(self, method: str, st: State) -> float:
        """The largest step (s) of ``method`` from state ``st``, at the plan's knobs (lawson8 in auto mode: held at
        τ_min where a mode is stiff at its step, as :meth:`choose` does)."""
        if method == "free":
            return self.max_step(True, "free", st)
        if method in RATE_KNOB:
            return self.frozen_flow_step(st, self.step_plan.knob(method))
        h = self.max_step(False, method, st)
        tau_min = self.terms.tau_min
        if method == "lawson8" and self.scene.integrator.method == "auto" and h > 2.0 * tau_min:
            h = tau_min
        return h

    def max_step(self, free: bool, method: str, st: State, spt: Optional[int] = None) -> float:
        """Largest lawson8/etdrk4/free step (s) at ``spt`` steps per turn (default: the step plan's: the scene's
        knob, else chosen for its accuracy) of the fastest rotation, bounded by ``integrator.max_step``."""
        terms = self.terms
        spt = spt or self.step_plan.steps_per_turn[method]
        y = st.y
        L = math.sqrt(float(y[0]) ** 2 + float(y[1]) ** 2 + float(y[2]) ** 2)
        if free:
            if terms.free_axis != -1:
                h = math.inf  # the free step is exact
            else:
                rate = L * np.max(np.abs(terms.Jinv - terms.inv_ref))
                h = 2 * math.pi / (spt * rate) if rate > 0 else math.inf
        else:
            om = max(L * terms.Jinv_max, st.nu_max, terms.field_om_max, terms.effect_rate(st.t, y))
            h = 2 * math.pi / (spt * om) if om > 0 else math.inf
        if self.scene.integrator.max_step is not None:
            h = min(h, self.scene.integrator.max_step)
        return h

    def frozen_flow_step(self, st: State, eps: Optional[float] = None) -> float:
        """Largest frozen-flow step (s): the body rate may change by ``rate_change`` of the fastest rate Ω
        (spin or field) per step at the torque's scale N = c|B|²(½Σ|w_n| + T_tail(Ω + ν_max)), the largest
        |m||B| the conductor gives at a slip up to Ω + ν_max (J_min Ω ε / N); ε = ``eps``, else the scene's
        ``integrator.rate_change``, else the one chosen for the scene's accuracy (``step_plan``)."""
        eps = eps or self.step_plan.rate_change
        h = eps * self.torque_time(st)
        if self.scene.integrator.max_step is not None:
            h = min(h, self.scene.integrator.max_step)
        return h

    def local_torque_scale(self, ax: int, st: State) -> float:
        """Mean torque scale (N m) at the present slips (:func:`gyro_sim.frozen_flow.torque_scale`) for an
        axisymmetric or isotropic rotor with symmetry axis ``ax`` (:func:`gyro_sim.frozen_flow.supported`)."""
        terms, y = self.terms, st.y
        Jt, Ja = float(terms.J[(ax + 1) % 3]), float(terms.J[ax])
        # (the axis in the case frame: quat_to_matrix's column in scalar code, the same bits)
        e_a: Optional[np.ndarray] = None
        if self.attitude and Jt != Ja:
            w, x, yq, z = y[3:7].tolist()
            e_a = self._ea  # (this simulator's scratch: read by the call below only)
            e_a[0], e_a[1], e_a[2] = _column(w, x, yq, z, ax)
        Bre, Bim, om = terms.phasors(st.t, st.current, st.rate, st.phase)
        if not om.size:  # (no field: frozen_flow.torque_scale's answer)
            return math.inf
        # (torque_scale's compiled part on the arguments it would make: the phasors and the state are float64 arrays,
        # |w| kept in Terms; the same bits without its conversions at every segment)
        return frozen_flow._torque_scale(Bre, Bim, om, y[0:3], Jt, Ja, e_a if e_a is not None else _ZERO3,
                                         e_a is not None, float(terms.c_m), terms.w_abs, terms.tau, float(terms.tail))

    def torque_time(self, st: State) -> float:
        """J_min Ω / N (s): the time the torque's scale N takes to change the fastest rate Ω by itself (inf without
        torque or rate). N: the mean torque at the present slips (:meth:`local_torque_scale`), no larger than the
        bound c|B|²(½Σ|w_n| + T_tail(Ω + ν_max)) at the largest slip and no smaller than LOCAL_SCALE_MIN of it.
        Kept while the commands, the rates met, L and q are the same (a step plan asks for it for several knobs)."""
        terms, y = self.terms, st.y
        # (q only where it is integrated: without attitude it is NaN, and NaN != NaN would never find the kept one)
        yl = y[0:7 if self.attitude else 3].tolist()
        key = (st.current.tobytes(), st.rate.tobytes(), st.nu_max, *yl)
        kept = self._tt
        if kept is not None and kept[0] == key:
            return kept[1]
        # |B| summed over the phasors: √2 b_k I_k a stator (its Bre, Bim are b_k I_k times two orthonormal vectors),
        # |B_p| a general field term (scalar code: this is asked once per command segment; the model's constants
        # made once, Terms)
        B = sum(sb * c for sb, c in zip(terms.b_sqrt2, st.current.tolist(), strict=True) if c > 0)  # ((√2 b) I)
        B += terms.field_B_norm if terms.field_B.size else 0.0
        om = max(math.sqrt(yl[0] ** 2 + yl[1] ** 2 + yl[2] ** 2) * terms.Jinv_max, st.nu_max, terms.field_om_absmax)
        N = terms.c_m * B * B * (terms.w_half + terms.tail * (om + st.nu_max))
        ax = terms.sym_axis
        if N > 0 and terms.w.size and ax >= 0:
            # the mean torque at the present slips, no larger than the bound: a spin-up's step grows as its slip falls
            # (the eddy-mode models; qs_flow's plan and auto's choice of it were measured at the bound: on
            # nutation_slow the local scale made auto take qs_flow, whose ticks are not compiled, at 1.2x the cost)
            N = min(N, max(self.local_torque_scale(ax, st), frozen_flow.LOCAL_SCALE_MIN * N))
        tt = terms.J_min * om / N if N > 0 and om > 0 else math.inf
        self._tt = (key, tt)
        return tt

    # --- the plan as a whole ------------------------------------------------------------------------------
    def planned_steps(self, st: State, plan=None) -> float:
        """The steps the run's plan predicts over its horizon (the accuracy's own knobs, :attr:`auto_plan`, or
        ``plan``: :meth:`plan_for`), from state ``st``: turns of the fastest rotation times lawson8's or ETDRK4's
        steps per turn, or the horizon over the frozen-flow step where that stepper applies, the fewest of them. An
        estimate made before any step (the error control then changes the step);
        :data:`gyro_sim.scenes.step_control.STEP_BUDGET` bounds it (:mod:`gyro_sim.engine.budget`)."""
        plan = self.auto_plan if plan is None else plan
        terms = self.terms
        steps = min(plan.turns * plan.steps_per_turn["lawson8"], plan.turns * plan.steps_per_turn["etdrk4"])
        if terms.sym_axis >= 0 and terms.eff[effects.ON] == 0.0 and terms.c_m > 0:
            steps = min(steps, self.horizon / self.frozen_flow_step(st, plan.rate_change))
        return float(steps)

    def plan_for(self, rtol: float, attitude: Optional[float], **accuracy):
        """The plan (as :attr:`auto_plan`: the accuracy's own knobs) this run would take at tolerances ``rtol`` and
        ``attitude`` (rad, None: none) instead of the scene's; for :meth:`planned_steps` (what to loosen)."""
        alt = self.scene.model_copy(update={"accuracy": self.scene.accuracy.model_copy(
            update={"rtol": rtol, "attitude": attitude, **accuracy})})
        return auto_plan(step_plan(alt, self.horizon, self.attitude, *self.rates), alt)

    # --- warnings ---------------------------------------------------------------------------------------
    def warn_plan(self, st: State) -> None:
        """Warn where the scene's attitude tolerance is below the floor a plan takes (PHASE_REL_MIN of the spin
        phase), and where the plan predicts a very long run (more than STEPS_WARN steps)."""
        om_plan = self.rates[0]
        acc, T = self.scene.accuracy, self.horizon
        floor = PHASE_REL_MIN * om_plan * T
        if self.attitude and acc.attitude is not None and acc.attitude < floor and not has_symmetry_axis(self.terms.J):
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
        plan = self.auto_plan
        steps = self.planned_steps(st)
        if steps > STEPS_WARN:
            accuracy_warning(
                f"scene {self.scene.name!r}: accuracy (rtol {acc.rtol:g}, attitude {acc.attitude} rad) over "
                f"{T:g} s needs about {steps:.2g} steps ({plan.turns:.3g} turns of the fastest rotation); a looser "
                f"accuracy runs faster")

    def _check_knob(self, method: str) -> None:
        """Warn once per stepper where the scene's explicit knob misses its accuracy by the error model
        (gyro_sim.accuracy.StepPlan.predicted); note the stepper as used (``methods_used``)."""
        self.methods_used.add(method)
        plan = self.step_plan
        knob = "rate_change" if method in RATE_KNOB else "steps_per_turn"
        if knob not in plan.explicit or method in self._knob_warned or self.quiet:
            return
        if method == "free" and self.terms.free_axis != -1:
            return  # exact steps
        self._knob_warned.add(method)
        eL, eq = plan.predicted(method)
        if eL > plan.tol_L or eq > plan.plan_q:
            want, val = self.auto_plan.knob(method), plan.knob(method)
            acc = self.scene.accuracy
            accuracy_warning(
                f"scene {self.scene.name!r}: integrator.{knob} = {val:g} cannot meet accuracy (rtol {acc.rtol:g}, "
                f"attitude {acc.attitude} rad) with {method} over {self.horizon:g} s by the error model: about "
                f"{eL:.2g} in L, {eq:.2g} rad in the attitude; {knob} = {want:g} would (leave it out to let the run "
                f"choose)")

    def check_slip(self, om: np.ndarray, st: State) -> None:
        """Note the slip bound of a new command segment (fastest field rate ``om`` + |Ω| now, rad/s) in ``slip_met``;
        warn once where it passes the slip the eddy modes were chosen for (a command or law beyond the scene's
        rates: gyro_sim.accuracy.mode_plan) and the modes then miss the tolerance."""
        slip = max(map(abs, om.tolist()), default=0.0) + norm3(st.y[0:3]) * self.terms.Jinv_max
        self.slip_met = max(self.slip_met, slip)
        mp = self.mode_plan
        if (self._slip_warned or self.quiet or mp.kind in (None, "thin_shell") or mp.n == 0
                or slip <= mp.slip * (1 + 1e-9)):
            return
        e_g, e_im = mp.error_at(slip)
        if e_g > mp.tol_g or e_im > mp.tol_im:
            self._slip_warned = True
            accuracy_warning(
                f"scene {self.scene.name!r}: at t = {st.t:.6g} s the slip reaches {slip:.4g} rad/s, beyond the "
                f"{mp.slip:.4g} rad/s the {mp.n} eddy modes were chosen for (a command or law faster than the "
                f"scene's rates): their truncation error there is {e_g:.2g} of ĝ, {e_im:.2g} of Im ĝ against "
                f"tolerances {mp.tol_g:.2g}, {mp.tol_im:.2g}; give the rate in the scene (a stator, command or law "
                f"parameter) or set modes")
