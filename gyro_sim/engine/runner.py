"""The :class:`Runner`: the run loop. A :class:`~gyro_sim.engine.simulator.Simulator` advanced break by break
(outputs, commands, controller ticks, switching events), collecting the samples of a run; its error estimate (the
shadow run and the error control) is the :class:`~gyro_sim.engine.shadow.ErrorEstimator` it calls at each break.
"""
from __future__ import annotations

import functools
import math
from typing import Optional

import numpy as np

from gyro_sim.compiled import effects
from gyro_sim.compiled.compile_watch import CompileClock
from gyro_sim.engine.budget import check_budget, check_run_size
from gyro_sim.engine.command_log import CommandLog
from gyro_sim.engine.model import body_rates, controller_period
from gyro_sim.scenes.scene import sorted_union
from gyro_sim.engine.result import RunResult
from gyro_sim.engine.saving import output_times, run_result, sample_arrays
from gyro_sim.engine.shadow import VECTOR_SAMPLES, ErrorEstimator
from gyro_sim.engine.simulator import Simulator
from gyro_sim.common.stamps import stamp_ns
from gyro_sim.scenes.accuracy import ErrorEstimate, is_legacy
from gyro_sim.scenes.limits import L_limit
from gyro_sim.scenes.scene import Scene, SceneError


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
    an in-process run decide alike), estimates the error and corrects the step: all of it the :attr:`estimator`
    (:class:`gyro_sim.engine.shadow.ErrorEstimator`), which the loop calls; :meth:`error_estimate` gives the
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
        # the error control and its shadow run (gyro_sim/engine/shadow.py); checks at fixed fractions of the horizon
        if estimate is None:  # (a law sampled at its switching events: no shadow; nor the old defaults' runs)
            estimate = (scene.controller is None or scene.controller.sampling != "events") and not is_legacy()
        self.estimator = ErrorEstimator(self.sim, scene, T, H, estimate)
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
        # the breaks of every run, samples or not: where the shadow follows (ErrorEstimator.follow)
        self._common = sorted_union(np.array([c.time for c in self._cmds], dtype=float), ticks,
                                    np.array([T], dtype=float), np.array(sorted(knots), dtype=float),
                                    self.estimator._checks)
        self.breaks = sorted_union(t_out, self._common) if sample_breaks else self._common.copy()
        self.estimator.set_breaks(t_out, self.breaks, self._common)
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
        self.command_log = CommandLog()  # every command applied: (t, names, currents|None, rates|None)
        self._bi = 0  # index of the next break to reach
        self._ci = 0
        self.wall_time = 0.0  # s in advance(), numba compile time left out (compile_time)
        self._clock = CompileClock()
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
        t, ticks = self.sim.t, self._ticks
        i = int(ticks.searchsorted(t))
        return i < ticks.size and ticks[i] == t

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
        return self.command_log.take()

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
        ControlInput = _control_input()
        sim = self.sim
        L, q = sim.y[0:3].copy(), sim.y[3:7].copy()
        if sim.terms.eff[effects.ON] or not sim.attitude:
            omega_b = sim.body_rates(sim.t, sim.y)[0]
        else:
            omega_b = body_rates(sim.terms.J, L, q)[1]
        if not hasattr(self, "_axes"):
            self._axes = (tuple(sim.terms.stator_names), sim.terms.control_axes)
        return ControlInput(t=stamp_ns(sim.t) * 1e-9, L=L, q=q, omega_b=omega_b, stator_names=self._axes[0], stator_axes=self._axes[1])

    def apply_commands(self, commands: dict) -> None:
        """Apply ``{stator name: (current A, rate rad/s)}`` now (unknown names raise ValueError)."""
        for name in commands:
            if name not in self.sim.terms.stator_names:
                raise ValueError(f"unknown stator {name!r}; allowed: {self.sim.terms.stator_names}")
        by_index = {self.sim.terms.stator_names.index(n): c for n, c in commands.items()}
        if not self._in_force(by_index):  # (a law that repeats its command at every tick: nothing to change)
            self.sim.set_stators(by_index)
            self.estimator.set_stators(by_index)
        if commands:
            names = list(commands)
            self.command_log.append((self.sim.t, names, [commands[n][0] for n in names], [commands[n][1] for n in names]))

    def _in_force(self, by_index: dict) -> bool:
        """Whether commands ``{stator index: (current A | None, rate rad/s | None)}`` are what the stators do now
        (each value None or equal to the present one): then applying them changes nothing, in the run or its
        shadow (the same field, no field step, the same rates; they passed the same limits when put in force)."""
        cur, rate = self.sim.current.tolist(), self.sim.rate.tolist()
        return all((c is None or _same_float(c, cur[k])) and (r is None or _same_float(r, rate[k]))
                   for k, (c, r) in by_index.items())

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
        sel = t_out[row:max(row, int(t_out.searchsorted(tb + 1e-12 * max(1.0, tb), side="right")))]
        sim = self.sim
        t_seg, ph0, r0, c0 = sim.t, sim.phase.copy(), sim.rate.copy(), sim.current.copy()
        out = slice(row, row + sel.size)
        rows = self._buf(out)
        if rows.stop > self.out_y.shape[0]:
            raise RuntimeError(f"output buffer of {self.out_y.shape[0]} rows is full: release() the rows taken")
        clock = self._clock  # (one clock for the run's advances: their wall and compile times, summed)
        w0, c0_ = clock.wall, clock.compile
        with clock:
            self.row = sim.advance(tb, sel, self.out_y, self.out_N, rows.start) + self._base
            self._accumulate(sel, rows)
            if self.estimator.shadow is not None and self.failure is None:
                self.estimator.follow(tb, sel)
        self.wall_time += clock.wall - w0
        self.compile_time += clock.compile - c0_
        if sel.size:  # (a break without samples writes no rows)
            self.cur[rows] = c0
            self.rate[rows] = r0
            self.phase[rows] = np.mod(ph0 + r0 * (sel[:, None] - t_seg), 2 * math.pi)
        if self.failure is not None:
            return slice(out.start, self.row)  # (the samples before the failure)
        self.apply_scene_commands()
        return out

    # --- the samples: checked, then summed by the error estimate --------------------------------
    def _check_samples(self, sel: np.ndarray, r: slice) -> tuple[int, "np.ndarray | list"]:
        """How many of the new output samples (times ``sel``, buffer rows ``r``) hold a sound state: finite (L, the
        attitude where it is integrated, the eddy modes and effects' states, the torque) with |L| within
        :attr:`L_sound` (:func:`gyro_sim.scenes.limits.L_limit`: what the fields can drive; the kinetic energy is at
        most |L|²/(2 J_min)), and their |L| (N m s). At the first that does not, the run fails: :attr:`failure` says
        what and when, the output ends with the sample before (:attr:`row`) and :attr:`done` is True."""
        y = self.out_y[r]
        if self.sim.attitude:  # scalar code for the sound case (the same |L| bits as np.linalg.norm's: x*x + y*y + z*z
            # in that order); a sum that is not finite (a NaN or inf in the rows, or finite values whose sum
            # overflows) and a large |L| take the general path below
            Ln1: "np.ndarray | list"
            if sel.size > VECTOR_SAMPLES:  # (many samples: the same operations on columns; quiet, as floats are)
                with np.errstate(over="ignore", invalid="ignore"):
                    Ln1 = np.sqrt(y[:, 0] * y[:, 0] + y[:, 1] * y[:, 1] + y[:, 2] * y[:, 2])
                top = float(Ln1.max())
            else:
                Ln1 = [math.sqrt(L0 * L0 + L1 * L1 + L2 * L2) for L0, L1, L2 in y[:, 0:3].tolist()]
                top = max(Ln1)
            if math.isfinite(float(y.sum()) + float(self.out_N[r].sum())) and not top > self.L_sound:
                return sel.size, Ln1
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
        """Check the new output samples (times ``sel``, buffer rows ``rows``; :meth:`_check_samples`: a broken state
        ends the run) and hand the sound ones to the error estimate (:meth:`ErrorEstimator.accumulate`)."""
        if not sel.size:
            return
        n, Ln = self._check_samples(sel, slice(rows.start, rows.start + sel.size))
        if not n:
            return
        self.estimator.accumulate(sel[:n], Ln, self.out_N[rows.start:rows.start + n],
                                  self.out_y[rows.start:rows.start + n, 0:3])

    def error_estimate(self) -> ErrorEstimate:
        """The run's estimated error so far (:meth:`ErrorEstimator.error_estimate`)."""
        return self.estimator.error_estimate()

    # --- exact switching instants ------------------------------------------------------------
    def _snapshot(self) -> tuple:
        sim = self.sim
        return (sim.y.copy(), sim.t, sim.phase.copy(), sim.current.copy(), sim.rate.copy(), sim._nu_max,
                self.row, self._bi, self._ci, len(self.command_log))

    def _restore(self, snap: tuple) -> None:
        sim = self.sim
        sim.y[:], sim.t, sim.phase[:], sim.current[:], sim.rate[:], sim._nu_max = snap[:6]
        self.row, self._bi, self._ci = snap[6:9]
        self.command_log.truncate(snap[9])

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

    def samples(self, rows: slice, euler: bool = True, energy: bool = True) -> dict:
        """Output rows as arrays (:func:`gyro_sim.engine.saving.sample_arrays`): t, L, q, omega_b, euler (None
        unless ``euler``), torque, energy (None unless ``energy``), current, rate, phase, modes, effects. ``rows``:
        output rows of the whole run (not yet released)."""
        t_rows, rows = self.t_out[rows], self._buf(rows)
        return sample_arrays(self.scene, self.sim.terms, self.sim.attitude, t_rows, self.out_y[rows],
                             self.out_N[rows], self.cur[rows], self.rate[rows], self.phase[rows], euler=euler,
                             energy=energy)

    def result(self) -> RunResult:
        """The whole run as a :class:`RunResult` (:func:`gyro_sim.engine.saving.run_result`; refused once rows were
        released: a streamed run's result is read back from its bag)."""
        if self._base:
            raise RuntimeError("Runner.result: output rows were released (a streamed run); read its bag back")
        return run_result(self.scene, self.sim.terms, self.sim.attitude, self.samples(slice(0, self.row), euler=False),
                          self.sim.steps, self.command_log.copy(), self.wall_time, self.compile_time,
                          None if self.failure is not None else self.error_estimate(), self.failure)


def _same_float(a, b: float) -> bool:
    """``a`` is a Python float with the value and sign of ``b`` (-0.0 is not 0.0; NaN is never the same)."""
    return type(a) is float and a == b and (a != 0.0 or math.copysign(1.0, a) == math.copysign(1.0, b))


@functools.cache
def _control_input():
    """gyro_ctl.laws.ControlInput (imported on first use: a run without a law does not import gyro_ctl)."""
    from gyro_ctl.laws import ControlInput

    return ControlInput
