"""Control ticks in compiled code: an in-process run advances through many breaks in one numba call.

Break by break (:meth:`gyro_sim.simulate.Runner.advance`), each controller tick costs tens of µs of Python (about
60 µs on the default scene, measured before this module: docs/benchmark.md): the law on a
:class:`gyro_ctl.laws.ControlInput`, the commands applied to the simulator and its shadow, the call of each one's
stepper, the samples' bookkeeping, the shadow's follow. :class:`TickLoop` advances a runner through consecutive
*plain* breaks (controller ticks and output samples; not a scene command or a flywheel knot, which stay with the
Python loop; an error-control check or the end ends a call, where the shadow then follows as
:meth:`Runner.advance` has it) in one compiled call: at each break it takes the same steps between
the same stops as :meth:`Simulator.advance`, writes the samples' stator columns and turns the field phases on
as :meth:`Runner.advance` does, and at a tick evaluates the built-in law (:func:`gyro_ctl.law_kernels.
law_commands`, the code the ROS controller node calls) on the state. It stops at the first tick whose commands
would change what the stators do; the Python loop applies them there as before. The shadow run of the error
control then follows through the same ticks in one call (of the same compiled loop, without samples or law).

Every number is the break-by-break loop's: the same steps between the same stops (the phasors and step plan are
kept across breaks while the commands stand), the field phases turned on break by break, the law's commands
from the same code on the same state, the same sequential sums of the error estimate. Runs agree with that loop,
and so with the ROS nodes, bit for bit (test/test_ticks.py).

Where it does not apply (:func:`tick_loop` returns None) the Python loop runs as before: a law without a compiled
form (``reorient``, a Python law put in ``gyro_ctl.laws.LAWS``), effects on (their step plan is made afresh at
each break), ``sampling: events`` (the located switches stay in Python).
"""
from __future__ import annotations

import math
import time
from contextlib import contextmanager
from typing import Iterator, Optional

import numpy as np
from numba import njit

from gyro_ctl import law_kernels
from gyro_ctl.laws import CompiledLaw

from gyro_sim.compiled import frozen_flow, kernels, qs_flow
from gyro_sim.compiled.compile_watch import CompileClock
from gyro_sim.compiled.effects import ON
from gyro_sim.common.stamps import stamp_ns
from gyro_sim.engine.model import holds
from gyro_sim.scenes.scene import sorted_union
from gyro_sim.engine.steppers import COMPILED_STEPPERS, arguments

__all__ = ["TickLoop", "tick_loop", "advance", "python_ticks", "MAX_BREAKS"]

#: most breaks one compiled call advances through: an ``on_samples`` caller (progress line, streamed bag) hears
#: from the run at least that often
MAX_BREAKS = 512
_TWO_PI = 2 * math.pi
_NO_AXES = np.zeros((0, 3))
_ENABLED = [True]  # False inside python_ticks()
#: the steppers' step bound in a call of the compiled loop (none: the loop's extent bounds its steps,
#: TickLoop._within_call; the argument types are Simulator.advance's, so numba compiles no second stepper)
_UNBOUNDED = np.int64(1 << 62)


# --- the steppers of Simulator.advance with one signature (their own arguments in the tuple P) ----------------
@njit(cache=True)
def _fields(y, t0, t_seg, stops, record, h, out_y, out_N, k, P):
    """lawson8 / ETDRK4 (:func:`gyro_sim.kernels.integrate`); P = (Bre, Bim, ω, J⁻¹, c_m, w, T_tail, λ, eff, A, b,
    c, case)."""
    Bre, Bim, om, Jinv, c_m, w, tail, lam, eff, A, b, c, case = P
    return kernels.integrate(y, t0, t_seg, stops, record, h, Bre, Bim, om, Jinv, c_m, w, tail, lam, out_y, out_N, k,
                             eff, A, b, c, case, np.zeros(3), _UNBOUNDED)


@njit(cache=True)
def _frozen(y, t0, t_seg, stops, record, h, out_y, out_N, k, P):
    """frozen_flow (:func:`gyro_sim.frozen_flow.integrate_frozen`); P = (Bre, Bim, ω, J⁻¹, J_t, J_a, axis, c_m, w,
    T_tail, 1/τ, case)."""
    Bre, Bim, om, Jinv, Jt, Ja, ax, c_m, w, tail, lam_modes, case = P
    return frozen_flow.integrate_frozen(y, t0, t_seg, stops, record, h, Bre, Bim, om, Jinv, Jt, Ja, ax, c_m, w, tail,
                                        lam_modes, out_y, out_N, k, case, np.zeros(3), _UNBOUNDED)


