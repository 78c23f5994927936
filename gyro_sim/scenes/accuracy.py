"""Accuracy by default: what a scene's ``accuracy`` section asks for, and how a run meets it.

A scene states its tolerance (``accuracy: {rtol: 1e-6, attitude: 1e-6}``: a relative tolerance on L and an
absolute one on the attitude in rad, both over the whole run; :data:`DEFAULT_RTOL`, :data:`DEFAULT_ATTITUDE`).
From it and the scene the run chooses

* the eddy modes of a solid sphere or a shell and whether the static tail term is used
  (:func:`mode_plan`): from the largest slip the run can meet (:func:`slip_bound`: the field rates of the
  stators, of the scheduled commands, of the controller law's parameters and of the general field terms,
  plus the fastest spin the rotor can reach in the duration), the fewest modes whose truncation error
  (the modal ĝ against the closed forms [M] (2.14), (2.13), :func:`modal_error`) is within
  :data:`MODE_SHARE` of the tolerance. An explicit ``modes:`` wins, with an :class:`AccuracyWarning` where it
  cannot meet the tolerance;
* the step knobs of every stepper (:func:`step_plan`: ``steps_per_turn`` of lawson8, ETDRK4 and the free
  stepper, ``rate_change`` of the frozen-flow step), from each stepper's error constant (measured,
  :data:`STEP_ERROR`) and the number of turns of the run (the attitude's phase error adds up over the
  duration). Explicit knobs win, with a warning where the error model says they miss the tolerance.

Budget. The modal truncation gets :data:`MODE_SHARE` (a quarter) of each tolerance and the steps the rest
(:data:`STEP_SHARE`); the run's error estimate (:mod:`gyro_sim.simulate`, ``RunResult.error_estimate``) adds
the two.

Modal error measure (:func:`modal_error`): over slips ω in (0, ω_max], max |ĝ_N(ω) − ĝ(ω)|/|ĝ(ω)| (the whole
moment, which sets L's direction) and |Im ĝ_N − Im ĝ|/Im ĝ (the dissipative part: the torque of a rotating field,
[M] (2.14), physics.md §3). The torque error δN = ε N turns into an error of L of ε ∫|N| dt ≈ ε |ΔL|, and of the
spin phase of at most ε ∫|Ω(t) − Ω(0)| dt ≤ ε Ω_reach T: that is why the attitude tolerance sets the Im part's
bound to attitude / (Ω_reach T) (:func:`mode_tolerances`).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Optional

import numpy as np

from gyro_sim.physics.conductor import (ModalModel, g_shell, g_solid_sphere, modal_shell, modal_solid_sphere, modal_thin_shell,
                        shell_tau_eff)
from gyro_sim.physics.constants import MU0

__all__ = ["DEFAULT_RTOL", "DEFAULT_ATTITUDE", "MODE_SHARE", "STEP_SHARE", "MAX_MODES", "AccuracyWarning",
           "ModePlan", "mode_plan", "slip_bound", "spin_reach", "modal_error", "choose_modes", "scene_conductor",
           "truncated_model", "mode_tolerances", "PHASE_REL_MIN"]

#: default relative tolerance on L over the whole run
DEFAULT_RTOL = 1e-6
#: default absolute tolerance on the attitude (rad, the rotation angle between computed and true attitude) over
#: the whole run
DEFAULT_ATTITUDE = 1e-6
#: share of each tolerance given to the eddy modes' truncation
MODE_SHARE = 0.25
#: share given to the steps
STEP_SHARE = 0.75
#: most eddy modes a run may carry (the scene format's limit of ``modes``)
MAX_MODES = 500
#: the tightest modal truncation error asked for: the closed forms of ĝ are evaluated to about 1e-15 of |ĝ|, and
#: the measured error of many modes levels off at a few 1e-15 (round-off)
MODE_TOL_FLOOR = 1e-13
#: slips at which the modal error is evaluated: this many, geometric from 1e-4 ω_max to ω_max
_GRID = 240


#: the fixed knobs of the runs before the accuracy plan (issue 19): 10 eddy modes with the tail, 12 lawson8 / 48
#: ETDRK4 / 48 free steps per turn, rate_change 1e-4, no shadow run. :func:`legacy` switches them on (the benchmark's
#: "today's defaults"; gyro_sim/bench_accuracy.py)
LEGACY_MODES = 10
LEGACY_STEPS_PER_TURN = {"lawson8": 12, "etdrk4": 48, "free": 48}
LEGACY_RATE_CHANGE = 1e-4
_LEGACY = [False]


class legacy:
    """Context manager: runs made inside plan as before the accuracy plan (:data:`LEGACY_MODES`,
    :data:`LEGACY_STEPS_PER_TURN`, :data:`LEGACY_RATE_CHANGE`, no error control); a scene's explicit knobs still
    win. For the benchmark's comparison with the old defaults only."""

    def __enter__(self):
        self._was = _LEGACY[0]
        _LEGACY[0] = True
        return self

    def __exit__(self, *exc):
        _LEGACY[0] = self._was
        return False


def is_legacy() -> bool:
    return _LEGACY[0]


class AccuracyWarning(UserWarning):
    """A run cannot meet its scene's ``accuracy`` (an explicit knob, too few modes, a slip beyond the plan)."""


def warn(text: str) -> None:
    """Issue an :class:`AccuracyWarning` (shown once per text by Python's default filter)."""
    warnings.warn(text, AccuracyWarning, stacklevel=3)


