"""The run's error estimate: the shadow run and the error control (:class:`ErrorEstimator`).

A shadow :class:`~gyro_sim.engine.simulator.Simulator` runs alongside the run (the same scene and commands, steps
``SHADOW_RATIO`` times longer) and stops where the run's dynamics change (a command that changes a stator), at the
error control's check instants and at the end; there the error control
(:class:`gyro_sim.scenes.step_control.ErrorControl`) compares the two, estimates the error and corrects the run's
step (``step_div``). Over the output samples it sums what the modes' and round-off's errors grow with (∫|N| dt,
∫ | |Ω| − |Ω0| | dt, the phase turned). :meth:`ErrorEstimator.error_estimate` gives the run's estimate
(:class:`gyro_sim.scenes.step_control.ErrorEstimate`): the steps' (the shadow's Richardson difference, else the plan's
model), the eddy modes' truncation, the averaged models' O(ε) and the phases' round-off.

The run loop (:class:`gyro_sim.engine.runner.Runner`) calls it: :meth:`~ErrorEstimator.set_stators`
where commands are applied, :meth:`~ErrorEstimator.follow` after each break, :meth:`~ErrorEstimator.accumulate` with
each break's sound samples, :meth:`~ErrorEstimator.hold_shadow` / :meth:`~ErrorEstimator.resync_shadow` around a
stretch the run takes otherwise (an averaged model: gyro_sim.engine.fidelity), and
:meth:`~ErrorEstimator.error_estimate` for the result; the compiled tick loop (gyro_sim.engine.ticks) follows through
many breaks in one call and counts them with :meth:`~ErrorEstimator.count_stretch`. It is handed the run's
simulator and its breaks; it never reaches up into the Runner.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Optional

import numpy as np

from gyro_sim.compiled import effects
from gyro_sim.engine.model import AVERAGED_ERROR
from gyro_sim.scenes.scene import sorted_union
from gyro_sim.physics.frames import norm3
from gyro_sim.scenes.accuracy import (COARSE_ORDER, FINER, FINER_TAU, R_MEASURABLE, RATE_KNOB, SHADOW_RATIO, SPT_MIN,
                                      STIFF, ErrorControl, ErrorEstimate)
from gyro_sim.scenes.scene import Scene
from gyro_sim.scenes.tolerance import has_symmetry_axis, phase_tolerance

if TYPE_CHECKING:
    from gyro_sim.engine.simulator import Simulator

#: unit round-off of a double (the phases' floor: ErrorEstimate.round_off)
ROUND_OFF = 2.0 ** -52
#: more output samples than this in one call: ErrorEstimator.accumulate works on arrays (the same bits)
VECTOR_SAMPLES = 32


class ErrorEstimator:
    """The error control of one run of ``sim`` (the run's :class:`Simulator`) over ``T`` s, planned for ``horizon``
    s: its :attr:`control` (:class:`ErrorControl`), its :attr:`shadow` (a follower of ``sim``; None without
    ``estimate``: the plan's model is then the estimate) and the sums over the output samples. The check instants
    (:attr:`_checks`, at fixed fractions of the horizon) must be breaks of the run; :meth:`set_breaks` hands over the
    run's breaks once it has them."""

    def __init__(self, sim: Simulator, scene: Scene, T: float, horizon: float, estimate: bool):
        self.sim, self.scene, self.T = sim, scene, T
        # the error control and its shadow run (gyro_sim/scenes/accuracy.py); checks at fixed fractions of the horizon
        plan = self.sim.step_size.step_plan
        self.control = ErrorControl(plan, self.sim.attitude, horizon, adapt=not plan.explicit and estimate,
                                    J_min=float(np.min(self.sim.terms.J)), L_bound=self.sim.step_size.L_bound,
                                    axis=self.sim.terms.sym_axis, accuracy=scene.accuracy)
        self.shadow: Optional[Simulator] = None
        if estimate:
            self.shadow = self.sim.follower()
        self._checks = self.control.checks[self.control.checks < T] if estimate else np.zeros(0)
        self._ck = 0  # the next check
        self._at_check = (self.sim.y[0:3].copy(), 0.0, 0, 0)  # (L, t, steps, shadow steps) at the previous check
        self._steps_seen = 0
        self._from_change = False  # whether the shadow's last stop was a command change (sync_shadow)
        self._impulse = 0.0  # ∫|N| dt over the output samples (N·m·s): the modes' error of L
        self._L_seen = sim.y[0:3].copy()  # L at the last output sample (N·m·s)
        self._spin_dev = 0.0  # ∫ | |Ω| − |Ω0| | dt (rad): the modes' error of the spin phase
        self._turned = 0.0  # ∫ |Ω| dt over the output samples (rad, |Ω| ≤ |L|/J_min): the phase the rotor turns
        self._last_t = 0.0
        self._om0 = float(np.linalg.norm(self.sim.y[0:3])) * float(np.max(self.sim.terms.Jinv))
        self.averaged_eps: list = []  # the averaged models' ε of each stretch (fidelity.py)
        # the shadow stops only where the dynamics change (a command that changes a stator: set_stators) and at
        # the checks and the end: between, its steps are SHADOW_RATIO times the run's, whatever the ticks and
        # samples that stop the run (a controller that re-sends the same command every tick leaves the shadow
        # free to step over its ticks: their Richardson difference then measures a run whose steps are as long
        # as the ticks). With an effect on (its rates change in time, the plan is made afresh at every break) the
        # shadow follows through every break of every run, as the run does.
        self._lazy = self.sim.terms.eff[effects.ON] == 0.0
        self.breaks = self._common = np.zeros(0)

    def set_breaks(self, t_out: np.ndarray, breaks: np.ndarray, common: np.ndarray) -> None:
        """The run's output instants ``t_out``, its ``breaks`` and those of every run, samples or not (``common``:
        where the shadow follows, :meth:`follow`), all s, sorted."""
        self.breaks, self._common = breaks, common
        if self.shadow is not None:
            stops = sorted_union(t_out, self.breaks, np.zeros(1))
            # (its step at most SHADOW_RATIO times the run's longest: the run's steps end at its stops)
            self.shadow.lead_gap = float(np.max(np.diff(stops))) if stops.size > 1 else math.inf

    def set_stators(self, by_index: dict) -> None:
        """The run's commands ``{stator index: (current A | None, rate rad/s | None)}``, applied now (the run's
        :meth:`Simulator.set_stators` has passed them), for the shadow too (which first reaches the present time where
        they change what a stator does)."""
        if self.shadow is not None:
            if self._lazy and _changes(self.shadow, by_index):
                self.sync_shadow(change=True)  # (the shadow reaches the change before it takes it)
            self.shadow._set_checked(by_index)  # (checked by the run's set_stators: the same limits)

    def accumulate(self, sel: np.ndarray, Ln: "np.ndarray | list", N_rows: np.ndarray, L_rows: np.ndarray) -> None:
        """∫|N| dt and ∫ | |Ω| − |Ω0| | dt (the modes' error bound, :meth:`error_estimate`) and the phase turned
        over new sound output samples: their times ``sel`` (s), |L| ``Ln`` (N m s; an array or a list), torques
        ``N_rows`` (N m) and kinetic moments ``L_rows`` (N m s, inertial frame)."""
        # (sequential sums in time order, sample by sample: the same bits whether samples are breaks or not; scalar
        # code for a few samples a call, the same operations on arrays for many: a long run's chunks)
        if sel.size > VECTOR_SAMPLES:
            self._accumulate_arrays(sel, np.asarray(Ln, dtype=float), N_rows, L_rows)
            return
        ts, Ls = sel.tolist(), (Ln.tolist() if isinstance(Ln, np.ndarray) else Ln)
        self.control.note_L(max(Ls))
        jmax = self.sim.terms.Jinv_max
        prev, turned = self._last_t, self._turned
        if self.sim.mode_plan.kind in (None, "thin_shell"):  # no truncation error to weigh (ModePlan.error_at: 0)
            for t, L in zip(ts, Ls, strict=True):
                turned += L * jmax * (t - prev)
                prev = t
        else:
            N = np.linalg.norm(N_rows, axis=1).tolist()
            # (over a sample interval ∫|N| dt ≥ |ΔL|: a torque that peaks between the samples, a field's switch-on,
            # counts)
            dL = np.linalg.norm(np.diff(np.vstack([self._L_seen, L_rows]), axis=0), axis=1).tolist()
            self._L_seen = L_rows[-1].copy()
            imp, dev, om0 = self._impulse, self._spin_dev, self._om0
            for t, L, Nk, dLk in zip(ts, Ls, N, dL, strict=True):
                dt, om = t - prev, L * jmax
                turned += om * dt
                imp += max(Nk * dt, dLk)
                dev += abs(om - om0) * dt
                prev = t
            self._impulse, self._spin_dev = imp, dev
        self._turned, self._last_t = turned, prev

    def _accumulate_arrays(self, sel: np.ndarray, Ln: np.ndarray, N_rows: np.ndarray, L_rows: np.ndarray) -> None:
        """:meth:`accumulate` on arrays: each term as the scalar code computes it (the same IEEE operations in the
        same order) and summed in time order (``np.add.accumulate``, sequential), so the sums' bits do not depend
        on how the samples come in chunks."""
        self.control.note_L(float(Ln.max()))
        jmax = self.sim.terms.Jinv_max
        dt = np.diff(sel, prepend=self._last_t)
        om = Ln * jmax
        self._turned = _running_sum(self._turned, om * dt)
        if self.sim.mode_plan.kind not in (None, "thin_shell"):
            N = np.linalg.norm(N_rows, axis=1)
            dL = np.linalg.norm(np.diff(np.vstack([self._L_seen, L_rows]), axis=0), axis=1)
            self._L_seen = L_rows[-1].copy()
            self._impulse = _running_sum(self._impulse, np.maximum(N * dt, dL))
            self._spin_dev = _running_sum(self._spin_dev, np.abs(om - self._om0) * dt)
        self._last_t = float(sel[-1])

    def follow(self, tb: float, sel: np.ndarray) -> None:
        """At a check instant and at the end: advance the shadow to ``tb`` (:meth:`sync_shadow`), compare and maybe
        change the step. With an effect on, the shadow follows through every break of every run (not an output
        sample made a break: the ROS node's samples are breaks, an in-process run's are not, and the shadow must
        take the same steps in both)."""
        sim, sh = self.sim, self.shadow
        assert sh is not None
        at_check = self._ck < self._checks.size and tb == self._checks[self._ck]
        if self._lazy:
            if not (at_check or tb >= self.T):
                return
        elif _holds(self.breaks, tb) and not _holds(self._common, tb):  # (an output sample made a break)
            return
        self.sync_shadow(tb)
        seg = sim._seg
        assert seg is not None
        method = seg[1][5]
        if at_check:
            self._ck += 1
            # |N| now and its mean since the previous check; whether the shadow's steps were longer there
            # (from the states at the checks alone: the same in every run, whatever its samples)
            n_now = norm3(sim.torque()) if not seg[1][4] else 0.0
            L0, t0, st0, sst0 = self._at_check
            n_mean = norm3(sim.y[0:3] - L0) / (tb - t0) if tb > t0 else n_now
            meas = sim.steps - st0 >= R_MEASURABLE * (sh.steps - sst0)
            self._at_check = (sim.y[0:3].copy(), tb, sim.steps, sh.steps)
            f = self.control.check(tb, sim, sh, method, n_now, n_mean, meas, turned=self._turned)
            if f is not None:
                sim.step_div *= f
            if f is not None or method in RATE_KNOB:  # (their step is J Ω / N of the state now: re-planned here)
                sim.replan()
                sh.replan()

    def sync_shadow(self, t: Optional[float] = None, change: bool = False) -> None:
        """Advance the shadow to ``t`` (default: the run's time) and count the stretch's steps, run's and
        shadow's, for the error control (its Richardson denominator). The shadow's stops are where this is called:
        at the checks and the end, where a command changes a stator (``change``) and before an averaged stretch."""
        sim, sh = self.sim, self.shadow
        t = sim.t if t is None else t
        if sh is None or not sh.t < t or sim._seg is None:
            return
        s0 = sh.steps
        # where a command change cuts the shadow's steps as the run's (its stretch no longer than R_MEASURABLE of the
        # run's steps: commands closer than the step, e.g. every 0.5 ms), their difference would say nothing: the
        # shadow follows the stretch with steps FINER times shorter than the run's there (the run's longest step is at
        # least the stretch over its steps), and the difference is the run's error (ErrorControl.denom). (Not where a
        # check cuts it: the early checks, T/4096 on, cut the run's first steps short, whose error is small beside
        # that of whole steps; a run whose steps are all cut so is cut by its commands.)
        k, span = sim.steps - self._steps_seen, t - sh.t
        h = sh._segment()[6]
        finer = 0.0  # (> 0: the shadow follows finer; the run's steps there over its plan's, what they weigh)
        ratio = FINER
        # (a stretch from a command change to a check is cut by the commands as much: followed finer too; one from
        # the start or from a check to a check is not)
        cut = change or self._from_change
        self._from_change = change
        if cut and math.isfinite(h) and h > 0 and 0 < k < R_MEASURABLE * math.ceil(span / h):
            h_run = sim._seg[1][6]
            finer = min(span / k / h_run, 1.0) if math.isfinite(h_run) and h_run > 0 else 1.0
            # (steps no longer than FINER_TAU τ_min either: across a field switch the run's longer steps span the
            # modes' transient, where the error is not a power of the step)
            tau = sim.tau_min
            if math.isfinite(tau) and tau > 0:
                ratio = max(FINER, span / k / (FINER_TAU * tau))
            gap, sh.lead_gap = sh.lead_gap, span / (k * ratio * SHADOW_RATIO[sh._segment()[5]])
            sh.replan()
        try:
            sh.advance(t)
        finally:
            if finer > 0:
                sh.lead_gap = gap
                sh.replan()
        self.count_stretch(sh.steps - s0, finer, ratio)

    def count_stretch(self, shadow_steps: int, finer: float = 0.0, ratio: float = FINER) -> None:
        """Count the stretch the shadow has just followed (``shadow_steps`` of its steps, the run's since the last
        count; ``finer`` > 0: its steps ``ratio`` (FINER or more) times shorter than the run's, the run's steps that
        fraction of its plan's, ErrorControl.note_method) for the error control's Richardson
        denominator, under the run's present segment's stepper."""
        sim = self.sim
        assert sim._seg is not None  # (it has advanced)
        _, _, _, _, free, method, h = sim._seg[1]
        # (the shadow below SPT_MIN steps a turn: its knob's, ErrorControl.coarsest)
        coarse = (method in COARSE_ORDER and not free
                  and sim.step_plan.knob(method) * sim.step_div < SHADOW_RATIO[method] * SPT_MIN[method])
        self.control.note_method(method, sim.steps - self._steps_seen, shadow_steps,
                                 exact=free and sim.terms.free_axis != -1, stiff=h > sim.tau_min, finer=finer,
                                 finer_ratio=ratio, coarse=coarse)
        self._steps_seen = sim.steps

    def hold_shadow(self) -> None:
        """An averaged stretch starts (gyro_sim.engine.fidelity): the shadow reaches the run's time and the two are
        compared there, the last time before the run's state is set from outside (:meth:`resync_shadow`)."""
        if self.shadow is None:
            return
        self.sync_shadow()
        if self.shadow.t == self.sim.t:  # (both at one instant: the differences are errors)
            self.control.measure(self.sim, self.shadow)

    def resync_shadow(self) -> None:
        """The run's state was set from outside (a fidelity hand-over, after :meth:`hold_shadow`): keep the errors
        so far and start the shadow, and the error control's growth, afresh from the run's state and time; the next
        check is the first after it (the error control waited for one inside the stretch to the run's end). (It
        compared the run at the stretch's end with the shadow at its start: the default scene under ``auto``, averaged
        from 6.4 s to its end, reported the spin-up over those 54 s as the steps' error, L 0.88.)"""
        if self.shadow is None:
            return
        sim, sh = self.sim, self.shadow
        self.control.bank(sim.t)
        self._at_check = (sim.y[0:3].copy(), sim.t, sim.steps, sh.steps)
        # (the check instants the stretch passed are not breaks the run reaches: its next check is the first after,
        # past round-off as the runner's next break is: fidelity._jump)
        self._ck = int(np.searchsorted(self._checks, sim.t + 1e-12 * max(1.0, sim.t), side="right"))
        sh.y[:] = sim.y
        sh.t, sh.phase, sh.current, sh.rate = sim.t, sim.phase.copy(), sim.current.copy(), sim.rate.copy()
        sh._nu_max = sim._nu_max
        sh.replan()

    def error_estimate(self) -> ErrorEstimate:
        """The run's estimated error so far (over the whole duration once it is done): the steps' (from the shadow,
        else the plan's model), the eddy modes' truncation at the largest slip met, the averaged models' O(ε)."""
        sim, acc = self.sim, self.scene.accuracy
        ctl = self.control
        L_max = max(ctl.L_max, norm3(sim.y[0:3]), 1e-300)
        if self.shadow is not None:
            if self.shadow.t == sim.t:
                ctl.measure(sim, self.shadow)
            # (else a run stopped between the shadow's stops: its errors as of the last; not caught up, which may
            # take as long as the run took since, e.g. after a signal)
            sL, sq, sp = ctl.estimate()
            how = "richardson"
            # steppers whose stretches the shadow could not measure (its steps no longer than the run's: stops
            # closer than the step): the plan's model at the knob they ran
            for m, k in ctl.weights.items():
                if not k or k >= R_MEASURABLE * ctl.shadow_steps.get(m, 0):
                    continue  # (measured)
                m = "etdrk4" if m == STIFF else m
                knob = (sim.step_plan.knob(m) / sim.step_div if m in RATE_KNOB
                        else sim.step_plan.knob(m) * sim.step_div)
                pL, pq = sim.step_plan.predicted(m, knob)
                sL, sq, sp, how = sL + pL, sq + pq, sp + pq, "richardson+model"
        else:
            used = sorted(sim.step_size.methods_used or {"free"})
            pred = [sim.step_plan.predicted(m) for m in used if m != "free" or sim.terms.free_axis == -1]
            sL = max([p[0] for p in pred] + [0.0])
            sq = sp = max([p[1] for p in pred] + [0.0])
            how = "model"
        e_g, e_im = sim.mode_plan.error_at(max(sim.slip_met, 0.0))
        mL = max(e_g, e_im) * self._impulse / L_max
        mq = e_im * self._spin_dev  # (a torque error turns the spin and precession rates: phases, directions)
        kL, kq = sim.mode_plan.step_error(sim.slip_met, sim.field_steps, sim.t, sim.terms.c_m, float(np.min(sim.J)))
        # (the field steps' transients in the modes left out: an impulse, which tilts L and turns the spin rate)
        mL, mp, mq = mL + kL / L_max, mq + kq, mq + kL / L_max
        aL = 0.0
        if self.averaged_eps:  # (only a hybrid run has averaged stretches: gyro_sim.fidelity imports SciPy's solvers)
            aL = AVERAGED_ERROR * max(self.averaged_eps)
        # (relative to the true largest |L|, which may be the run's less its error: e / (1 − e) of it)
        k = 1.0 / (1.0 - (sL + mL + aL)) if sL + mL + aL < 0.5 else 1.0
        sL, mL, aL = k * sL, k * mL, k * aL
        att = sim.attitude and not self.averaged_eps
        # round-off: each step's phase update errs by ~u of the angle and of the unit quaternion, and the
        # conserved |L| and energy random-walk by u √n of themselves, which turns the phases' rates
        n = max(sim.steps, 1)
        ro = ROUND_OFF * (self._turned * (1.0 + math.sqrt(n)) + n) if att else 0.0
        sym = has_symmetry_axis(sim.J)
        phase_tol = phase_tolerance(acc, 1.0, self._turned) if sym else math.nan
        return ErrorEstimate(L=sL + mL + aL, attitude=(sq + mq + ro) if att else math.nan, steps_L=sL,
                             steps_attitude=sq if att else math.nan, modes_L=mL, modes_attitude=mq if att else math.nan,
                             averaged_L=aL, steps_method=how, rtol=acc.rtol,
                             atol=math.nan if acc.attitude is None else acc.attitude,
                             phase=(sp + mp + ro) if att and sym else math.nan,
                             steps_phase=sp if att and sym else math.nan,
                             modes_phase=mp if att and sym else math.nan,
                             phase_tol=phase_tol if att else math.nan, round_off=ro)


def _running_sum(start: float, terms: np.ndarray) -> float:
    """``start`` plus ``terms`` added one by one in order (the bits of a Python loop ``start += term``)."""
    return float(np.add.accumulate(np.concatenate(([start], terms)))[-1])


def _holds(times: np.ndarray, t: float) -> bool:
    """Whether sorted ``times`` hold ``t``."""
    i = int(np.searchsorted(times, t))
    return i < times.size and times[i] == t


def _changes(sim: Simulator, commands: dict) -> bool:
    """Whether ``{stator index: (current A | None, rate rad/s | None)}`` changes what a stator of ``sim`` does."""
    return any(c is not None and c != sim.current[k] or r is not None and r != sim.rate[k]
               for k, (c, r) in commands.items())