@njit(cache=True)
def _free(y, t0, t_seg, stops, record, h, out_y, out_N, k, P):
    """The torque-free stepper (:func:`gyro_sim.kernels.integrate_free`); P = (J⁻¹, 1/J_ref, axis, τ)."""
    Jinv, inv_ref, axis, tau = P
    return kernels.integrate_free(y, t0, stops, record, h, Jinv, inv_ref, axis, tau, out_y, out_N, k, np.zeros(3),
                                  _UNBOUNDED)


@njit(cache=True)
def _qs(y, t0, t_seg, stops, record, h, out_y, out_N, k, P):
    """The quasi-static flow step (:func:`gyro_sim.compiled.qs_flow.integrate_qs`); P = (Bre, Bim, ω, J⁻¹, J_t,
    J_a, axis, c_m, w, T_tail, case)."""
    Bre, Bim, om, Jinv, Jt, Ja, ax, c_m, w, tail, case = P
    return qs_flow.integrate_qs(y, t0, t_seg, stops, record, h, Bre, Bim, om, Jinv, Jt, Ja, ax, c_m, w, tail, out_y,
                                out_N, k, case, np.zeros(3), _UNBOUNDED)


@njit(inline="always")
def _step(Pf, Pz, Pa, Pq, y, t0, t_seg, stops, record, h, out_y, out_N, k):
    """The stepper whose argument tuple is given (the others None: numba prunes the calls of the others)."""
    if Pf is not None:
        return _fields(y, t0, t_seg, stops, record, h, out_y, out_N, k, Pf)
    if Pz is not None:
        return _frozen(y, t0, t_seg, stops, record, h, out_y, out_N, k, Pz)
    if Pa is not None:
        return _free(y, t0, t_seg, stops, record, h, out_y, out_N, k, Pa)
    if Pq is not None:
        return _qs(y, t0, t_seg, stops, record, h, out_y, out_N, k, Pq)
    return k, 0  # (none given: no step)


# --- the loops ------------------------------------------------------------------------------------------------
@njit
def _turn(phase, rate, dt):
    """Field phases σ_k (rad) turned on by ``dt`` s at rates ν_k, in place, as Simulator.advance does."""
    for k in range(phase.shape[0]):
        phase[k] = np.mod(phase[k] + rate[k] * dt, _TWO_PI)


@njit
def _bound(h_max, span):
    """The step bound of an advance over ``span`` s: ``h_max``, or the whole span where the plan has none
    (Simulator.advance; such advances go one break at a time)."""
    return h_max if math.isfinite(h_max) else max(span, 1e-300)


@njit
def _stops(bk, s_end, t_out, s, i, e):
    """The stops of one advance through breaks bk[i..e] from sample index ``s``: each break's samples (recorded),
    then the break itself where no sample falls on it (not recorded), as Simulator.advance takes them."""
    n = 0
    lo = s
    for b in range(i, e + 1):
        hi = s_end[b]
        n += hi - lo + (1 if hi == lo or t_out[hi - 1] < bk[b] else 0)
        lo = hi
    stops = np.empty(n)
    record = np.empty(n, np.bool_)
    n = 0
    lo = s
    for b in range(i, e + 1):
        hi = s_end[b]
        for j in range(lo, hi):
            stops[n] = t_out[j]
            record[n] = True
            n += 1
        if hi == lo or t_out[hi - 1] < bk[b]:  # (a sample within round-off past the break is its last stop)
            stops[n] = bk[b]
            record[n] = False
            n += 1
        lo = hi
    return stops, record