# --------------------------------------------------------------------------------------------------
# what the scene can meet: rates, currents, spin
# --------------------------------------------------------------------------------------------------
def law_limits(ctl) -> tuple[float, float]:
    """(largest |rate| rad/s, largest current A) a controller law's parameters can command (0 where it commands
    none); ``rate_limit``/``current_limit`` clip them."""
    if ctl is None:
        return 0.0, 0.0
    p = ctl.params
    rates, currents = [0.0], [0.0]
    law = ctl.law
    if law == "spinup":
        rates.append(abs(p.target_spin))
        currents.append(p.current)
    elif law == "psi_switching":
        nu = p.nu if isinstance(p.nu, list) else [p.nu]
        rates += [abs(v) for v in nu] + [abs(p.spin_rate)]
        currents += [p.control_current, p.spin_current]
    elif law == "manual":
        rates += [abs(c.rate) for c in p.commands.values()]
        currents += [c.current for c in p.commands.values()]
    elif law == "reorient":
        rates += [abs(v) for v in p.rates.values()]
        currents.append(p.current_limit)
    rate, cur = max(rates), max(currents)
    if ctl.rate_limit is not None:
        rate = min(rate, ctl.rate_limit)
    if ctl.current_limit is not None:
        cur = min(cur, ctl.current_limit)
    return rate, cur


def field_rates(scene) -> float:
    """Largest field rate (rad/s) the scene sets: stators, scheduled commands, the controller law's parameters,
    general field terms."""
    rates = [abs(s.rate) for s in scene.stators] + [abs(c.rate) for c in scene.commands if c.rate is not None]
    rates += [f.frequency for f in scene.field] + [law_limits(scene.controller)[0]]
    return max(rates + [0.0])


def field_amplitude(scene) -> float:
    """An upper bound (T) on |B| the scene can set: Σ_k b_k I_max + Σ_p |B_p| (I_max: the largest current of the
    stator, of its commands and of the law's parameters)."""
    law_cur = law_limits(scene.controller)[1]
    B = 0.0
    for s in scene.stators:
        cur = max([s.current, law_cur] + [c.current for c in scene.commands
                                          if c.stator == s.name and c.current is not None])
        B += s.coil_constant * cur
    for f in scene.field:
        B += math.hypot(*f.real) + math.hypot(*f.imag)
    return B


def active_stators(scene) -> list:
    """The stators that can carry current in a run: a current in the scene, in a command, or named by the law."""
    ctl = scene.controller
    used = set(ctl.stators_used()) if ctl is not None else set()
    on = {c.stator for c in scene.commands if c.current}
    return [s for s in scene.stators if s.current > 0 or s.name in on or s.name in used]


def spin_reach(scene, T: float) -> float:
    """Fastest body rate |Ω| (rad/s) the rotor can reach within T s: at most |L0|/J_min plus what the largest
    torque can add in T (|m| ≤ (2π r2³/μ0)|B| since |ĝ| ≤ 1; the quasi-static torque k_e B²(Ω + ν)), and at
    most the larger of |L0|/J_min and the fastest field rate × J_max/J_min (an induction drive does not pass its
    field's rate), twice that where the stators that can carry current have more than one axis ([K] (2.1)'s
    equilibria l_k* ≤ 2 m_k ν_k/(γ(M + m_k)) with the factor 2)."""
    J = np.asarray(scene.rotor.inertia, dtype=float)
    ini = scene.initial
    L0 = ini.kinetic_moment if ini.kinetic_moment is not None else J[2] * abs(ini.spin or 0.0)
    om0 = L0 / float(np.min(J))
    nu = field_rates(scene)
    cond = scene.rotor.conductor
    if cond is None or scene.torque_model == "none" or scene.effects.magnetizable is not None:
        if scene.effects.flywheel is not None or scene.effects.magnetizable is not None:
            return om0 + nu  # (the flywheel's own rate is the stepper's concern: Simulator._effect_rate)
        return om0
    c_m = 2 * math.pi * cond.outer_radius ** 3 / MU0
    B = field_amplitude(scene)
    N = c_m * B * B
    if scene.torque_model == "quasi_static":
        r1 = cond.inner_radius
        N *= shell_tau_eff(r1, cond.outer_radius, cond.conductivity) * (om0 + 2 * nu)
    by_torque = om0 + N * T / float(np.min(J))
    axes = {tuple(round(abs(float(v)), 12) for v in s.axis) for s in active_stators(scene)}
    several = len(axes) > 1 or bool(scene.field)
    by_rate = max(om0, (2.0 if several else 1.0) * nu * float(np.max(J) / np.min(J)))
    return min(by_torque, by_rate)


def slip_bound(scene, T: float) -> float:
    """Largest slip (rad/s, the frequency of the field seen from the body) a run of T s can meet: the fastest
    field rate plus the fastest spin (:func:`spin_reach`)."""
    return field_rates(scene) + spin_reach(scene, T)


# --------------------------------------------------------------------------------------------------
# modal truncation
# --------------------------------------------------------------------------------------------------
@lru_cache(maxsize=64)
def _full_model(kind: str, r2: float, sigma: float, thickness: Optional[float]) -> ModalModel:
    """The conductor's modal model with :data:`MAX_MODES` modes (truncations are slices of it)."""
    if kind == "solid_sphere":
        return modal_solid_sphere(r2, sigma, MAX_MODES)
    return modal_shell(r2 - thickness, r2, sigma, MAX_MODES)


def truncated_model(kind: str, r2: float, sigma: float, thickness: Optional[float], n: int,
                    tail: bool = True) -> ModalModel:
    """The first ``n`` modes of the conductor, with the static tail term (``tail``: T = τ_eff − Σ_{k≤n} w_k τ_k,
    [M] (2.14)/(2.13)'s exact low-frequency slope) or without it; a thin shell's one exact mode ([M] (2.15))."""
    if kind == "thin_shell":
        return modal_thin_shell(r2, thickness, sigma)
    n = int(n)
    if n > MAX_MODES:
        full = modal_solid_sphere(r2, sigma, n) if kind == "solid_sphere" else modal_shell(r2 - thickness, r2, sigma, n)
    else:
        full = _full_model(kind, float(r2), float(sigma), None if thickness is None else float(thickness))
    tau, w = full.tau[:n], full.weight[:n]
    if tail and kind == "solid_sphere":  # the closed form of the sphere's tail, [M] (2.14): 6 μ0σa²/π⁴ ζ(4, n+1)
        from scipy.special import zeta

        tail_tau = 6.0 * MU0 * sigma * r2 * r2 / math.pi ** 4 * float(zeta(4.0, n + 1))
    elif tail:  # the exact k² slope of (2.13) less the kept modes' (conductor.modal_shell)
        tail_tau = shell_tau_eff(r2 - thickness, r2, sigma) - float(np.sum(w * tau))
    else:
        tail_tau = 0.0
    return ModalModel(tau=tau, weight=w, tail_tau=tail_tau, radius=r2, kind=kind)


