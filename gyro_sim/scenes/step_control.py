"""The step knobs of each stepper from the tolerance, the error estimate of a run and its error control (the
shadow run's comparison at fixed checks; :mod:`gyro_sim.scenes.accuracy`, docs/accuracy.md)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from gyro_sim.physics.frames import attitude_split_one, norm3
from gyro_sim.scenes.scene_text import SceneError
from gyro_sim.scenes.tolerance import (LEGACY_RATE_CHANGE, LEGACY_STEPS_PER_TURN, STEP_SHARE, has_symmetry_axis,
                                      is_legacy, phase_tolerance, planning_attitude)

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
FROZEN_ERROR = {"L": 3e-6, "q": 1e-2}
#: quasi-static flow step (gyro_sim/compiled/qs_flow.py): the error per turn is about K ε² with ε = rate_change, K the
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
#: a run whose plan predicts more work than this (steps, plus its output samples and controller ticks: each is a
#: stop of the stepper) is refused before it starts, in one line saying what to loosen (gyro_sim.engine.budget;
#: ``gyro-sim run --force`` / ``run(scene, force=True)`` runs it anyway). 1e9 steps are about 1.5 to 3 CPU-hours
#: at the 5 to 10 µs a step of the built-in scenes (the shadow run of the error control included): a plan beyond
#: it is a tolerance or a duration asked by mistake far more often than a run someone means to wait for (the
#: default scene over 30 000 s at its default accuracy plans 1.7e9 steps; with ``accuracy.attitude: null``, 4e6)
STEP_BUDGET = 1e9

#: fewest steps per turn a plan takes (below, lawson8 and ETDRK4 leave their asymptotic range; docs/numerics.md)
SPT_MIN = {"lawson8": 8, "etdrk4": 16, "free": 8}
SPT_MAX = 100000  # the scene format's limit of steps_per_turn
#: largest rate_change a plan takes (frozen_flow; qs_flow, accurate with longer steps: its error is mostly third order)
RATE_CHANGE_MAX = 2e-4
#: largest rate_change the error control takes the frozen-flow step to from what it measures (the plan stays at
#: RATE_CHANGE_MAX: the plan's error model is a typical scene's, and ``auto`` chooses the stepper by it; at 1e-9
#: constant_field's frozen-flow errors were 100x the model's at 5e-4). The shadow's steps, SHADOW_RATIO (2) times
#: longer, stay where the error falls with the step (docs/accuracy.md, "Floors")
RATE_CHANGE_CONTROL_MAX = 5e-4
QS_RATE_CHANGE_MAX = 1e-2
RATE_CHANGE_MIN = 1e-9


class StepBudgetError(SceneError):
    """A run refused before it starts: its plan exceeds :data:`STEP_BUDGET` (the message, one line, says what to
    loosen). ``planned``: the work the plan predicts (steps), ``budget``: the budget it exceeds."""

    def __init__(self, message: str, planned: float = math.nan, budget: float = STEP_BUDGET):
        super().__init__(message)
        self.planned, self.budget = float(planned), float(budget)


@dataclass(frozen=True)
class StepPlan:
    """The step knobs of a run (:func:`step_plan`): steps per turn of each turn-resolving stepper, the frozen-flow
    ``rate_change``, the turns they were chosen for (``turns``: of the fastest rotation over the run;
    ``free_turns``: of the free rotor's body-frame motion), the step tolerances (``tol_L`` relative, ``tol_q``
    rad; inf where the attitude is not integrated), which knobs the scene gave (``explicit``) and the quasi-static
    flow step's ``rate_change`` (``qs_rate_change``; the scene's ``rate_change`` where it gives one). ``tol_q`` is
    the directions' tolerance (the symmetry axis; the whole attitude without one), ``tol_p`` the spin phase's,
    ``plan_q`` what the error models of the phases are planned for."""

    steps_per_turn: dict
    rate_change: float
    turns: float
    free_turns: float
    tol_L: float
    tol_q: float
    explicit: frozenset = frozenset()
    qs_rate_change: float = RATE_CHANGE_MAX
    #: the spin phase's tolerance (rad, absolute, the step share; inf: none or no symmetry axis)
    tol_p: float = math.inf
    #: the tolerance the steppers' phase error models are planned for (rad; :func:`planning_attitude`)
    plan_q: float = math.inf

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


def _plan_tolerances(scene, T: float, attitude: bool, omega: float) -> tuple[float, float, float, float]:
    """(tol_L, tol_q, tol_p, plan_q) of a plan (:data:`STEP_SHARE` of each tolerance): L relative, the directions
    (rad), the spin phase (rad, absolute over the run) and the phases' planning tolerance (rad; at least
    :data:`PHASE_REL_MIN` of the phase the run can turn through: double precision holds a phase to ~1e-14 of
    itself at best)."""
    acc = scene.accuracy
    tol_L = STEP_SHARE * acc.rtol
    if not attitude:
        return tol_L, math.inf, math.inf, math.inf
    floor = PHASE_REL_MIN * omega * T
    sym = has_symmetry_axis(scene.rotor.inertia)
    # (the directions of an axisymmetric body are its axis' cone about L, no phase: no floor)
    tol_q = math.inf if acc.attitude is None else STEP_SHARE * max(acc.attitude, 0.0 if sym else floor)
    tol_p = STEP_SHARE * max(phase_tolerance(acc, omega, T), floor) if sym else math.inf
    plan_q = STEP_SHARE * max(planning_attitude(scene, omega, T), floor)
    return tol_L, tol_q, tol_p, plan_q


def _plan_L(tol_L: float, tol_q: float, tol_p: float, omega: float, T: float, sym: bool) -> float:
    """L's tolerance for the plan: an error δ of |L| turns the spin rate by δ of itself, and the phase drifts by δ
    Ω T over the run: the spin phase's tolerance over Ω T (a relative phase tolerance: itself, whatever T). Without
    a symmetry axis the whole attitude drifts so: tol_q over Ω T. The directions of an axisymmetric body drift by
    sin θ of its precession phase: the error control follows that from the θ it meets."""
    if not omega * T > 0:
        return tol_L
    return min(tol_L, (tol_p if sym else tol_q) / (omega * T))


def step_plan(scene, T: float, attitude: bool, omega: float, omega_free: float) -> StepPlan:
    """The step knobs of a run of T s (:class:`StepPlan`) for the scene's ``accuracy`` (:data:`STEP_SHARE` of it):
    ``omega`` the fastest rate (rad/s) the field steppers resolve over the run, ``omega_free`` the free rotor's
    body-frame rate. Explicit ``integrator.steps_per_turn`` / ``rate_change`` win (the simulator warns where the
    model says they miss the tolerance, for the stepper it runs)."""
    tol_L, tol_q, tol_p, plan_q = _plan_tolerances(scene, T, attitude, omega)
    sym = has_symmetry_axis(scene.rotor.inertia)
    turns = omega * T / (2 * math.pi)
    free_turns = omega_free * T / (2 * math.pi)
    plan_L = _plan_L(tol_L, tol_q, tol_p, omega, T, sym)
    spt = {m: _spt_for(m, free_turns if m == "free" else turns, plan_L, 0.5 * plan_q) for m in STEP_ERROR}
    eps = _rate_change_for(turns, plan_L, 0.5 * plan_q)
    eps_qs = _qs_rate_change_for(turns, plan_L, 0.5 * plan_q)
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
    return StepPlan(spt, eps, turns, free_turns, tol_L, tol_q, frozenset(explicit), qs_rate_change=eps_qs,
                    tol_p=tol_p, plan_q=plan_q)


def auto_plan(plan: StepPlan, scene) -> StepPlan:
    """The plan at the accuracy's own knobs (explicit knobs left out): what ``method: auto`` decides the stepper
    by (the choice follows the physics and the tolerance; the scene's knobs then set the chosen stepper's
    accuracy)."""
    if not plan.explicit or "legacy" in plan.explicit:
        return plan if "legacy" not in plan.explicit else StepPlan(
            dict(LEGACY_STEPS_PER_TURN), LEGACY_RATE_CHANGE, plan.turns, plan.free_turns, plan.tol_L, plan.tol_q,
            plan.explicit, qs_rate_change=LEGACY_RATE_CHANGE, tol_p=plan.tol_p, plan_q=plan.plan_q)
    omT = plan.turns * 2 * math.pi
    plan_L = _plan_L(plan.tol_L, plan.tol_q, plan.tol_p, omT, 1.0, has_symmetry_axis(scene.rotor.inertia))
    tol = (plan_L, 0.5 * plan.plan_q)
    spt = {m: _spt_for(m, plan.free_turns if m == "free" else plan.turns, *tol) for m in STEP_ERROR}
    return StepPlan(spt, _rate_change_for(plan.turns, *tol), plan.turns, plan.free_turns, plan.tol_L, plan.tol_q,
                    qs_rate_change=_qs_rate_change_for(plan.turns, *tol), tol_p=plan.tol_p, plan_q=plan.plan_q)


# --------------------------------------------------------------------------------------------------
# the run's error: estimate and control
# --------------------------------------------------------------------------------------------------
#: order of each stepper (Richardson: the error of a run is its difference from a run with steps R times longer
#: over R^p − 1); the free stepper of an axisymmetric or spherical body is exact
ORDER = {"lawson8": 8, "etdrk4": 4, "frozen_flow": 1, "free": 8, "qs_flow": 1}
#: qs_flow (gyro_sim/compiled/qs_flow.py) converges at second to third order, but not monotonically: its error terms
#: beat with the field's ripple (f h mod 2π), and the ratio of its errors at 2h and h measured 1.3 to 13
#: (docs/accuracy.md); its stretches are estimated at order 1 (the run's difference from its shadow), as the stiff
#: ETDRK4's below.
#: ETDRK4 with steps longer than the fastest eddy mode's τ (a stiff step) is far from its order 4: measured on
#: constant_field (τ = 0.26 ms) its error falls as h^1.4 to h^2 for h from 8 τ to 2 τ (order reduction; Hochbruck &
#: Ostermann 2005), and the Richardson estimate at order 4 was 6 to 10 times too small. Its stretches are estimated
#: at order 1 (d/(R − 1): the run's difference from its shadow, an upper bound while the error falls with the step)
STIFF_ORDER = 1
STIFF = "etdrk4 (stiff)"
#: the estimate's order of a stepper's stretches whose shadow takes fewer than SPT_MIN steps per turn (the error
#: control lets it down to SPT_MIN / SHADOW_RATIO, ErrorControl.coarsest): between 8 and 4 steps per turn lawson8's
#: error fell as h^7.3 on drift_sources and reorient_L, h^7 on phase_portrait (h^8.7 on three_stators), and
#: d/(2^8 − 1) was 1.6x below drift_sources' true L error; below the least measured, with a margin (docs/accuracy.md,
#: "Floors"). The step control keeps ORDER (its decisions as they were)
COARSE_ORDER = {"lawson8": 6.5}
#: the estimate's order of the free stepper's stretches (a triaxial rotor's: the axisymmetric one's are exact), whose
#: shadow takes 8 to 16 steps a turn (ErrorControl.coarsest): on free_rotor its error fell as h^7.59 from 8 to 16
#: steps a turn (5.58e-5 against 2.90e-7 rad over 10 s, the same ratio over 40 s) and as h^7.95 from 16 to 32, so
#: d/(2^8 − 1) was 0.75 of the run's error there, and the runs' estimates 0.94 (40 s) and 0.98 (100 s) of it at 1 Hz
#: output; below the least measured, with a margin, as COARSE_ORDER. The step control keeps ORDER
ESTIMATE_ORDER = {"free": 7.0}
#: how much longer the shadow run's steps are, per stepper (its cost: 1/R of the run's)
SHADOW_RATIO = {"lawson8": 2.0, "etdrk4": 2.0, "frozen_flow": 2.0, "free": 2.0, "qs_flow": 2.0}
#: the instants (fractions of the duration) where a run compares itself with its shadow and may change its step:
#: early ones catch a plan far off, then every 1/16
CHECKS = tuple(2.0 ** -k for k in range(12, 4, -1)) + tuple(k / 16 for k in range(1, 16))
#: least ratio of the run's steps to the shadow's over a stepper's stretches for their difference to measure it
R_MEASURABLE = 1.3
#: where stops closer than the run's step cut the shadow's steps as they cut the run's (commands every 0.5 ms), the
#: shadow follows that stretch with steps this many times shorter than the run's instead (step doubling, the run the
#: coarser: the difference is the run's error less 1/FINER^p of it; ErrorEstimator.sync_shadow)
FINER = 2.0
#: ... and with steps at most this many τ_min (the fastest eddy mode's time constant) where the run's steps there are
#: longer: a step across a field switch spans the modes' transient, and beyond ~τ the frozen-flow step's error is not
#: a power of its step (z3 spin field on/off every 0.5 ms, τ 0.26 ms, one 0.5 ms step a stretch: its error over 1,
#: 2, 3, 4, 8 steps a stretch 9.5, 8.7, 4.3, 2.5, 0.65e-12, h² only from 3 steps on): the shadow at half the run's
#: step erred 0.91 of the run and the estimate was 1.2x below the true L error. At τ_min/4 its error is below
#: 1/F of the run's (F its ratio to the run's steps), which the denominator 1 − F^−p (p ≥ 1) needs
FINER_TAU = 0.25
#: the step share of the tolerance a run aims its projected error at (a margin for the estimate's own error)
AIM = 0.5
#: a run refines its step by at most this factor at a check, coarsens it by at most COARSEN, and keeps its step
#: within [1/MAX_COARSE, MAX_REFINE] of the plan's
REFINE_MAX = 2.0
#: at the early checks (before T/16) the step is made shorter only where the projected new error is this many times
#: the budget, by at most REFINE_MAX_EARLY: they project a short stretch over the whole run
EARLY_RHO = 4.0
REFINE_MAX_EARLY = 2.0
COARSEN = 2.0
#: a refinement whose next check shows the projected error above this fraction of the one before did not pay: the
#: control refines no further there (the growth is not the steps'); an early check undoes it where the growth rose as
#: many times as the step was shortened, or more (ErrorControl.check)
REFINE_FUTILE = 0.7
#: the PI step control's exponents over the order (Gustafsson 1991; Hairer & Wanner II, IV.2: α = 0.7, β = 0.4)
PI_ALPHA = 0.7
PI_BETA = 0.4
MAX_COARSE = 8.0
MAX_REFINE = 64.0


_EST_KEYS = ("L", "attitude", "steps_L", "steps_attitude", "modes_L", "modes_attitude", "averaged_L", "steps_method",
             "rtol", "atol", "phase", "steps_phase", "modes_phase", "phase_tol", "round_off")
#: the keys every bag's estimate has (those after them came with the spin phase apart, issue 28: NaN where missing)
_EST_REQUIRED = _EST_KEYS[:10]


@dataclass
class ErrorEstimate:
    """A run's estimated error over its whole duration (what ``RunResult.error_estimate`` holds).

    ``L``: relative error of L (max over the run of |ΔL| / max |L|); ``attitude``: rad, the directions of the
    rotor's axes up to its spin about the symmetry axis (the whole attitude for a body without one); ``phase``:
    rad, the spin phase about the symmetry axis (NaN where the attitude is not a result: not integrated, or
    averaged out; the phase also without a symmetry axis). Each is the sum of its parts: ``steps_*`` (the steps:
    a Richardson estimate from the shadow run, ``steps_method`` 'richardson', or the step plan's error model where
    no shadow ran, 'model'), ``modes_*`` (the eddy modes' truncation bound at the largest slip met),
    ``averaged_L`` (the averaged models' O(ε), fidelity auto/averaged) and ``round_off`` (rad: the phases' floor in
    double precision, in ``attitude`` and ``phase``). ``rtol``/``atol``: the scene's tolerances; ``phase_tol`` the
    spin phase's in rad (``accuracy.phase`` × the phase turned, or ``phase_atol``).
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
    phase: float = math.nan
    steps_phase: float = math.nan
    modes_phase: float = math.nan
    phase_tol: float = math.nan
    round_off: float = 0.0

    @property
    def met(self) -> bool:
        """Whether the estimate is within the scene's accuracy."""
        return (self.L <= self.rtol and not (self.attitude > self.atol)  # (atol NaN: no attitude tolerance)
                and not (self.phase > self.phase_tol))

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in _EST_KEYS} | {"met": self.met}

    def to_json(self) -> str:
        """The estimate as one line of JSON (NaN as null): the bag's custom_data ``gyro_sim.error_estimate``."""
        import json

        return json.dumps({k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                           for k, v in self.as_dict().items()}, separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str) -> "ErrorEstimate":
        import json

        d = json.loads(text)
        return cls(**{k: (math.nan if d.get(k) is None else d[k]) for k in _EST_KEYS if k in d or k in _EST_REQUIRED})

    def text(self) -> str:
        """One line: ``L 3.1e-07 (rtol 1e-06), attitude 2.2e-07 rad (1e-06), spin phase 4e-06 rad (1.2e-04)``."""
        att = ("not a result" if not math.isfinite(self.attitude) else f"{self.attitude:.2g} rad"
               + (f" ({self.atol:g})" if math.isfinite(self.atol) else ""))
        ph = ""
        if math.isfinite(self.phase):
            ph = f", spin phase {self.phase:.2g} rad" + (f" ({self.phase_tol:.2g})" if math.isfinite(self.phase_tol)
                                                        else "")
        return (f"L {self.L:.2g} (rtol {self.rtol:g}), attitude {att}{ph}"
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
                 L_bound: float = 0.0, axis: int = -1, accuracy=None):
        self.plan, self.attitude, self.T, self.adapt, self.J_min = plan, attitude, T, adapt, J_min
        self.L_bound = L_bound  # the largest |L| the run can reach (N m s): the scale of L's relative error ahead
        self.axis = axis  # the body's symmetry axis (frames.symmetry_axis; −1: none, the whole attitude)
        self.accuracy = accuracy  # the scene's accuracy section (a relative phase tolerance follows the phase turned)
        self.checks = np.array(sorted({float(T * f) for f in CHECKS if 0 < T * f < T}))
        self.dL = 0.0  # largest error of L (N m s)
        self.e_q = 0.0  # directions, rad
        self.e_p = 0.0  # spin phase, rad
        self.L_max = 0.0
        self.weights: dict = {}  # steps of each (inexact) stepper
        self.shadow_steps: dict = {}  # the shadow's steps over the same stretches
        self.shadow_len: dict = {}  # the same, at least the run's over SHADOW_RATIO (the steps' lengths, note_method)
        self.coarse: dict = {}  # the run's steps of each stepper where its shadow was below SPT_MIN (COARSE_ORDER)
        # the run's steps of each stepper over the stretches the shadow followed finer, by (stepper, the ratio of the
        # run's steps to the shadow's there)
        self.finer: dict = {}
        self.est = (0.0, 0.0, 0.0)  # the estimate's running maxima (|ΔL|, directions, phase; denom_estimate)
        self.banked_est = (0.0, 0.0, 0.0)
        # (t, |ΔL|, direction error, phase error, error of |L|) now, at the previous check
        self.prev: Optional[tuple[float, float, float, float, float]] = None
        self.dLn = 0.0
        self.banked = (0.0, 0.0, 0.0)  # errors before a re-sync (fidelity hand-overs)
        self.history: list = []  # (t, e_L, e_q, e_p, step_div) at each check
        self.rho_prev: Optional[float] = None  # the last check's projected error over its budget (the PI control)
        self.div_prev: Optional[float] = None  # the step_div of the last check
        self.growth_prev: Optional[float] = None  # the errors' growth over their tolerances at the last check (1/s)

    @property
    def denom(self) -> float:
        """r^p − 1 of the run, as the step control takes it: r the ratio of the run's steps to the shadow's over the
        stretches of each stepper (SHADOW_RATIO where steps are not cut by stops, more where the run's stops cut its
        steps and the shadow's do not), harmonically weighted by the run's steps (inf: only exact steps)."""
        return self._denoms()[0]

    @property
    def denom_estimate(self) -> float:
        """r^p − 1 of the run as its error estimate takes it: r of the steps' lengths (:meth:`note_method`), at
        least R_MEASURABLE where the counts measure."""
        return self._denoms()[1]

    def _denoms(self) -> tuple[float, float]:
        """(:attr:`denom`, :attr:`denom_estimate`) in one pass over the stretches: r of the counts where the shadow
        measured (r ≥ R_MEASURABLE: where it took the same steps its difference says nothing), and for the estimate r
        of the steps' lengths (at least R_MEASURABLE); a stretch the shadow followed finer counts 1 − f^−p (the
        difference is the run's error less 1/f^p of it, f its steps' ratio to the run's there)."""
        if not (sum(self.weights.values()) + sum(self.finer.values())):
            return math.inf, math.inf
        acc, acc_e, n = 0.0, 0.0, 0
        shadow_steps, shadow_len = self.shadow_steps, self.shadow_len
        for m, k in self.weights.items():
            r = k / max(shadow_steps.get(m, k), 1)
            if r >= R_MEASURABLE:
                p = ORDER.get(m, STIFF_ORDER)
                acc += k / (r ** p - 1.0)
                r = max(min(r, k / max(shadow_len.get(m, k), 1)), R_MEASURABLE)
                kc = min(self.coarse.get(m, 0), k)
                pe = ESTIMATE_ORDER.get(m, p)
                acc_e += (k - kc) / (r ** pe - 1.0) + (kc / (r ** COARSE_ORDER[m] - 1.0) if kc else 0.0)
                n += k
        for (m, f), k in self.finer.items():
            x = k / (1.0 - f ** -ORDER.get(m, STIFF_ORDER))
            acc += x
            acc_e += x
            n += k
        return (n / acc if acc > 0 else math.inf), (n / acc_e if acc_e > 0 else math.inf)

    def note_method(self, method: str, steps: int, shadow_steps: int, exact: bool = False,
                    stiff: bool = False, finer: float = 0.0, finer_ratio: float = FINER, coarse: bool = False) -> None:
        """Count a stretch's steps (run and shadow) for the Richardson denominator; ``stiff``: an ETDRK4 stretch
        with steps longer than the fastest mode's τ (:data:`STIFF_ORDER`); ``finer``: a stretch the shadow
        followed with steps at most 1/:data:`FINER` of the run's (:meth:`ErrorEstimator.sync_shadow`), its value the
        error the run's steps there make against steps of the run's plan, (h / h_plan)^p ≤ 1: a stretch cut short (an
        early check, T/4096) weighs little beside the stretches of whole steps; ``finer_ratio``: how many times shorter
        the shadow's steps were there (:data:`FINER`, more where the run's steps are longer than :data:`FINER_TAU`
        τ_min); ``coarse``: the shadow's steps there were longer than SPT_MIN a turn (:data:`COARSE_ORDER`)."""
        # the estimate's r is of the steps' lengths, not of their counts: where the run's own stops (samples, ticks)
        # cut its steps it takes more than SHADOW_RATIO times the shadow's, but its longest steps, which make its
        # error, are still only SHADOW_RATIO times shorter than the shadow's (magnetizable_body: counts 3.3, r^8 − 1
        # 59x too large); the shadow's count is taken at least the run's over SHADOW_RATIO there. (The step control
        # keeps the counts: its decisions, and so the runs' results, as they were.)
        ratio = SHADOW_RATIO.get(method, 2.0)
        if stiff and method == "etdrk4":
            method = STIFF
        if not exact and steps and finer:
            w = max(min(finer, 1.0) ** ORDER.get(method, STIFF_ORDER), 1e-300)
            key = (method, finer_ratio)
            self.finer[key] = self.finer.get(key, 0) + steps * w
        elif not exact and steps:
            self.weights[method] = self.weights.get(method, 0) + steps
            self.shadow_steps[method] = self.shadow_steps.get(method, 0) + shadow_steps
            self.shadow_len[method] = self.shadow_len.get(method, 0) + max(shadow_steps, steps / ratio)
            if coarse and method in COARSE_ORDER:
                self.coarse[method] = self.coarse.get(method, 0) + steps

    @property
    def e_L(self) -> float:
        """Relative error of L so far: the largest |ΔL| over the largest |L| seen."""
        return self.dL / self.L_max if self.L_max > 0 else 0.0

    def note_L(self, L_norm: float) -> None:
        self.L_max = max(self.L_max, L_norm)

    def measure(self, main, shadow) -> tuple[float, float, float, float, float, float]:
        """Update the running maxima; returns (|ΔL|, direction error, phase error) now and (e_L, e_q, e_p)."""
        # (the raw differences (| |L| − |L_s| |, |L − L_s|, direction, phase; attitude_split_one) over the step
        # control's denominator and over the estimate's; self.dLn: the error of |L|, which turns the spin and
        # precession rates: the phases drift at it over J)
        y, ys = main.y, shadow.y
        L, Ls = y[0:3], ys[0:3]
        nL = norm3(L)
        self.L_max = max(self.L_max, nL)
        rLn = abs(nL - norm3(Ls))
        rq = rp = 0.0
        if self.attitude:
            a, b = y[0:7].tolist(), ys[0:7].tolist()
            rq, rp = attitude_split_one(a[3:7], b[3:7], self.axis, a[0:3], b[0:3])
        rL = norm3(L - Ls)
        den, den_e = self._denoms()
        if math.isfinite(den):
            dLn, dL, dq, dp = rLn / den, rL / den, rq / den, rp / den
        else:
            dLn, dL, dq, dp = 0.0, 0.0, 0.0, 0.0
        bk = self.banked
        self.dL = max(self.dL, bk[0] + dL)
        self.e_q = max(self.e_q, bk[1] + dq)
        self.e_p = max(self.e_p, bk[2] + dp)
        # the estimate's (denom_estimate): the same differences
        if math.isfinite(den_e):
            n0, n1, n2 = rL / den_e, rq / den_e, rp / den_e
        else:
            n0, n1, n2 = 0.0, 0.0, 0.0
        est, be = self.est, self.banked_est
        self.est = (max(est[0], be[0] + n0), max(est[1], be[1] + n1), max(est[2], be[2] + n2))
        self.dLn = dLn
        return dL, dq, dp, self.e_L, self.e_q, self.e_p

    def estimate(self) -> tuple[float, float, float]:
        """The steps' error so far as the estimate reports it: (L relative, directions rad, spin phase rad), the
        running maxima at :attr:`denom_estimate`."""
        return (self.est[0] / self.L_max if self.L_max > 0 else 0.0), self.est[1], self.est[2]

    def bank(self, t: float) -> None:
        """Keep the errors so far (the shadow is about to be set to the run's state at ``t`` s: a fidelity
        hand-over): the differences grow afresh from zero at ``t``, and the PI control's memory starts over."""
        self.banked = (self.dL, self.e_q, self.e_p)
        self.banked_est = self.est
        self.prev = (t, 0.0, 0.0, 0.0, 0.0)
        self.dLn = 0.0
        self.rho_prev = self.div_prev = self.growth_prev = None

    def coarsest(self, main, method: str) -> float:
        """The least step_div the stepper may take: its knob no coarser than SPT_MIN / RATE_CHANGE_CONTROL_MAX (the
        shadow's: lawson8's own, its shadow then down to SPT_MIN / SHADOW_RATIO, estimated at COARSE_ORDER)."""
        if method == "frozen_flow":  # (its shadow's knob SHADOW_RATIO times coarser: still in the asymptotic range)
            return self.plan.rate_change / RATE_CHANGE_CONTROL_MAX
        if method == "qs_flow":
            return SHADOW_RATIO[method] * self.plan.qs_rate_change / QS_RATE_CHANGE_MAX
        div = 1.0
        if method in SPT_MIN:
            div = (1.0 if method in COARSE_ORDER else SHADOW_RATIO[method]) * SPT_MIN[method] \
                / self.plan.steps_per_turn[method]
        if method == "lawson8" and main.tau.size:  # the shadow's lawson8 step too within 2 τ_min (its order holds)
            div = max(div, SHADOW_RATIO[method] * main._h_for("lawson8") / (2.0 * main.tau_min))
        return div

    def check(self, t: float, main, shadow, method: str, torque_now: float = 1.0, torque_mean: float = 1.0,
              measurable: bool = True, turned: Optional[float] = None) -> Optional[float]:
        """At a check instant: measure, and return the factor to divide the step by (None: unchanged).
        ``torque_now`` / ``torque_mean``: |N| now and its mean since the previous check (errors are made in
        proportion to the torque: the growth ahead is projected at today's torque); ``measurable``: whether the
        shadow's steps were longer than the run's since the previous check (else the error made was not seen, and
        the step is not made longer); ``turned``: the phase the run has turned so far (rad)."""
        dL, dq, dp, e_L, e_q, e_p = self.measure(main, shadow)
        dLn = self.dLn
        self.history.append((t, e_L, e_q, e_p, main.step_div))
        t0, dL0, dq0, dp0, dLn0 = self.prev if self.prev is not None else (0.0, 0.0, 0.0, 0.0, 0.0)
        self.prev = (t, dL, dq, dp, dLn)
        if not self.adapt or method not in ORDER or t <= t0:
            return None
        if not measurable and main.step_div < 1.0:  # back to a step the shadow can measure against
            return 1.0 / main.step_div
        plan, left = self.plan, self.T - t
        early = t < self.T / 16 * (1 - 1e-12)
        L_ref = max(self.L_max, self.L_bound, 1e-300)
        scale = min(torque_now / torque_mean, 1.0) if torque_mean > 0 else 1.0
        # L: what is made and what the steps will add at the present rate
        rate_L = scale * max(dL - dL0, 0.0) / (t - t0)
        new = [rate_L * left / L_ref / plan.tol_L]
        room = [max(AIM - self.dL / L_ref / plan.tol_L, 0.1 * AIM)]
        if self.attitude:
            # the error of |L| turns the spin and precession rates: the phases drift at it over J from now on (the
            # whole attitude without a symmetry axis; the cone of an axisymmetric rotor's axis does not drift so)
            rate_Ln = scale * max(dLn - dLn0, 0.0) / (t - t0)
            k_cone = 1.0 if self.axis < 0 else 0.0
            tol_p = plan.tol_p
            acc = self.accuracy
            if turned is not None and acc is not None and acc.phase_atol is None and math.isfinite(tol_p) and not early:
                # a relative phase tolerance follows the phase the run turns: so far, and ahead at today's rate (the
                # plan's took the fastest rate the run can reach over all of it; the early checks, where a spin-up
                # has turned little, keep the plan's)
                om_now = norm3(main.y[0:3]) / self.J_min
                tol_p = min(tol_p, STEP_SHARE * phase_tolerance(acc, 1.0, turned + om_now * left))
            for tol, e, d, d0, k in ((plan.tol_q, e_q, dq, dq0, k_cone), (tol_p, e_p, dp, dp0, 1.0)):
                if not math.isfinite(tol):
                    continue
                drift, drift0 = k * dLn / self.J_min, k * dLn0 / self.J_min
                committed = e + drift * left
                # growth beyond the drift of the L error there was (the steps' own phase error)
                rate = scale * max((d - d0) / (t - t0) - 0.5 * (drift + drift0), 0.0)
                # (the drift the new L error will start, quadratic in the time left, only on the regular checks'
                # evidence: early in a spin-up the error of |L| grows fast for a while and then stays)
                grow = 0.0 if early else k * rate_Ln / self.J_min * 0.5 * left * left
                new.append((rate * left + grow) / tol)
                room.append(max(AIM - committed / tol, 0.1 * AIM))
        rho = max(n / r for n, r in zip(new, room))
        settled = all(r > 0.1 * AIM for r in room)  # (no longer steps once the budget is spent)
        p = ORDER[method]
        rho_prev, self.rho_prev = self.rho_prev, rho
        # PI control (Gustafsson 1991; Hairer & Wanner, IV.2): the factor follows the error's ratio to its target
        # and, damped, its trend since the previous check, so a run does not swing between too long and too short
        pi = (rho / 0.6) ** (PI_ALPHA / p) * ((rho / rho_prev) ** (PI_BETA / p) if rho_prev and rho > 0 else 1.0)
        if not measurable:
            # the breaks cut the run's steps and the shadow's alike (ticks, commands): never coarser here, and where
            # the error grows beyond its budget shorter, until the run's steps are shorter than the breaks and the
            # shadow can measure again
            if rho <= 1.0 or early:
                return None
            div = min(MAX_REFINE, main.step_div * 2.0)
            return None if div == main.step_div else div / main.step_div
        refined = self.div_prev is not None and main.step_div > 1.5 * self.div_prev
        growth = max(new) / max(left, 1e-300)  # (the errors' growth per second over their tolerances)
        div_last, growth_prev = self.div_prev, self.growth_prev
        self.div_prev, self.growth_prev = main.step_div, growth
        # the last refinement did not bring the error's growth down: it is not the steps' (an early error of L
        # drifting the phases, a feedback law's switching). Steps r = step_div / div_last (≥ 1.5) times shorter make
        # the steps' own error grow r^p (p ≥ 1) times slower, at most 1/1.5 of what it did: a growth still above
        # REFINE_FUTILE of it was not made by the steps, and the control refines no further
        futile = refined and growth_prev is not None and growth > REFINE_FUTILE * growth_prev
        if futile and early and growth >= main.step_div / div_last * growth_prev:
            # an early check undoes the refinement (back to the step of the check before) where the growth rose at
            # least r times: as differences made step by step whatever the step's length do (the wobble of the
            # first steps), not as the steps' error (r^-p). The early checks project a short stretch over the whole
            # run, and the refinement was bought on such evidence alone; the regular checks (T/16 on) refine where
            # the error is the steps'. (Undone at r^-p < growth ratio < r, nutation_slow's spin-up refined again
            # later and took 9 % more steps; constant_field: its step, halved three times on a wobble of 1e-9 rad,
            # stayed 8x short until 7.5 s, 17 000 of its 20 898 steps, and bought nothing; docs/benchmark.md)
            return div_last / main.step_div
        if rho > (EARLY_RHO if early else 1.0):  # (early checks project a short stretch far: they act on more)
            if futile and not early:  # (shorter steps would only cost)
                return None
            f = min(REFINE_MAX_EARLY if early else REFINE_MAX, max(pi, 1.0))
        elif rho < 0.3 and settled and not early:  # (coarser only on the regular checks' evidence)
            f = max(1.0 / COARSEN, min(pi, 1.0))
        else:
            return None
        div = min(MAX_REFINE, max(1.0 / MAX_COARSE, self.coarsest(main, method), main.step_div * f))
        return None if div == main.step_div else div / main.step_div