@njit(cache=True)
def breaks(Pf, Pz, Pa, Pq, y, t, t_seg, h_max, bk, s_end, t_out, s0, base, out_y, out_N, phase, rate, cur,
           ph_rows, cur_rows, rate_rows, law_at, reads_state, t_law, kind, axes, fp, cl, rl, idx, log_c, log_r):
    """Advance y from ``t`` through the breaks ``bk`` (s) under fixed commands, with the numbers
    :meth:`Runner.advance` gives one break at a time: the samples t_out[s0 : s_end[i]] (output row s − ``base``)
    are stops recorded on the way to break i; their stator columns get the currents ``cur``, rates ``rate`` and
    phases turned on from the break before; ``phase`` (rad) turns on to each break. Where ``law_at[i]`` the law
    (kind, axes, fp, limits cl, rl: :func:`gyro_ctl.law_kernels.law_commands`) is evaluated at time ``t_law[i]``
    on the state: if its commands would change a stator (a current or rate, of stator ``idx[j]``, other than the
    one in force) the loop stops there, else they are written to row n of ``log_c``, ``log_r`` (NaN: unchanged).
    A law that does not read the state (``reads_state`` False) is evaluated at its first tick only: its commands
    are those at every tick.

    The steps between two evaluations of the law are taken in one stepper call (the same steps between the same
    stops as break by break: each interval between stops is split alike, and the stepper keeps no other state;
    without a step bound, one break at a time as Simulator.advance bounds the step by the break's span).

    Returns (breaks done, steps, the next sample index, commands logged)."""
    nb = bk.shape[0]
    n_st = phase.shape[0]
    nc = idx.shape[0]
    c_new = np.empty(nc)
    r_new = np.empty(nc)
    steps = 0
    s = s0
    n_log = 0
    evaluate = True
    bounded = math.isfinite(h_max)
    i = 0
    while i < nb:
        e = i  # this advance ends at the next tick where the law is evaluated, else at the last break
        while bounded and e < nb - 1 and not (law_at[e] and evaluate):
            e += 1
        stops, record = _stops(bk, s_end, t_out, s, i, e)
        _, st = _step(Pf, Pz, Pa, Pq, y, t, t_seg, stops, record, _bound(h_max, bk[e] - t), out_y, out_N, s - base)
        steps += st
        for b in range(i, e + 1):
            hi = s_end[b]
            for j in range(s, hi):
                row = j - base
                for k in range(n_st):
                    cur_rows[row, k] = cur[k]
                    rate_rows[row, k] = rate[k]
                    ph_rows[row, k] = np.mod(phase[k] + rate[k] * (t_out[j] - t), _TWO_PI)
            _turn(phase, rate, bk[b] - t)
            t = bk[b]
            s = hi
            if law_at[b] and not evaluate:  # the state-free law's commands, as at its first tick
                for j in range(nc):
                    log_c[n_log, j] = c_new[j]
                    log_r[n_log, j] = r_new[j]
                n_log += 1
        if law_at[e] and evaluate:
            law_kernels.law_commands(kind, t_law[e], y[0:3], y[3:7], axes, fp, cl, rl, c_new, r_new)
            for j in range(nc):
                c, r = c_new[j], r_new[j]
                if (c == c and c != cur[idx[j]]) or (r == r and r != rate[idx[j]]):
                    return e + 1, steps, s, n_log
            for j in range(nc):
                log_c[n_log, j] = c_new[j]
                log_r[n_log, j] = r_new[j]
            n_log += 1
            evaluate = reads_state
        i = e + 1
    return nb, steps, s, n_log


def _next(mask: np.ndarray) -> np.ndarray:
    """For each index, the first index at or after it where ``mask`` holds (mask.size where none does)."""
    at = np.append(np.flatnonzero(mask), mask.size)
    return at[np.searchsorted(at, np.arange(mask.size))]


def stepper(sim, seg: tuple) -> tuple:
    """(Pf, Pz, Pa, Pq): the arguments of the stepper :meth:`Simulator.advance` calls for a simulator's segment
    ``seg`` (:meth:`Simulator._segment`) in its slot (:func:`gyro_sim.engine.steppers.arguments`)."""
    return arguments(sim.terms, seg)