def _exact_g(kind: str, r2: float, sigma: float, thickness: Optional[float], w: np.ndarray) -> np.ndarray:
    if kind == "solid_sphere":
        return g_solid_sphere(w, r2, sigma)  # [M] (2.14)
    return g_shell(w, r2 - thickness, r2, sigma)  # [M] (2.13), corrected


@lru_cache(maxsize=256)
def _errors(kind: str, r2: float, sigma: float, thickness: Optional[float], slip: float) -> dict:
    """(e_g, e_im) arrays over n = 1..MAX_MODES with and without the tail: dict {tail: (e_g[n-1], e_im[n-1])}."""
    w = slip * np.geomspace(1e-4, 1.0, _GRID)
    g = _exact_g(kind, r2, sigma, thickness, w)
    full = _full_model(kind, r2, sigma, thickness)
    iwt = 1j * w[:, None] * full.tau[None, :]
    terms = full.weight * iwt / (1.0 - iwt)  # (grid, modes)
    partial = np.cumsum(terms, axis=1)  # Σ_{k≤n}
    kept_slope = np.cumsum(full.weight * full.tau)
    out = {}
    for tail in (True, False):
        gm = partial + (1j * w[:, None] * (full.tau_eff - kept_slope)[None, :] if tail else 0.0)
        e_g = np.max(np.abs(gm - g[:, None]) / np.abs(g)[:, None], axis=0)
        e_im = np.max(np.abs(gm.imag - g.imag[:, None]) / g.imag[:, None], axis=0)
        out[tail] = (e_g, e_im)
    return out


def modal_error(kind: str, r2: float, sigma: float, thickness: Optional[float], n: int, tail: bool,
                slip: float) -> tuple[float, float]:
    """(e_g, e_im): largest |ĝ_N − ĝ|/|ĝ| and |Im ĝ_N − Im ĝ|/Im ĝ over slips (0, ``slip``] (rad/s) of the
    first ``n`` modes (with or without the tail) against the closed form ([M] (2.14) sphere, corrected (2.13)
    shell); (0, 0) for a thin shell (its one mode is [M] (2.15) exactly) and at zero slip."""
    if kind == "thin_shell" or not slip > 0:
        return 0.0, 0.0
    if n > MAX_MODES:
        return 0.0, 0.0  # (beyond the table: smaller than at MAX_MODES)
    e = _errors(kind, float(r2), float(sigma), None if thickness is None else float(thickness), float(slip))[tail]
    return float(e[0][n - 1]), float(e[1][n - 1])


def choose_modes(kind: str, r2: float, sigma: float, thickness: Optional[float], slip: float, tol_g: float,
                 tol_im: float) -> tuple[int, bool, float, float, bool]:
    """(n, tail, e_g, e_im, met): the fewest modes (and the tail choice) whose :func:`modal_error` up to ``slip`` is
    within (tol_g, tol_im); where even :data:`MAX_MODES` is not, that many with ``met`` False."""
    if kind == "thin_shell":
        return 1, False, 0.0, 0.0, True
    if not slip > 0:
        return 1, True, 0.0, 0.0, True
    errs = _errors(kind, float(r2), float(sigma), None if thickness is None else float(thickness), float(slip))
    best = None
    for tail in (True, False):
        e_g, e_im = errs[tail]
        ok = np.nonzero((e_g <= tol_g) & (e_im <= tol_im))[0]
        if ok.size and (best is None or ok[0] + 1 < best[0]):
            best = (int(ok[0]) + 1, tail, float(e_g[ok[0]]), float(e_im[ok[0]]), True)
    if best is not None:
        return best
    # not met: the choice with the smaller error at MAX_MODES
    cands = [(max(errs[t][0][-1] / tol_g, errs[t][1][-1] / tol_im), t) for t in (True, False)]
    tail = min(cands)[1]
    return MAX_MODES, tail, float(errs[tail][0][-1]), float(errs[tail][1][-1]), False


def best_tail(kind: str, r2: float, sigma: float, thickness: Optional[float], n: int, slip: float) -> bool:
    """With ``n`` modes given: the tail choice with the smaller error up to ``slip`` (the tail unless it hurts)."""
    if kind == "thin_shell" or not slip > 0 or n > MAX_MODES:
        return kind != "thin_shell"
    a = modal_error(kind, r2, sigma, thickness, n, True, slip)
    b = modal_error(kind, r2, sigma, thickness, n, False, slip)
    return max(a) <= max(b)


def mode_tolerances(rtol: float, attitude: Optional[float], om_reach: float, T: float) -> tuple[float, float]:
    """(tol_g, tol_im) of the modal truncation: :data:`MODE_SHARE` of rtol for both; the Im part also within
    MODE_SHARE × attitude / (Ω_reach T) (the spin phase error ε ∫|Ω − Ω0| dt), where the attitude counts."""
    tol_g = max(MODE_SHARE * rtol, MODE_TOL_FLOOR)
    tol_im = tol_g
    if attitude is not None and om_reach * T > 0:
        tol_im = max(min(tol_im, MODE_SHARE * attitude / (om_reach * T)), MODE_TOL_FLOOR)
    return tol_g, tol_im


