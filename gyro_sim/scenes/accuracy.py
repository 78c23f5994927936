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

The plan's pieces: :mod:`gyro_sim.scenes.tolerance` (defaults, warnings, rates and reach),
:mod:`gyro_sim.scenes.modal_truncation` (eddy modes), :mod:`gyro_sim.scenes.step_control` (step knobs, error
estimate and control). This module gathers them: every name it had is importable from it.
"""
from __future__ import annotations

from gyro_sim.scenes.tolerance import (  # noqa: F401  (the names of the accuracy plan, gathered)
    DEFAULT_RTOL,
    DEFAULT_ATTITUDE,
    MODE_SHARE,
    STEP_SHARE,
    MAX_MODES,
    MODE_TOL_FLOOR,
    _GRID,
    LEGACY_MODES,
    LEGACY_STEPS_PER_TURN,
    LEGACY_RATE_CHANGE,
    _LEGACY,
    legacy,
    is_legacy,
    AccuracyWarning,
    warn,
    law_limits,
    field_rates,
    field_amplitude,
    active_stators,
    spin_reach,
    slip_bound,
)
from gyro_sim.scenes.modal_truncation import (  # noqa: F401  (the names of the accuracy plan, gathered)
    _full_model,
    truncated_model,
    _exact_g,
    _errors,
    modal_error,
    choose_modes,
    best_tail,
    mode_tolerances,
    ModePlan,
    mode_plan,
    scene_conductor,
)
from gyro_sim.scenes.step_control import (  # noqa: F401  (the names of the accuracy plan, gathered)
    STEP_ERROR,
    FROZEN_ERROR,
    QS_FLOW_ERROR,
    RATE_KNOB,
    PHASE_REL_MIN,
    STEPS_WARN,
    STEP_BUDGET,
    StepBudgetError,
    SPT_MIN,
    SPT_MAX,
    RATE_CHANGE_MAX,
    QS_RATE_CHANGE_MAX,
    RATE_CHANGE_MIN,
    StepPlan,
    _spt_for,
    _rate_change_for,
    _qs_rate_change_for,
    step_plan,
    auto_plan,
    ORDER,
    STIFF_ORDER,
    STIFF,
    COARSE_ORDER,
    ESTIMATE_ORDER,
    SHADOW_RATIO,
    CHECKS,
    R_MEASURABLE,
    FINER,
    FINER_TAU,
    AIM,
    REFINE_MAX,
    EARLY_RHO,
    REFINE_MAX_EARLY,
    COARSEN,
    MAX_COARSE,
    MAX_REFINE,
    ErrorEstimate,
    ErrorControl,
)

__all__ = ["DEFAULT_RTOL", "DEFAULT_ATTITUDE", "MODE_SHARE", "STEP_SHARE", "MAX_MODES", "AccuracyWarning",
           "ModePlan", "mode_plan", "slip_bound", "spin_reach", "modal_error", "choose_modes", "scene_conductor",
           "truncated_model", "mode_tolerances", "PHASE_REL_MIN"]