class TickLoop:
    """The compiled tick loop of one :class:`~gyro_sim.simulate.Runner` driven by a built-in law (or none): see the
    module docstring. Make it with :func:`tick_loop`; :meth:`advance` in place of ``Runner.advance`` where the next
    break is plain."""

    def __init__(self, r, law: Optional[CompiledLaw]):
        self.r = r
        self._clock = CompileClock()  # (one for the loop's calls: their wall and compile times, summed)
        bk = r.breaks
        fly = r.scene.effects.flywheel
        knots = [t for t in fly.profile.time if 0 < t < r.T] if fly is not None else []
        hard = holds(bk, sorted_union(np.array([c.time for c in r._cmds], dtype=float), np.array(knots, dtype=float)))
        # a check or the end (not a command's or knot's break) ends a call: the loop advances to it, then the shadow
        # follows there as Runner.advance has it follow (ErrorEstimator.follow)
        self._soft = holds(bk, sorted_union(r.estimator._checks, np.array([r.T]))) & ~hard
        # the first break at or after each that a call stops before (hard) or at (soft): len(bk) where none is
        self._next_hard = _next(hard)
        self._next_soft = _next(self._soft)
        self._tick = holds(bk, r._ticks) if law is not None else np.zeros(bk.size, bool)
        self._common = holds(bk, r._common)
        # the samples each break records: those up to it and within round-off past it (Runner.advance's ``sel``)
        self._s_end = np.searchsorted(r.t_out, bk + 1e-12 * np.maximum(1.0, bk), side="right")
        sim = r.sim
        if law is None:
            self.kind, self.fp, self.cl, self.rl = law_kernels.HOLD, np.zeros(0), math.nan, math.nan
            self.needs_time = self.reads_state = False
            self.names, self.axes = [], _NO_AXES
        else:
            self.kind, self.fp, self.cl, self.rl = law.kind, law.fp, law.current_limit, law.rate_limit
            self.needs_time, self.reads_state = law.needs_time, law.reads_state
            terms = sim.terms
            self.names = law.command_names(terms.stator_names)
            self.axes = law.control_axes(terms.stator_names, terms.control_axes)  # (control_input's axes)
        self.idx = np.array([sim.terms.stator_names.index(n) for n in self.names], dtype=np.int64)

    def advance(self, until: Optional[float] = None) -> Optional[slice]:
        """Advance through the plain breaks ahead (up to :data:`MAX_BREAKS`, none after ``until`` s, as many as the
        output buffer holds), stopping early at a tick whose law changes the commands (the runner is then at that
        tick, its commands not yet applied). Returns the output rows written, or None where the next break is
        not plain (then ``Runner.advance`` takes it)."""
        r = self.r
        if r.row == 0 or r.done:
            return None
        i0, j = r._bi, self._extent(until)
        if j <= i0 or r.sim._segment()[5] not in COMPILED_STEPPERS:
            return None
        j_all, j = j, self._within_call(i0, j)
        if j <= i0:  # (a break farther than a call's steps: Runner.advance, whose stepper calls are bounded)
            return None
        clock = self._clock
        wall0, comp0 = clock.wall, clock.compile
        with clock:
            w0 = time.perf_counter()
            bk, law_at, rows, n_log, log_c, log_r = self._advance_main(r.breaks[i0:j])
            if j < j_all:  # (the call's steps bounded it: tuned to Simulator.CALL_WALL s a call)
                r.sim._tune_call(time.perf_counter() - w0, r.sim.call_steps)
            nb = r._bi - i0
            common = bk[:nb][self._common[i0:i0 + nb]]
            es = r.estimator
            if es.shadow is not None and common.size and not es._lazy and r.failure is None:
                self._follow(common)
            if self._soft[r._bi - 1] and es.shadow is not None and r.failure is None:
                es.follow(float(bk[nb - 1]), None)  # (at a check or the end: as Runner.advance)
        r.wall_time += clock.wall - wall0
        r.compile_time += clock.compile - comp0
        if n_log:
            self._log(bk[:nb][law_at[:nb]][:n_log], log_c[:n_log], log_r[:n_log])
        return rows

    def _extent(self, until: Optional[float]) -> int:
        """The end (exclusive index of r.breaks) of the plain breaks the next call may take."""
        r = self.r
        i0 = r._bi
        j = min(int(self._next_hard[i0]), int(self._next_soft[i0]) + 1, i0 + MAX_BREAKS)
        if until is not None:
            j = min(j, int(r.breaks.searchsorted(until, side="right")))
        room = r._base + r.out_y.shape[0]  # the first sample the output buffer cannot take
        return min(j, i0 + int(self._s_end[i0:j].searchsorted(room, side="right")))

    def _within_call(self, i0: int, j: int) -> int:
        """The end (exclusive) of the breaks r.breaks[i0:j] one compiled call may take: those within the steps
        of one stepper call (:attr:`Simulator.call_steps` steps of the segment's step from now), so Python
        handles a signal between calls (the shadow's steps are longer). One break at a time where the plan has
        no step bound."""
        r = self.r
        sim = r.sim
        h = sim._seg[1][6]
        if not math.isfinite(h):
            return j  # (a step a stop)
        return min(j, int(r.breaks.searchsorted(sim.t + sim.call_steps * h, side="right")))

    def _advance_main(self, bk: np.ndarray) -> tuple:
        """The run through breaks ``bk`` (from r._bi on) in one call of :func:`breaks`: its state, samples, field
        phases, steps, the runner's row and break index and its error sums. Returns (bk, where the law was due,
        the output rows written, commands logged, their currents, their rates)."""
        r = self.r
        sim, i0, row0 = r.sim, r._bi, r.row
        law_at = self._tick[i0:i0 + bk.size].copy()
        law_at[-1] = False  # the last break returns to the Python loop, which runs the law there
        t_law = np.array([stamp_ns(t) * 1e-9 for t in bk.tolist()]) if self.needs_time else bk
        log_c, log_r = np.empty((bk.size, self.idx.size)), np.empty((bk.size, self.idx.size))
        seg = sim._segment()
        phase = sim.phase.copy()
        nb, steps, s_hi, n_log = breaks(
            *stepper(sim, seg), sim.y, sim.t, seg[0], seg[6], bk, self._s_end[i0:i0 + bk.size], r.t_out, row0,
            r._base, r.out_y, r.out_N, phase, sim.rate, sim.current, r.phase, r.cur, r.rate, law_at,
            self.reads_state, t_law, self.kind, self.axes, self.fp, self.cl, self.rl, self.idx, log_c, log_r)
        sim.steps += steps
        sim.phase = phase
        sim.t = sim._seg_t_end = float(bk[nb - 1])
        rows = slice(row0, s_hi)
        r.row, r._bi = s_hi, i0 + nb
        r._accumulate(r.t_out[row0:s_hi], r._buf(rows))
        rows = slice(row0, r.row)  # (a run that failed ends at its last sound sample: Runner._check_samples)
        return bk, law_at, rows, n_log, log_c, log_r

    def _follow(self, common: np.ndarray) -> None:
        """The shadow run follows through the common breaks ``common`` (ErrorEstimator.follow, none a check) in one
        call; its steps and the run's count for the error control."""
        es = self.r.estimator
        es.count_stretch(self._follow_one(es.shadow, common))  # (under the run's segment of this chunk)

    @staticmethod
    def _follow_one(sh, common: np.ndarray) -> int:
        """Advance shadow ``sh`` through ``common`` in one call of :func:`breaks`; returns its steps."""
        sseg = sh._segment()
        phase = sh.phase.copy()
        n, k = common.size, sh.rate.size
        # (breaks without samples or law: one stepper call through them, as Simulator.advance(tb) break by break; the
        # run's argument types, so numba compiles no second loop)
        _, s_steps, _, _ = breaks(
            *stepper(sh, sseg), sh.y, sh.t, sseg[0], sseg[6], common, np.zeros(n, np.int64), common, 0, 0,
            np.zeros((1, sh.y.size)), np.zeros((1, 3)), phase, sh.rate, sh.current, np.zeros((1, k)),
            np.zeros((1, k)), np.zeros((1, k)), np.zeros(n, np.bool_), False, common, law_kernels.HOLD, _NO_AXES,
            np.zeros(0), math.nan, math.nan, np.zeros(0, np.int64), np.zeros((n, 0)), np.zeros((n, 0)))
        sh.steps += s_steps
        sh.phase = phase
        sh.t = sh._seg_t_end = float(common[-1])
        return s_steps

    def _log(self, times: np.ndarray, cur: np.ndarray, rate: np.ndarray) -> None:
        """The commands of the ticks whose law changed nothing, in the runner's log as apply_commands writes them."""
        names = self.names
        if not names:  # (a law that commands no stator, 'hold': nothing applied, nothing logged, as apply_commands)
            return
        # (arrays, made into tuples where the log is read: gyro_sim.engine.command_log; the law 'off' leaves a
        # field's rate unchanged: NaN there, None in the log)
        self.r.command_log.add_ticks(times, names, cur, rate, nan_is_none=self.kind == law_kernels.OFF)