@dataclass(frozen=True)
class ModePlan:
    """The eddy modes of a run: ``n`` modes (0: no lag modes), ``tail`` (the static tail term used), the slip
    bound (rad/s) they were chosen for, the tolerances of the truncation (tol_g, tol_im) and its error there
    (e_g, e_im), ``explicit`` (the scene's ``modes:``) and ``met`` (whether the error is within the tolerances)."""

    n: int
    tail: bool
    slip: float
    tol_g: float
    tol_im: float
    e_g: float
    e_im: float
    explicit: bool
    met: bool
    kind: Optional[str] = None
    radius: float = 0.0
    sigma: float = 0.0
    thickness: Optional[float] = None
    notes: tuple = field(default_factory=tuple)

    def error_at(self, slip: float) -> tuple[float, float]:
        """(e_g, e_im) of this truncation up to ``slip`` (rad/s)."""
        if self.kind is None or self.n == 0:
            return 0.0, 0.0
        return modal_error(self.kind, self.radius, self.sigma, self.thickness, self.n, self.tail, slip)


def mode_plan(scene, T: Optional[float] = None, attitude: bool = True, quiet: bool = False,
              reach: Optional[float] = None) -> ModePlan:
    """The eddy modes a run of ``scene`` over T s (default: its duration) carries, for its ``accuracy``
    (:func:`choose_modes`, :func:`mode_tolerances`); ``attitude``: whether the attitude is integrated (its
    tolerance then bounds the Im part's error); ``reach``: :func:`spin_reach` of the scene over T where the caller
    has it (rad/s). Warns (:class:`AccuracyWarning`) where an explicit ``modes:``, or :data:`MAX_MODES`, misses
    the tolerance."""
    T = float(scene.duration if T is None else T)
    cond = scene.rotor.conductor
    acc = scene.accuracy
    om = spin_reach(scene, T) if reach is None else reach
    slip = field_rates(scene) + om  # (slip_bound, without a second spin_reach)
    tol_g, tol_im = mode_tolerances(acc.rtol, acc.attitude if attitude else None, om, T)
    att_text = "none" if acc.attitude is None else f"{acc.attitude:g} rad"
    if cond is None or scene.torque_model != "lag" or scene.effects.magnetizable is not None:
        return ModePlan(0, False, slip, tol_g, tol_im, 0.0, 0.0, False, True)  # (a magnetizable body: no modes)
    kind, r2, sig, h = cond.kind, float(cond.outer_radius), float(cond.conductivity), cond.thickness
    base = dict(kind=kind, radius=r2, sigma=sig, thickness=h)
    if kind == "thin_shell":
        return ModePlan(1, False, slip, tol_g, tol_im, 0.0, 0.0, scene.modes is not None, True, **base)
    if is_legacy():
        n = int(scene.modes or LEGACY_MODES)
        e_g, e_im = modal_error(kind, r2, sig, h, n, True, slip)
        return ModePlan(n, True, slip, tol_g, tol_im, e_g, e_im, True, e_g <= tol_g and e_im <= tol_im, **base)
    if scene.modes is not None:
        n = int(scene.modes)
        tail = best_tail(kind, r2, sig, h, n, slip)
        e_g, e_im = modal_error(kind, r2, sig, h, n, tail, slip)
        met = e_g <= tol_g and e_im <= tol_im
        if not met and not quiet:
            need = choose_modes(kind, r2, sig, h, slip, tol_g, tol_im)
            warn(f"scene {scene.name!r}: modes = {n} cannot meet accuracy (rtol {acc.rtol:g}, attitude "
                 f"{att_text}) up to the slip {slip:.4g} rad/s the run can meet: truncation error "
                 f"{e_g:.2g} of ĝ, {e_im:.2g} of Im ĝ against tolerances {tol_g:.2g}, {tol_im:.2g}; "
                 + (f"{need[0]} modes would" if need[4] else f"even {MAX_MODES} modes would not")
                 + " (leave modes out to let the run choose)")
        return ModePlan(n, tail, slip, tol_g, tol_im, e_g, e_im, True, met, **base)
    n, tail, e_g, e_im, met = choose_modes(kind, r2, sig, h, slip, tol_g, tol_im)
    if not met and not quiet:
        warn(f"scene {scene.name!r}: {MAX_MODES} eddy modes (the most a run carries) cannot meet accuracy (rtol "
             f"{acc.rtol:g}, attitude {att_text}) up to the slip {slip:.4g} rad/s: truncation error "
             f"{e_g:.2g} of ĝ, {e_im:.2g} of Im ĝ against {tol_g:.2g}, {tol_im:.2g}")
    return ModePlan(n, tail, slip, tol_g, tol_im, e_g, e_im, False, met, **base)


def scene_conductor(scene, T: Optional[float] = None, attitude: bool = True,
                    quiet: bool = False) -> Optional[ModalModel]:
    """The modal model a run of ``scene`` uses (:func:`mode_plan`), None without a conductor. A non-lag torque model
    gets the conductor's model with its exact τ_eff (k_e does not depend on the modes)."""
    cond = scene.rotor.conductor
    if cond is None:
        return None
    if scene.torque_model != "lag":
        n = 1
        return truncated_model(cond.kind, cond.outer_radius, cond.conductivity, cond.thickness, n, True)
    plan = mode_plan(scene, T, attitude, quiet=quiet)
    return truncated_model(cond.kind, cond.outer_radius, cond.conductivity, cond.thickness, plan.n, plan.tail)


