"""The :class:`Runner`: a :class:`~gyro_sim.engine.simulator.Simulator` advanced break by break (outputs, commands,
controller ticks, switching events) with its error control, collecting the samples of a run.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from gyro_sim.compiled import effects
from gyro_sim.compiled.compile_watch import CompileClock
from gyro_sim.engine.budget import check_budget, check_run_size
from gyro_sim.engine.model import AVERAGED_ERROR, body_rates, controller_period
from gyro_sim.engine.result import RunResult
from gyro_sim.engine.saving import output_times, run_result, sample_arrays
from gyro_sim.engine.simulator import Simulator
from gyro_sim.common.stamps import stamp_ns
from gyro_sim.physics.frames import symmetry_axis
from gyro_sim.scenes.accuracy import (FINER, R_MEASURABLE, RATE_KNOB, SHADOW_RATIO, STIFF, ErrorControl,
                                      ErrorEstimate, is_legacy)
from gyro_sim.scenes.limits import L_limit
from gyro_sim.scenes.scene import Scene, SceneError
from gyro_sim.scenes.tolerance import has_symmetry_axis, phase_tolerance

#: unit round-off of a double (the phases' floor: ErrorEstimate.round_off)
ROUND_OFF = 2.0 ** -52


class Runner:
    """Advances a :class:`Simulator` break by break over a scene's duration, collecting the outputs.

    Breaks are the output instants (unless ``sample_breaks`` is False), the scene's command instants and
    the controller ticks. At each
    break the scene's due commands are applied; at a controller tick the caller supplies the
    commands (in-process: the law; ROS node: the command message). The sample recorded at time t
    shows the state at t and the field that acted up to t. Used by :func:`run` and by the
    simulator node, so both produce the same numbers. ``attitude``: see :func:`integrates_attitude` (the
    ROS node passes True: it publishes /gyro/imu and /gyro/euler).

    Accuracy (gyro_sim/scenes/accuracy.py): the simulator's modes and step knobs are planned for the scene's
    ``accuracy`` over ``horizon`` s (default: the duration). With ``estimate`` (default) a shadow simulator runs
    alongside (same commands, same stops, longer steps) and the error control (:class:`gyro_sim.accuracy.
    ErrorControl`) compares the two at its check instants, which are breaks of every run (so the ROS node and
    an in-process run decide alike), estimates the error and corrects the step; :meth:`error_estimate` gives the
    run's estimate. ``estimate=False`` (a run that locates switching events: its bisection re-integrates stretches
    the shadow cannot follow) runs the plan alone and estimates by the plan's model.

    Budget: a run whose plan exceeds :data:`gyro_sim.scenes.step_control.STEP_BUDGET` steps is refused here, before
    any work, with a :class:`gyro_sim.scenes.step_control.StepBudgetError` (a SceneError) saying what to loosen;
    ``force`` runs it anyway (:mod:`gyro_sim.engine.budget`).
    """

    def __init__(self, scene: Scene, duration: Optional[float] = None, sample_breaks: bool = True,
                 attitude: Optional[bool] = None, control_period: Optional[float] = None,
                 buffer_rows: Optional[int] = None, horizon: Optional[float] = None,
                 estimate: Optional[bool] = None, force: bool = False):
        T = scene.duration if duration is None else float(duration)
        if T != scene.duration:  # (the scene's own was checked on loading)
            check_run_size(scene, T)  # the samples and the memory, before the plan's arithmetic meets T
        if control_period is not None and not (math.isfinite(control_period) and control_period > 0):
            raise SceneError(f"control_period = {control_period}: must be a finite number of seconds > 0")
        self.scene, self.T = scene, T
        # the accuracy plan is made for the run's duration (``horizon``: another, e.g. a re-run of an interrupted
        # bag planned for its whole duration)
        H = T if horizon is None else float(horizon)
        self.sim = Simulator(scene, attitude, horizon=H, warn_plan=False)
        # the step budget (gyro_sim/engine/budget.py): a plan beyond it is refused before any work, unless forced (in
        # one line: the plan's warnings follow once it has passed)
        self.period = control_period or controller_period(scene)
        if not force:
            check_budget(self.sim, T, self.period)
        if not is_legacy():
            self.sim.step_size.warn_plan(self.sim.state())
        # the error control and its shadow run (gyro_sim/scenes/accuracy.py); checks at fixed fractions of the horizon
        plan = self.sim.step_size.step_plan
        if estimate is None:  # (a law sampled at its switching events: no shadow; nor the old defaults' runs)
            estimate = (scene.controller is None or scene.controller.sampling != "events") and not is_legacy()
        self.control = ErrorControl(plan, self.sim.attitude, H, adapt=not plan.explicit and estimate,
                                    J_min=float(np.min(self.sim.terms.J)), L_bound=self.sim.step_size.L_bound,
                                    axis=symmetry_axis(self.sim.terms.J), accuracy=scene.accuracy)
        self.shadow = None
        if estimate:
            self.shadow = self.sim.follower()
        self._checks = self.control.checks[self.control.checks < T] if estimate else np.zeros(0)
        self._ck = 0  # the next check
        self._at_check = (self.sim.y[0:3].copy(), 0.0, 0, 0)  # (L, t, steps, shadow steps) at the previous check
        self._steps_seen = 0
        self._impulse = 0.0  # ∫|N| dt over the output samples (N·m·s): the modes' error of L
        self._L_seen = self.sim.y[0:3].copy()  # L at the last output sample (N·m·s)
        self._spin_dev = 0.0  # ∫ | |Ω| − |Ω0| | dt (rad): the modes' error of the spin phase
        self._turned = 0.0  # ∫ |Ω| dt over the output samples (rad, |Ω| ≤ |L|/J_min): the phase the rotor turns
        self._last_t = 0.0
        self._om0 = float(np.linalg.norm(self.sim.y[0:3])) * float(np.max(self.sim.terms.Jinv))
        self.averaged_eps: list = []  # the averaged models' ε of each stretch (fidelity.py)
        # ticks: the controller's (its period, else one per output sample); control_period sets them for any
        # scene (the ROS node: external commands are taken at ticks, also where the scene has no controller)
        # every controller tick is an output sample too: the controller (node) sees the published state
        self.t_out, self._ticks = t_out, ticks = output_times(scene, T, self.period)
        self._cmds = sorted((c for c in scene.commands if c.time < T), key=lambda c: c.time)
        fly = scene.effects.flywheel  # the kinks of its speed profile are breaks: steps never straddle one
        knots = {t for t in fly.profile.time if 0 < t < T} if fly is not None else set()
        # output samples are breaks where a caller acts on each (the ROS node publishes and paces); in-process
        # they are recorded inside one advance (the same bits: Simulator._segment)
        # (with an effect on the step plan is made afresh at every advance: the samples stay breaks)
        if self.sim.terms.eff[effects.ON] != 0.0:
            sample_breaks = True
        # (NumPy arrays, 8 bytes an instant: a long run's breaks are not a Python list of floats)
        # the breaks of every run, samples or not: where the shadow follows (Runner._follow)
        self._common = np.unique(np.concatenate([np.array([c.time for c in self._cmds], dtype=float), ticks,
                                                 np.array([T], dtype=float), np.array(sorted(knots), dtype=float),
                                                 self._checks]))
        self.breaks = np.unique(np.concatenate([t_out if sample_breaks else np.zeros(0), self._common]))
        # the shadow stops only where the dynamics change (a command that changes a stator: apply_commands) and at
        # the checks and the end: between, its steps are SHADOW_RATIO times the run's, whatever the ticks and
        # samples that stop the run (a controller that re-sends the same command every tick leaves the shadow
        # free to step over its ticks: their Richardson difference then measures a run whose steps are as long
        # as the ticks). With an effect on (its rates change in time, the plan is made afresh at every break) the
        # shadow follows through every break of every run, as the run does.
        self._lazy = self.sim.terms.eff[effects.ON] == 0.0
        if self.shadow is not None:
            stops = np.unique(np.concatenate([t_out, self.breaks, [0.0]]))
            # (its step at most SHADOW_RATIO times the run's longest: the run's steps end at its stops)
            self.shadow.lead_gap = float(np.max(np.diff(stops))) if stops.size > 1 else math.inf
        # output rows held in memory: all of them, or a buffer of ``buffer_rows`` that release() empties (a
        # streamed run: its rows go to a bag as they come, memory stays flat however long the run)
        if buffer_rows is not None and buffer_rows < 2:
            raise ValueError(f"buffer_rows = {buffer_rows}: must be at least 2")
        n = t_out.size if buffer_rows is None else min(t_out.size, int(buffer_rows))
        self._base = 0  # the output row (of the whole run) held in buffer row 0
        k = len(self.sim.terms.stator_names)
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
        # the run fails loudly where its state breaks (_check_samples): "failed: <what> at t = … s", else None
        self.failure: Optional[str] = None
        terms = self.sim.terms  # N m s (scenes/limits.py)
        self.L_sound = L_limit(scene, terms.max_rate, terms.effect_rate(self.sim.t, self.sim.y))

    # --- the loop, one break at a time ---------------------------------------------------------
    @property
    def done(self) -> bool:
        """The run reached its end, or failed (:attr:`failure`)."""
        return self.failure is not None or self._bi >= len(self.breaks) and self.row > 0

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
        if due:
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
        if sim.terms.eff[effects.ON] or not sim.attitude:
            omega_b = sim.body_rates(sim.t, sim.y)[0]
        else:
            omega_b = body_rates(sim.terms.J, L, q)[1]
        if not hasattr(self, "_axes"):
            self._axes = (tuple(sim.terms.stator_names), np.cross(sim.terms.e1, sim.terms.e2))
        return ControlInput(t=stamp_ns(sim.t) * 1e-9, L=L, q=q, omega_b=omega_b, stator_names=self._axes[0], stator_axes=self._axes[1])

    def apply_commands(self, commands: dict) -> None:
        """Apply ``{stator name: (current A, rate rad/s)}`` now (unknown names raise ValueError)."""
        for name in commands:
            if name not in self.sim.terms.stator_names:
                raise ValueError(f"unknown stator {name!r}; allowed: {self.sim.terms.stator_names}")
        by_index = {self.sim.terms.stator_names.index(n): c for n, c in commands.items()}
        self.sim.set_stators(by_index)
        if self.shadow is not None:
            if self._lazy and _changes(self.shadow, by_index):
                self.sync_shadow(change=True)  # (the shadow reaches the change before it takes it)
            self.shadow.set_stators(by_index)
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
        # the samples up to the break and within round-off past it (t_out is sorted)
        sel = t_out[row:max(row, int(np.searchsorted(t_out, tb + 1e-12 * max(1.0, tb), side="right")))]
        sim = self.sim
        t_seg, ph0, r0, c0 = sim.t, sim.phase.copy(), sim.rate.copy(), sim.current.copy()
        out = slice(row, row + sel.size)
        rows = self._buf(out)
        if rows.stop > self.out_y.shape[0]:
            raise RuntimeError(f"output buffer of {self.out_y.shape[0]} rows is full: release() the rows taken")
        with CompileClock() as clock:
            self.row = sim.advance(tb, sel, self.out_y, self.out_N, rows.start) + self._base
            self._accumulate(sel, rows)
            if self.shadow is not None and self.failure is None:
                self._follow(tb, sel)
        self.wall_time += clock.wall
        self.compile_time += clock.compile
        self.cur[rows] = c0
        self.rate[rows] = r0
        self.phase[rows] = np.mod(ph0 + r0 * (sel[:, None] - t_seg), 2 * math.pi)
        if self.failure is not None:
            return slice(out.start, self.row)  # (the samples before the failure)
        self.apply_scene_commands()
        return out

    # --- accuracy: the shadow run, the checks, the estimate ----------------------------------------
    def _follow(self, tb: float, sel: np.ndarray) -> None:
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
            n_now = _norm(sim.torque()) if not seg[1][4] else 0.0
            L0, t0, st0, sst0 = self._at_check
            n_mean = _norm(sim.y[0:3] - L0) / (tb - t0) if tb > t0 else n_now
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
        if change and math.isfinite(h) and h > 0 and 0 < k < R_MEASURABLE * math.ceil(span / h):
            h_run = sim._seg[1][6]
            finer = min(span / k / h_run, 1.0) if math.isfinite(h_run) and h_run > 0 else 1.0
            gap, sh.lead_gap = sh.lead_gap, span / (k * FINER * SHADOW_RATIO[sh._segment()[5]])
            sh.replan()
        try:
            sh.advance(t)
        finally:
            if finer > 0:
                sh.lead_gap = gap
                sh.replan()
        self.count_stretch(sh.steps - s0, finer)

    def count_stretch(self, shadow_steps: int, finer: float = 0.0) -> None:
        """Count the stretch the shadow has just followed (``shadow_steps`` of its steps, the run's since the last
        count; ``finer`` > 0: its steps FINER times shorter than the run's, the run's steps that fraction of its
        plan's, ErrorControl.note_method) for the error control's Richardson
        denominator, under the run's present segment's stepper."""
        sim = self.sim
        assert sim._seg is not None  # (it has advanced)
        _, _, _, _, free, method, h = sim._seg[1]
        self.control.note_method(method, sim.steps - self._steps_seen, shadow_steps,
                                 exact=free and sim.terms.free_axis != -1, stiff=h > sim.tau_min, finer=finer)
        self._steps_seen = sim.steps

    def _check_samples(self, sel: np.ndarray, r: slice) -> tuple[int, np.ndarray]:
        """How many of the new output samples (times ``sel``, buffer rows ``r``) hold a sound state: finite (L, the
        attitude where it is integrated, the eddy modes and effects' states, the torque) with |L| within
        :attr:`L_sound` (:func:`gyro_sim.scenes.limits.L_limit`: what the fields can drive; the kinetic energy is at
        most |L|²/(2 J_min)), and their |L| (N m s). At the first that does not, the run fails: :attr:`failure` says
        what and when, the output ends with the sample before (:attr:`row`) and :attr:`done` is True."""
        y = self.out_y[r]
        if self.sim.attitude:  # (every column of y: L, q, the modes and effects' states)
            ok = np.isfinite(y).all(axis=1) & np.isfinite(self.out_N[r]).all(axis=1)
        else:
            ok = np.isfinite(y[:, 0:3]).all(axis=1) & np.isfinite(y[:, 7:]).all(axis=1) & \
                np.isfinite(self.out_N[r]).all(axis=1)
        with np.errstate(invalid="ignore", over="ignore"):
            Ln = np.linalg.norm(y[:, 0:3], axis=1)
        big = ok & (Ln > self.L_sound)
        if ok.all() and not big.any():
            return sel.size, Ln
        bad = np.flatnonzero(~ok | big)
        i = int(bad[0])
        if big[i]:
            what = (f"|L| = {Ln[i]:.3g} N m s, beyond the {self.L_sound:.3g} N m s the fields can drive "
                    f"(scenes/limits.py L_limit)")
        else:
            parts = [name for name, cols in (("L", y[i, 0:3]), ("the attitude", y[i, 3:7] if self.sim.attitude
                                                                 else np.zeros(1)),
                                             ("the eddy modes / effects", y[i, 7:]), ("the torque", self.out_N[r][i]))
                     if not np.isfinite(cols).all()]
            what = f"the state is not finite ({', '.join(parts)})"
        self.failure = f"failed: {what} at t = {float(sel[i]):.9g} s"
        self.row = self._base + r.start + i
        return i, Ln[:i]

    def _accumulate(self, sel: np.ndarray, rows: slice) -> None:
        """∫|N| dt and ∫ | |Ω| − |Ω0| | dt over the new output samples (the modes' error bound, error_estimate),
        after checking them (:meth:`_check_samples`: a broken state ends the run)."""
        if not sel.size:
            return
        n, Ln = self._check_samples(sel, slice(rows.start, rows.start + sel.size))
        if not n:
            return
        # (sequential sums in time order, sample by sample: the same bits whether samples are breaks or not; scalar
        # code, a few samples a call)
        ts, Ls = sel[:n].tolist(), Ln.tolist()
        self.control.note_L(max(Ls))
        jmax = self.sim.terms.Jinv_max
        prev, turned = self._last_t, self._turned
        if self.sim.mode_plan.kind in (None, "thin_shell"):  # no truncation error to weigh (ModePlan.error_at: 0)
            for t, L in zip(ts, Ls, strict=True):
                turned += L * jmax * (t - prev)
                prev = t
        else:
            r = slice(rows.start, rows.start + n)
            N = np.linalg.norm(self.out_N[r], axis=1).tolist()
            # (over a sample interval ∫|N| dt ≥ |ΔL|: a torque that peaks between the samples, a field's switch-on,
            # counts)
            dL = np.linalg.norm(np.diff(np.vstack([self._L_seen, self.out_y[r, 0:3]]), axis=0), axis=1).tolist()
            self._L_seen = self.out_y[r.stop - 1, 0:3].copy()
            imp, dev, om0 = self._impulse, self._spin_dev, self._om0
            for t, L, Nk, dLk in zip(ts, Ls, N, dL, strict=True):
                dt, om = t - prev, L * jmax
                turned += om * dt
                imp += max(Nk * dt, dLk)
                dev += abs(om - om0) * dt
                prev = t
            self._impulse, self._spin_dev = imp, dev
        self._turned, self._last_t = turned, prev

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
        L_max = max(ctl.L_max, _norm(sim.y[0:3]), 1e-300)
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
        """Output rows as arrays (:func:`gyro_sim.engine.saving.sample_arrays`): t, L, q, omega_b, euler (None
        unless ``euler``), torque, energy, current, rate, phase, modes, effects. ``rows``: output rows of the whole
        run (not yet released)."""
        t_rows, rows = self.t_out[rows], self._buf(rows)
        return sample_arrays(self.scene, self.sim.terms, self.sim.attitude, t_rows, self.out_y[rows],
                             self.out_N[rows], self.cur[rows], self.rate[rows], self.phase[rows], euler=euler)

    def result(self) -> RunResult:
        """The whole run as a :class:`RunResult` (:func:`gyro_sim.engine.saving.run_result`; refused once rows were
        released: a streamed run's result is read back from its bag)."""
        if self._base:
            raise RuntimeError("Runner.result: output rows were released (a streamed run); read its bag back")
        return run_result(self.scene, self.sim.terms, self.sim.attitude, self.samples(slice(0, self.row), euler=False),
                          self.sim.steps, list(self.command_log), self.wall_time, self.compile_time,
                          None if self.failure is not None else self.error_estimate(), self.failure)


def _norm(v: np.ndarray) -> float:
    """|v| of a 3-vector as np.linalg.norm takes it (the square root of its dot product: the same bits), without
    its overhead."""
    return math.sqrt(float(v.dot(v)))


def _holds(times: np.ndarray, t: float) -> bool:
    """Whether sorted ``times`` hold ``t``."""
    i = int(np.searchsorted(times, t))
    return i < times.size and times[i] == t


def _changes(sim: Simulator, commands: dict) -> bool:
    """Whether ``{stator index: (current A | None, rate rad/s | None)}`` changes what a stator of ``sim`` does."""
    return any(c is not None and c != sim.current[k] or r is not None and r != sim.rate[k]
               for k, (c, r) in commands.items())