def tick_loop(r, law) -> Optional[TickLoop]:
    """The compiled tick loop of runner ``r`` driven by ``law`` (a :class:`gyro_ctl.laws.CompiledLaw`, or None: no
    controller), or None where it does not apply: a law without a compiled form, an effect on (the step plan is
    made afresh at each break), a law naming a stator the scene lacks (the Python loop then says so)."""
    if not _ENABLED[0] or law is not None and not isinstance(law, CompiledLaw):
        return None
    if r.sim.terms.eff[ON] != 0.0:
        return None
    try:
        return TickLoop(r, law)
    except ValueError:
        return None


def advance(r, loop: Optional[TickLoop], until: Optional[float] = None) -> slice:
    """One advance of a loop driving runner ``r``: through the plain breaks ahead in one compiled call where
    ``loop`` (:func:`tick_loop`) applies, else :meth:`Runner.advance` (to the next break, or ``until`` s)."""
    rows = loop.advance(until) if loop is not None else None
    return rows if rows is not None else r.advance(until=until)


@contextmanager
def python_ticks() -> Iterator[None]:
    """Within the block, runs take their ticks break by break in Python (:func:`tick_loop` gives None): the
    loop before this module, to compare with (the benchmark's per-tick part, the tests)."""
    _ENABLED[0] = False
    try:
        yield
    finally:
        _ENABLED[0] = True