# --------------------------------------------------------------------------------------------------
# steps
# --------------------------------------------------------------------------------------------------
#: error model of the turn-resolving steppers, for the plan a run starts with: over one turn of the fastest
#: rotation (spin or field; for the free stepper one turn of the body-frame motion of L) a step of 1/spt of the
#: turn leaves an error of about C spt^(−order) in L (relative) and in the attitude (rad); the run's error is the
#: number of turns times that (the spin phase error adds up). Constants: typical of the built-in scenes with each
#: stepper forced (docs/accuracy.md, "Calibration"); a run then corrects its knobs from its own error estimate
#: (:class:`ErrorControl`).
STEP_ERROR = {
    "lawson8": {"order": 8, "L": 1e-3, "q": 0.1},
    "etdrk4": {"order": 4, "L": 0.1, "q": 5.0},
    "free": {"order": 8, "L": 0.0, "q": 50.0},
}
#: frozen-flow step: the error per turn is about K ε² with ε = rate_change (second order in the step)
FROZEN_ERROR = {"L": 3e-6, "q": 0.1}
#: quasi-static flow step (gyro_sim/qs_flow.py): the error per turn is about K ε² with ε = rate_change, K the
#: frozen-flow step's: at equal rate_change its errors were never larger than the frozen-flow step's on the
#: quasi-static scenes (the same in L, far smaller in the attitude of a spin-up: third order there), docs/accuracy.md
QS_FLOW_ERROR = {"order": 2, "L": FROZEN_ERROR["L"], "q": FROZEN_ERROR["q"]}
#: the steppers whose knob is ``rate_change`` (the relative change of the body rate a step may make), not
#: ``steps_per_turn``
RATE_KNOB = frozenset({"frozen_flow", "qs_flow"})
#: the tightest attitude tolerance a plan takes, as a fraction of the spin phase Ω T the run can turn through
#: (rad): the run's phase holds to about 1e-14 of itself in double precision, and an error δ of L relative turns
#: into δ Ω T of phase; below this a run warns and plans at the floor (docs/accuracy.md)
PHASE_REL_MIN = 1e-12
#: a plan predicting more steps than this warns (minutes of CPU on the machines measured)
STEPS_WARN = 1e8
#: fewest steps per turn a plan takes (below, lawson8 and ETDRK4 leave their asymptotic range; docs/numerics.md)
SPT_MIN = {"lawson8": 8, "etdrk4": 16, "free": 8}
SPT_MAX = 100000  # the scene format's limit of steps_per_turn
#: largest rate_change a plan takes (frozen_flow; qs_flow, accurate with longer steps: its error is mostly third order)
RATE_CHANGE_MAX = 5e-4
QS_RATE_CHANGE_MAX = 1e-2
RATE_CHANGE_MIN = 1e-9


@dataclass(frozen=True)
class StepPlan:
    """The step knobs of a run (:func:`step_plan`): steps per turn of each turn-resolving stepper, the frozen-flow
    ``rate_change``, the turns they were chosen for (``turns``: of the fastest rotation over the run;
    ``free_turns``: of the free rotor's body-frame motion), the step tolerances (``tol_L`` relative, ``tol_q``
    rad; inf where the attitude is not integrated), which knobs the scene gave (``explicit``) and the quasi-static
    flow step's ``rate_change`` (``qs_rate_change``; the scene's ``rate_change`` where it gives one)."""

    steps_per_turn: dict
    rate_change: float
    turns: float
    free_turns: float
    tol_L: float
    tol_q: float
    explicit: frozenset = frozenset()
    qs_rate_change: float = RATE_CHANGE_MAX

    def knob(self, method: str) -> float:
        """The plan's knob of ``method``: ``rate_change`` (:data:`RATE_KNOB`) or ``steps_per_turn``."""
        if method == "qs_flow":
            return self.qs_rate_change
        return self.rate_change if method == "frozen_flow" else self.steps_per_turn[method]

    def predicted(self, method: str, knob: Optional[float] = None) -> tuple[float, float]:
        """(L, attitude) errors the model predicts for ``method`` at ``knob`` (default: the plan's)."""
        if method == "frozen_flow":
            eps = self.rate_change if knob is None else knob
            return FROZEN_ERROR["L"] * eps * eps * self.turns, FROZEN_ERROR["q"] * eps * eps * self.turns
        if method == "qs_flow":
            f = self.turns * (self.qs_rate_change if knob is None else knob) ** QS_FLOW_ERROR["order"]
            return QS_FLOW_ERROR["L"] * f, QS_FLOW_ERROR["q"] * f
        m = STEP_ERROR[method]
        spt = self.steps_per_turn[method] if knob is None else knob
        turns = self.free_turns if method == "free" else self.turns
        f = turns * float(spt) ** (-m["order"])
        return m["L"] * f, m["q"] * f


def _spt_for(method: str, turns: float, tol_L: float, tol_q: float) -> int:
    m = STEP_ERROR[method]
    need = SPT_MIN[method]
    for key, tol in (("L", tol_L), ("q", tol_q)):
        if m[key] > 0 and turns > 0 and math.isfinite(tol):
            need = max(need, math.ceil((turns * m[key] / tol) ** (1.0 / m["order"])))
    return int(min(need, SPT_MAX))


def _rate_change_for(turns: float, tol_L: float, tol_q: float) -> float:
    eps = RATE_CHANGE_MAX
    for key, tol in (("L", tol_L), ("q", tol_q)):
        if turns > 0 and math.isfinite(tol):
            eps = min(eps, math.sqrt(tol / (FROZEN_ERROR[key] * turns)))
    return max(eps, RATE_CHANGE_MIN)


def _qs_rate_change_for(turns: float, tol_L: float, tol_q: float) -> float:
    """The quasi-static flow step's rate_change for the tolerances by :data:`QS_FLOW_ERROR` (K ε^order per turn)."""
    eps = QS_RATE_CHANGE_MAX
    for key, tol in (("L", tol_L), ("q", tol_q)):
        if turns > 0 and math.isfinite(tol):
            eps = min(eps, (tol / (QS_FLOW_ERROR[key] * turns)) ** (1.0 / QS_FLOW_ERROR["order"]))
    return max(eps, RATE_CHANGE_MIN)


