"""Tolerances of a scene's ``accuracy`` section and the rates a run can meet (the base of the accuracy plan,
:mod:`gyro_sim.scenes.accuracy`): defaults, the legacy knobs, :class:`AccuracyWarning`, the field rates,
amplitudes and the spin a run can reach, the slip bound."""
from __future__ import annotations

import math
import warnings

import numpy as np

from gyro_sim.physics.conductor import (shell_tau_eff)
from gyro_sim.physics.constants import MU0
from gyro_sim.physics.frames import symmetry_axis


#: default relative tolerance on L over the whole run
DEFAULT_RTOL = 1e-6
#: default absolute tolerance on the directions of the rotor's axes (rad: the angle between the computed and the
#: true symmetry axis; the whole rotation angle for a body without symmetry axis) over the whole run
DEFAULT_ATTITUDE = 1e-6
#: default tolerance on the spin phase about the symmetry axis, relative to the phase the rotor turns through: the
#: phase is the time integral of the spin rate, which ``rtol`` holds to 1e-6 at every instant; 1e-7 holds the mean
#: rate (what a counter of a rotor's phase marker reads) ten times tighter than that, so the phase is never the
#: worst-known result of a run, and costs nothing over the directions' tolerance on the built-in scenes
#: (docs/accuracy.md, "Why these defaults": 1e-9 took 2.7x the steps of the default scene)
DEFAULT_PHASE = 1e-7
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
#: "today's defaults"; gyro_sim/apps/bench_accuracy.py)
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
# the attitude's tolerances: directions and spin phase
# --------------------------------------------------------------------------------------------------
def has_symmetry_axis(J) -> bool:
    """Whether principal moments J have two equal (an axisymmetric or isotropic body: a spin phase apart)."""
    return symmetry_axis(J) >= 0


def phase_tolerance(acc, om: float, T: float) -> float:
    """Absolute tolerance (rad) on the spin phase of a run that turns at up to ``om`` rad/s for T s:
    ``accuracy.phase_atol`` where given, else ``accuracy.phase`` × ``om`` T (the phase turned), never tighter than
    ``accuracy.attitude`` (a phase error below the directions' tolerance is nothing an engineer sees: a spin-up from
    rest turns through little phase at first); inf where none, and where ``attitude`` is null (only L matters)."""
    if acc.phase_atol is not None:
        return float(acc.phase_atol)
    if acc.phase is None or acc.attitude is None:  # (attitude: null: only L matters, the phase with the rest)
        return math.inf
    return max(float(acc.phase) * max(om * T, 0.0), float(acc.attitude))


def planning_attitude(scene, om: float, T: float) -> float:
    """The tolerance (rad) on the phases the steppers err in (the spin phase and the precession phase of the
    symmetry axis about L: their error models count both alike) that holds a run's attitude tolerances: the spin
    phase's (:func:`phase_tolerance`; the cone of the axis about L, which ``attitude`` holds, the steppers keep far
    closer: the error control measures it). A body without symmetry axis: ``accuracy.attitude`` (the whole
    attitude). inf where neither is asked for. The plan's first guess: the run's error control measures each and
    corrects."""
    acc = scene.accuracy
    J = scene.rotor.inertia
    if not has_symmetry_axis(J):
        return math.inf if acc.attitude is None else float(acc.attitude)
    return phase_tolerance(acc, om, T)