def step_plan(scene, T: float, attitude: bool, omega: float, omega_free: float) -> StepPlan:
    """The step knobs of a run of T s (:class:`StepPlan`) for the scene's ``accuracy`` (:data:`STEP_SHARE` of it):
    ``omega`` the fastest rate (rad/s) the field steppers resolve over the run, ``omega_free`` the free rotor's
    body-frame rate. Explicit ``integrator.steps_per_turn`` / ``rate_change`` win (the simulator warns where the
    model says they miss the tolerance, for the stepper it runs)."""
    acc = scene.accuracy
    tol_L = STEP_SHARE * acc.rtol
    # the attitude's absolute tolerance, at least PHASE_REL_MIN of the spin phase the run can turn through (double
    # precision holds the phase to ~1e-14 of itself at best: a tighter one is planned at that floor)
    tol_q = (STEP_SHARE * max(acc.attitude, PHASE_REL_MIN * omega * T) if attitude and acc.attitude is not None
             else math.inf)
    turns = omega * T / (2 * math.pi)
    free_turns = omega_free * T / (2 * math.pi)
    # an error of L made early turns the spin rate and the attitude drifts from then on: with L's error growing
    # through the run, half the attitude's budget allows an L error of tol_q / (Ω T) at the end
    plan_L = min(tol_L, tol_q / (omega * T)) if omega * T > 0 else tol_L
    spt = {m: _spt_for(m, free_turns if m == "free" else turns, plan_L, 0.5 * tol_q) for m in STEP_ERROR}
    eps = _rate_change_for(turns, plan_L, 0.5 * tol_q)
    eps_qs = _qs_rate_change_for(turns, plan_L, 0.5 * tol_q)
    integ = scene.integrator
    explicit = set()
    if is_legacy():
        spt, eps = dict(LEGACY_STEPS_PER_TURN), LEGACY_RATE_CHANGE
        eps_qs = eps
        explicit.add("legacy")
    if integ.steps_per_turn is not None:
        spt = {m: int(integ.steps_per_turn) for m in spt}
        explicit.add("steps_per_turn")
    if integ.rate_change is not None:
        eps = eps_qs = float(integ.rate_change)
        explicit.add("rate_change")
    return StepPlan(spt, eps, turns, free_turns, tol_L, tol_q, frozenset(explicit), qs_rate_change=eps_qs)


def auto_plan(plan: StepPlan, scene) -> StepPlan:
    """The plan at the accuracy's own knobs (explicit knobs left out): what ``method: auto`` decides the stepper
    by (the choice follows the physics and the tolerance; the scene's knobs then set the chosen stepper's
    accuracy)."""
    if not plan.explicit or "legacy" in plan.explicit:
        return plan if "legacy" not in plan.explicit else StepPlan(
            dict(LEGACY_STEPS_PER_TURN), LEGACY_RATE_CHANGE, plan.turns, plan.free_turns, plan.tol_L, plan.tol_q,
            plan.explicit, qs_rate_change=LEGACY_RATE_CHANGE)
    omT = plan.turns * 2 * math.pi
    plan_L = min(plan.tol_L, plan.tol_q / omT) if omT > 0 else plan.tol_L
    tol = (plan_L, 0.5 * plan.tol_q)
    spt = {m: _spt_for(m, plan.free_turns if m == "free" else plan.turns, *tol) for m in STEP_ERROR}
    return StepPlan(spt, _rate_change_for(plan.turns, *tol), plan.turns, plan.free_turns, plan.tol_L, plan.tol_q,
                    qs_rate_change=_qs_rate_change_for(plan.turns, *tol))


# --------------------------------------------------------------------------------------------------
# the run's error: estimate and control
# --------------------------------------------------------------------------------------------------
#: order of each stepper (Richardson: the error of a run is its difference from a run with steps R times longer
#: over R^p − 1); the free stepper of an axisymmetric or spherical body is exact
ORDER = {"lawson8": 8, "etdrk4": 4, "frozen_flow": 2, "free": 8, "qs_flow": 1}
#: qs_flow (gyro_sim/qs_flow.py) converges at second to third order, but not monotonically: its error terms beat with
#: the field's ripple (f h mod 2π), and the ratio of its errors at 2h and h measured 1.3 to 13 (docs/accuracy.md);
#: its stretches are estimated at order 1 (the run's difference from its shadow), as the stiff ETDRK4's below.
#: ETDRK4 with steps longer than the fastest eddy mode's τ (a stiff step) is far from its order 4: measured on
#: constant_field (τ = 0.26 ms) its error falls as h^1.4 to h^2 for h from 8 τ to 2 τ (order reduction; Hochbruck &
#: Ostermann 2005), and the Richardson estimate at order 4 was 6 to 10 times too small. Its stretches are estimated
#: at order 1 (d/(R − 1): the run's difference from its shadow, an upper bound while the error falls with the step)
STIFF_ORDER = 1
STIFF = "etdrk4 (stiff)"
#: how much longer the shadow run's steps are, per stepper (its cost: 1/R of the run's)
SHADOW_RATIO = {"lawson8": 2.0, "etdrk4": 2.0, "frozen_flow": 4.0, "free": 2.0, "qs_flow": 2.0}
#: the instants (fractions of the duration) where a run compares itself with its shadow and may change its step:
#: early ones catch a plan far off, then every 1/16
CHECKS = tuple(2.0 ** -k for k in range(12, 4, -1)) + tuple(k / 16 for k in range(1, 16))
#: least ratio of the run's steps to the shadow's over a stepper's stretches for their difference to measure it
R_MEASURABLE = 1.3
#: the step share of the tolerance a run aims its projected error at (a margin for the estimate's own error)
AIM = 0.5
#: a run refines its step by at most this factor at a check, coarsens it by at most COARSEN, and keeps its step
#: within [1/MAX_COARSE, MAX_REFINE] of the plan's
REFINE_MAX = 4.0
#: at the early checks (before T/16) the step is made shorter only where the projected new error is this many times
#: the budget, by at most REFINE_MAX_EARLY: they project a short stretch over the whole run
EARLY_RHO = 4.0
REFINE_MAX_EARLY = 2.0
COARSEN = 2.0
MAX_COARSE = 8.0
MAX_REFINE = 1e4


@dataclass
class ErrorEstimate:
    """A run's estimated error over its whole duration (what ``RunResult.error_estimate`` holds).

    ``L``: relative error of L (max over the run of |ΔL| / max |L|); ``attitude``: rad (NaN where the attitude is
    not a result: not integrated, or averaged out). Each is the sum of its parts: ``steps_*`` (the steps: a
    Richardson estimate from the shadow run, ``steps_method`` 'richardson', or the step plan's error model where
    no shadow ran, 'model'), ``modes_*`` (the eddy modes' truncation bound at the largest slip met) and
    ``averaged_L`` (the averaged models' O(ε), fidelity auto/averaged). ``rtol``/``atol``: the scene's tolerances.
    """

    L: float
    attitude: float
    steps_L: float
    steps_attitude: float
    modes_L: float
    modes_attitude: float
    averaged_L: float
    steps_method: str
    rtol: float
    atol: float

    @property
    def met(self) -> bool:
        """Whether the estimate is within the scene's accuracy."""
        return self.L <= self.rtol and not (self.attitude > self.atol)  # (atol NaN: no attitude tolerance)

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in ("L", "attitude", "steps_L", "steps_attitude", "modes_L",
                                              "modes_attitude", "averaged_L", "steps_method", "rtol", "atol")} | {
            "met": self.met}

    def to_json(self) -> str:
        """The estimate as one line of JSON (NaN as null): the bag's custom_data ``gyro_sim.error_estimate``."""
        import json

        return json.dumps({k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                           for k, v in self.as_dict().items()}, separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str) -> "ErrorEstimate":
        import json

        d = json.loads(text)
        keys = ("L", "attitude", "steps_L", "steps_attitude", "modes_L", "modes_attitude", "averaged_L",
                "steps_method", "rtol", "atol")
        return cls(**{k: (math.nan if d.get(k) is None else d[k]) for k in keys})

    def text(self) -> str:
        """One line: ``L 3.1e-07 (rtol 1e-06), attitude 2.2e-07 rad (1e-06)``."""
        att = ("not a result" if not math.isfinite(self.attitude) else f"{self.attitude:.2g} rad"
               + (f" ({self.atol:g})" if math.isfinite(self.atol) else ""))
        return (f"L {self.L:.2g} (rtol {self.rtol:g}), attitude {att}"
                + ("" if self.met else ", beyond the scene's accuracy"))


class ErrorControl:
    """The error estimate of a run and the control of its step (:class:`gyro_sim.simulate.Runner` drives it).

    A shadow run (the same scene, same commands, same stops, steps :data:`SHADOW_RATIO` times longer) goes along;
    at the check instants (:data:`CHECKS` of the horizon: breaks of every run, in-process and in the ROS node, so
    both decide alike) their difference gives the run's error (Richardson: d/(R^p − 1), R^p − 1 averaged over the
    steppers used, weighted by their steps). Errors of L and of the attitude are running maxima.

    Control: an error made in L persists and, through the spin rate, makes the attitude drift at |ΔL|/J_min from
    then on; no later step undoes it. So the projection to the end is (present error) + (drift of the present L
    error) × (time left) + (new error: the growth since the previous check that the drift does not explain,
    and the drift the new L error will start) — and only the new error is the step's to change: the step is made
    longer or shorter (by up to :data:`COARSEN` / :data:`REFINE_MAX` a check) so that it fills the budget left
    (:data:`AIM` of the step share less what is committed). Explicit knobs are not changed (they win), only
    estimated.
    """

    def __init__(self, plan: StepPlan, attitude: bool, T: float, adapt: bool, J_min: float = 1.0,
                 L_bound: float = 0.0):
        self.plan, self.attitude, self.T, self.adapt, self.J_min = plan, attitude, T, adapt, J_min
        self.L_bound = L_bound  # the largest |L| the run can reach (N m s): the scale of L's relative error ahead
        self.checks = np.array(sorted({float(T * f) for f in CHECKS if 0 < T * f < T}))
        self.dL = 0.0  # largest error of L (N m s)
        self.e_q = 0.0  # rad
        self.L_max = 0.0
        self.weights: dict = {}  # steps of each (inexact) stepper
        self.shadow_steps: dict = {}  # the shadow's steps over the same stretches
        self.prev = None  # (t, |ΔL| now, attitude error now, error of |L| now) at the previous check
        self.dLn = 0.0
        self.banked = (0.0, 0.0)  # errors before a re-sync (fidelity hand-overs)
        self.history: list = []  # (t, e_L, e_q, step_div) at each check

    @property
    def denom(self) -> float:
        """r^p − 1 of the run: r the ratio of the run's steps to the shadow's over the stretches of each stepper
        (SHADOW_RATIO where steps are not cut by stops, more where the run's stops cut its steps and the shadow's
        do not), harmonically weighted by the run's steps (inf: only exact steps)."""
        n = sum(self.weights.values())
        if not n:
            return math.inf
        acc, n = 0.0, 0
        for m, k in self.weights.items():
            r = k / max(self.shadow_steps.get(m, k), 1)
            if r >= R_MEASURABLE:  # (where the shadow took the same steps its difference says nothing)
                acc += k / (r ** ORDER.get(m, STIFF_ORDER) - 1.0)
                n += k
        return n / acc if acc > 0 else math.inf

    def note_method(self, method: str, steps: int, shadow_steps: int, exact: bool = False,
                    stiff: bool = False) -> None:
        """Count a stretch's steps (run and shadow) for the Richardson denominator; ``stiff``: an ETDRK4 stretch
        with steps longer than the fastest mode's τ (:data:`STIFF_ORDER`)."""
        if stiff and method == "etdrk4":
            method = STIFF
        if not exact and steps:
            self.weights[method] = self.weights.get(method, 0) + steps
            self.shadow_steps[method] = self.shadow_steps.get(method, 0) + shadow_steps

    @property
    def e_L(self) -> float:
        """Relative error of L so far: the largest |ΔL| over the largest |L| seen."""
        return self.dL / self.L_max if self.L_max > 0 else 0.0

    def note_L(self, L_norm: float) -> None:
        self.L_max = max(self.L_max, L_norm)

    def _now(self, main, shadow) -> tuple[float, float]:
        """(|ΔL| N m s, attitude error rad) of the run now from its difference with the shadow; ``self.dLn``: the
        error of |L| (what turns the spin rate: the attitude drifts at it over J)."""
        den = self.denom
        if not math.isfinite(den):
            self.dLn = 0.0
            return 0.0, 0.0
        self.dLn = abs(float(np.linalg.norm(main.y[0:3])) - float(np.linalg.norm(shadow.y[0:3]))) / den
        dL = float(np.linalg.norm(main.y[0:3] - shadow.y[0:3])) / den
        dq = 0.0
        if self.attitude:
            q, qs = main.y[3:7], shadow.y[3:7]
            d = min(float(np.linalg.norm(q - qs)), float(np.linalg.norm(q + qs)))
            dq = 4.0 * math.asin(min(1.0, 0.5 * d)) / den
        return dL, dq

    def measure(self, main, shadow) -> tuple[float, float, float, float]:
        """Update the running maxima; returns (|ΔL| now, attitude error now, e_L, e_q)."""
        self.L_max = max(self.L_max, float(np.linalg.norm(main.y[0:3])))
        dL, dq = self._now(main, shadow)
        self.dL = max(self.dL, self.banked[0] + dL)
        self.e_q = max(self.e_q, self.banked[1] + dq)
        return dL, dq, self.e_L, self.e_q

    def bank(self) -> None:
        """Keep the errors so far (the shadow is about to be set to the run's state: a fidelity hand-over)."""
        self.banked = (self.dL, self.e_q)
        self.prev = None
        self.dLn = 0.0

    def coarsest(self, main, method: str) -> float:
        """The least step_div the stepper may take: its knob no coarser than SPT_MIN / RATE_CHANGE_MAX."""
        if method == "frozen_flow":  # (its shadow's knob SHADOW_RATIO times coarser: still in the asymptotic range)
            return self.plan.rate_change / RATE_CHANGE_MAX
        if method == "qs_flow":
            return SHADOW_RATIO[method] * self.plan.qs_rate_change / QS_RATE_CHANGE_MAX
        div = 1.0
        if method in SPT_MIN:
            div = SHADOW_RATIO[method] * SPT_MIN[method] / self.plan.steps_per_turn[method]
        if method == "lawson8" and main.tau.size:  # the shadow's lawson8 step too within 2 τ_min (its order holds)
            div = max(div, SHADOW_RATIO[method] * main._h_for("lawson8") / (2.0 * main.tau_min))
        return div

    def check(self, t: float, main, shadow, method: str, torque_now: float = 1.0, torque_mean: float = 1.0,
              measurable: bool = True) -> Optional[float]:
        """At a check instant: measure, and return the factor to divide the step by (None: unchanged).
        ``torque_now`` / ``torque_mean``: |N| now and its mean since the previous check (errors are made in
        proportion to the torque: the growth ahead is projected at today's torque); ``measurable``: whether the
        shadow's steps were longer than the run's since the previous check (else the error made was not seen, and
        the step is not made longer)."""
        dL, dq, e_L, e_q = self.measure(main, shadow)
        dLn = self.dLn
        self.history.append((t, e_L, e_q, main.step_div))
        t0, dL0, dq0, dLn0 = self.prev if self.prev is not None else (0.0, 0.0, 0.0, 0.0)
        self.prev = (t, dL, dq, dLn)
        if not self.adapt or method not in ORDER or t <= t0:
            return None
        if not measurable:  # back to a step the shadow can measure against (never coarser here)
            return 1.0 / main.step_div if main.step_div < 1.0 else None
        plan, left = self.plan, self.T - t
        L_ref = max(self.L_max, self.L_bound, 1e-300)
        scale = min(torque_now / torque_mean, 1.0) if torque_mean > 0 else 1.0
        # L: what is made and what the steps will add at the present rate
        rate_L = scale * max(dL - dL0, 0.0) / (t - t0)
        new = [rate_L * left / L_ref / plan.tol_L]
        room = [max(AIM - self.dL / L_ref / plan.tol_L, 0.1 * AIM)]
        if self.attitude and math.isfinite(plan.tol_q):
            # the error of |L| turns the spin rate: the attitude drifts at it over J from now on
            drift, drift0 = dLn / self.J_min, dLn0 / self.J_min
            rate_Ln = scale * max(dLn - dLn0, 0.0) / (t - t0)
            committed = e_q + drift * left
            # growth of the attitude error beyond the drift of the L error there was (the steps' own phase error)
            rate_q = scale * max((dq - dq0) / (t - t0) - 0.5 * (drift + drift0), 0.0)
            new.append((rate_q * left + rate_Ln / self.J_min * 0.5 * left * left) / plan.tol_q)
            room.append(max(AIM - committed / plan.tol_q, 0.1 * AIM))
        rho = max(n / r for n, r in zip(new, room))
        settled = all(r > 0.1 * AIM for r in room)  # (no longer steps once the budget is spent)
        p = ORDER[method]
        early = t < self.T / 16 * (1 - 1e-12)
        if rho > (EARLY_RHO if early else 1.0):  # (early checks project a short stretch far: they act on more)
            f = min(REFINE_MAX_EARLY if early else REFINE_MAX, (rho / 0.6) ** (1.0 / p))
        elif rho < 0.3 and settled and not early:  # (coarser only on the regular checks' evidence)
            f = max(1.0 / COARSEN, (max(rho, 1e-300) / 0.6) ** (1.0 / p))
        else:
            return None
        div = min(MAX_REFINE, max(1.0 / MAX_COARSE, self.coarsest(main, method), main.step_div * f))
        return None if div == main.step_div else div / main.step_div
