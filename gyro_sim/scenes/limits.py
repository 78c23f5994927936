"""Physical limits of a scene: the largest current and field rate of each stator, the spread of the rotor's principal
moments, and the largest values a scene may name at all. A value beyond them is refused, in one line naming the
field, the value and the limit: in a scene file (at load), in a command (:meth:`gyro_sim.engine.simulator.Simulator.
set_stators`; the simulator node's ``gyro/stator_commands``, refused with a rate-limited ``gyro/status`` report and
the state unchanged) and in the control laws' parameters (their outputs are those parameters, clipped).

Absolute limits (no scene may pass them; they guard the arithmetic on user values too):

* :data:`MAX_FIELD` (100 T): the field amplitude b_k I_k of one stator, and |Re B_p| + |Im B_p| of a field term. The
  strongest continuous magnets make 45 T; a coil of this project's kind makes a few mT.
* :data:`MAX_RATE` (1e7 rad/s): any field rate (stators, commands, law parameters, field frequencies) and the initial
  body rate |L0|/J_min. At 1e7 rad/s the rim of a 1 mm rotor moves at 10 km/s, beyond the burst speed of any
  material (about 1-2 km/s).

Per stator (``stators[k].max_current`` A, ``stators[k].max_rate`` rad/s in the scene; defaults derived from the
scene, so every scene loads as before):

* largest current: ``max_current``, default :data:`LIMIT_MARGIN` (10) times the largest field amplitude the scene
  gives any stator (b_j × the largest current of stator j in its ``current``, its commands, the law's currents),
  at least :data:`FIELD_FLOOR` (0.1 T, a strong resistive coil), at most :data:`MAX_FIELD`, divided by the stator's
  coil constant b_k: a field limit shared by the stators, as a current of each;
* largest field rate: ``max_rate``, default :data:`LIMIT_MARGIN` times the fastest rate the scene names (field
  rates of stators, commands, law parameters, field terms; the initial body rate), at least :data:`RATE_FLOOR`
  (1e4 rad/s), at most :data:`MAX_RATE`.

An explicit ``max_current`` / ``max_rate`` may lower these or raise them up to the absolute limits; the scene's own
values (the stator's current and rate, its commands, the law's parameters naming it) must lie within them.

Rotor: the triangle inequality of the principal moments is physics (:class:`gyro_sim.scenes.scene.Rotor`); beyond it
J_max / J_min may be at most ``rotor.max_inertia_ratio`` (default :data:`MAX_INERTIA_RATIO`, 1e4: a rod about 245
times longer than thick; a gyroscope's rotor is near a sphere). A thin axis of 1e-15 kg m² next to 1e6 kg m² spins
1e21 times faster than the body: the plan of such a run is steps without end (issue 29).

The run's own guard, where a state breaks anyway, is :func:`L_limit` (:class:`gyro_sim.engine.runner.Runner`).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from gyro_sim.scenes.scene_text import preview
from gyro_sim.scenes.tolerance import field_rates, law_limits

__all__ = ["MAX_FIELD", "MAX_RATE", "MAX_INERTIA_RATIO", "LIMIT_MARGIN", "FIELD_FLOOR", "RATE_FLOOR", "stator_limits",
           "check_scene_limits", "command_problem", "real_value", "L_limit", "L_MARGIN"]

#: T: the largest field amplitude of one stator (b_k I_k) or of one general field term a scene may name
MAX_FIELD = 100.0
#: rad/s: the largest field rate, field frequency or initial body rate a scene may name
MAX_RATE = 1e7
#: the default largest J_max / J_min of the rotor (``rotor.max_inertia_ratio`` overrides it)
MAX_INERTIA_RATIO = 1e4
#: the default per-stator limits are this many times the scene's own largest field and rate
LIMIT_MARGIN = 10.0
#: T: the default field limit is at least this (a scene whose stators carry no current in the file: commands come
#: from a controller over ROS)
FIELD_FLOOR = 0.1
#: rad/s: the default rate limit is at least this
RATE_FLOOR = 1e4
#: the run fails where |L| passes this many times the largest kinetic moment the fields can drive (:func:`L_limit`)
L_MARGIN = 10.0


def _initial_rate(scene) -> float:
    """|L0| / J_min (rad/s): the fastest body rate of the initial state."""
    ini, J = scene.initial, scene.rotor.inertia
    L0 = ini.kinetic_moment if ini.kinetic_moment is not None else J[2] * abs(ini.spin or 0.0)
    return L0 / min(J)


def _stator_values(scene, field: str) -> dict[str, list[tuple[str, float]]]:
    """{stator name: [(key, value), ...]} of every ``field`` ("current", A, or "rate", rad/s) the scene gives each
    stator: its own, its commands', the law's, in that order (one pass over the scene: 2,000 stators and 20,000
    commands took 51 s when each stator scanned them all)."""
    out: dict[str, list[tuple[str, float]]] = {}
    for i, s in enumerate(scene.stators):
        out.setdefault(s.name, []).append((f"stators.{i}.{field}", getattr(s, field)))
    for i, c in enumerate(scene.commands):
        v = getattr(c, field)
        if v is not None:
            out.setdefault(c.stator, []).append((f"commands.{i}.{field}", v))
    for key, names, cur, rate in _law_values(scene.controller):
        v = cur if field == "current" else rate
        if v is not None:
            for n in dict.fromkeys(names):
                out.setdefault(n, []).append((key, v))
    return out


def _stator_currents(scene) -> dict[str, list[tuple[str, float]]]:
    """{stator name: [(key, current A), ...]}: every current the scene gives each stator (:func:`_stator_values`)."""
    return _stator_values(scene, "current")


def _stator_rates(scene) -> dict[str, list[tuple[str, float]]]:
    """{stator name: [(key, rate rad/s), ...]}: every field rate the scene gives each stator."""
    return _stator_values(scene, "rate")


def _law_values(ctl) -> list[tuple[str, list, Optional[float], Optional[float]]]:
    """(key, stator names, current A | None, rate rad/s | None) of the law parameters that command stators."""
    if ctl is None:
        return []
    p, law, k = ctl.params, ctl.law, "controller.params"
    if law == "spinup":
        return [(f"{k}.current", [p.stator], p.current, None), (f"{k}.target_spin", [p.stator], None, p.target_spin)]
    if law == "psi_switching":
        ctl_names = list(p.control_stators)
        out = [(f"{k}.control_current", ctl_names, p.control_current, None),
               (f"{k}.spin_current", [p.spin_stator], p.spin_current, None),
               (f"{k}.spin_rate", [p.spin_stator], None, p.spin_rate)]
        return out + [(f"{k}.nu", [n], None, p.rate(i)) for i, n in enumerate(ctl_names)]
    if law == "manual":
        return [v for n, c in p.commands.items()
                for v in ((f"{k}.commands.{n}.current", [n], c.current, None),
                          (f"{k}.commands.{n}.rate", [n], None, c.rate))]
    if law == "reorient":
        names = list(p.rates)
        return [(f"{k}.current_limit", names, p.current_limit, None)] + [
            (f"{k}.rates.{n}", [n], None, r) for n, r in p.rates.items()]
    return []


def _largest_field(scene) -> float:
    """T: the largest field amplitude one stator gets in the scene (b_j × its largest current), the general field
    terms' amplitudes included."""
    law_cur = law_limits(scene.controller)[1]
    currents = _stator_currents(scene)
    B = [s.coil_constant * max([s.current, law_cur] + [c for _, c in currents.get(s.name, ())])
         for s in scene.stators]
    B += [math.hypot(*f.real) + math.hypot(*f.imag) for f in scene.field]
    return max(B + [0.0])


def stator_limits(scene) -> tuple[np.ndarray, np.ndarray]:
    """(largest current A, largest |field rate| rad/s) of each stator, in the scene's order: the stator's
    ``max_current`` / ``max_rate`` where given, else the defaults of the module docstring."""
    B = min(max(LIMIT_MARGIN * _largest_field(scene), FIELD_FLOOR), MAX_FIELD)
    rate = min(max(LIMIT_MARGIN * max(field_rates(scene), _initial_rate(scene)), RATE_FLOOR), MAX_RATE)
    cur = [s.max_current if s.max_current is not None else B / s.coil_constant for s in scene.stators]
    rates = [s.max_rate if s.max_rate is not None else rate for s in scene.stators]
    return np.array(cur, dtype=float), np.array(rates, dtype=float)


def _g(x: float) -> str:
    return f"{x:.6g}"


def check_scene_limits(scene) -> None:
    """ValueError (one line: the key, the value, the limit) where a value of ``scene`` passes the limits of the
    module docstring. Called by the scene's validation before anything computes with the values (the accuracy plan,
    the result size): 1e300 rad/s is refused here, not met as an OverflowError deeper down."""
    J = list(scene.rotor.inertia)
    ratio, allowed = max(J) / min(J), scene.rotor.max_inertia_ratio or MAX_INERTIA_RATIO
    if ratio > allowed:
        raise ValueError(
            f"rotor.inertia = {J}: J_max/J_min = {ratio:.3g} is beyond the largest ratio {allowed:.3g} "
            f"(rotor.max_inertia_ratio; the default {MAX_INERTIA_RATIO:g} is a rod about 245 times longer than thick)")
    for i, f in enumerate(scene.field):
        B = math.hypot(*f.real) + math.hypot(*f.imag)
        if B > MAX_FIELD:
            raise ValueError(f"field.{i}: |real| + |imag| = {_g(B)} T is beyond MAX_FIELD = {MAX_FIELD:g} T "
                             "(the strongest continuous magnets make 45 T)")
        if f.frequency > MAX_RATE:
            raise ValueError(f"field.{i}.frequency = {_g(f.frequency)} rad/s: beyond MAX_RATE = {MAX_RATE:g} rad/s")
    om0 = _initial_rate(scene)
    if om0 > MAX_RATE:
        key = "initial.kinetic_moment" if scene.initial.kinetic_moment is not None else "initial.spin"
        val = scene.initial.kinetic_moment if scene.initial.kinetic_moment is not None else scene.initial.spin
        raise ValueError(f"{key} = {_g(val)}: the initial body rate |L0|/J_min = {_g(om0)} rad/s is beyond "
                         f"MAX_RATE = {MAX_RATE:g} rad/s (the rim of a 1 mm rotor would move at 10 km/s)")
    # the absolute limits first (a value of 1e300 must not reach the defaults' arithmetic), then the stators' own
    currents, rates = _stator_currents(scene), _stator_rates(scene)
    for i, s in enumerate(scene.stators):
        cap = MAX_FIELD / s.coil_constant
        if s.max_current is not None and s.max_current > cap:
            raise ValueError(f"stators.{i}.max_current = {_g(s.max_current)} A: beyond {_g(cap)} A, the current of "
                             f"MAX_FIELD = {MAX_FIELD:g} T at coil_constant {_g(s.coil_constant)} T/A")
        if s.max_rate is not None and s.max_rate > MAX_RATE:
            raise ValueError(f"stators.{i}.max_rate = {_g(s.max_rate)} rad/s: beyond MAX_RATE = {MAX_RATE:g} rad/s")
        for key, c in currents.get(s.name, ()):
            if c > cap:
                raise ValueError(f"{key} = {_g(c)} A: stator {preview(s.name, 40)} would make b·I = "
                                 f"{_g(s.coil_constant * c)} T, "
                                 f"beyond MAX_FIELD = {MAX_FIELD:g} T ({_g(cap)} A at coil_constant "
                                 f"{_g(s.coil_constant)} T/A)")
        for key, r in rates.get(s.name, ()):
            if abs(r) > MAX_RATE:
                raise ValueError(f"{key} = {_g(r)} rad/s: beyond MAX_RATE = {MAX_RATE:g} rad/s")
    cur, rate = stator_limits(scene)
    for i, s in enumerate(scene.stators):
        for key, c in currents.get(s.name, ()):
            if c > cur[i]:
                raise ValueError(f"{key} = {_g(c)} A: beyond {_g(cur[i])} A, the largest current of stator "
                                 f"{preview(s.name, 40)} (stators.{i}.max_current)")
        for key, r in rates.get(s.name, ()):
            if abs(r) > rate[i]:
                raise ValueError(f"{key} = {_g(r)} rad/s: beyond {_g(rate[i])} rad/s, the largest field rate of stator "
                                 f"{preview(s.name, 40)} (stators.{i}.max_rate)")


def L_limit(scene, max_rate: np.ndarray, effect_rate: float = 0.0) -> float:
    """N m s: the largest |L| a sound run of ``scene`` may reach, :data:`L_MARGIN` times J_max Ω_max. Ω_max: the
    larger of the initial body rate and twice the fastest field rate the run may command (``max_rate``, the field
    terms' frequencies) times J_max/J_min (an induction drive does not pass its field's rate; with fields about
    several axes [K] (2.1)'s equilibria reach at most twice it: :func:`gyro_sim.scenes.tolerance.spin_reach`), plus
    ``effect_rate`` (the rate an effect drives: a flywheel, a damper's spring; Simulator._effect_rate) and the swing
    of an unbalance's pendulum, sqrt(4 |k| / J_min). The kinetic energy is then at most |L|² / (2 J_min).
    A magnetizable body's static moment exchanges energy with the field without bound by the rates: no limit (inf)."""
    if scene.effects.magnetizable is not None:
        return math.inf
    J = scene.rotor.inertia
    nu = max([float(np.max(max_rate, initial=0.0))] + [f.frequency for f in scene.field])
    om = max(_initial_rate(scene), 2.0 * nu * max(J) / min(J)) + effect_rate
    unb = scene.effects.unbalance
    if unb is not None:
        om += math.sqrt(4.0 * (abs(unb.k) + abs(unb.k1) + abs(unb.k2)) / min(J))
    return L_MARGIN * max(J) * om


def real_value(x) -> float:
    """``x`` as a float; NaN where it has none (an integer beyond the floats, 10**400: OverflowError otherwise)."""
    try:
        return float(x)
    except (OverflowError, TypeError, ValueError):
        return math.nan


def command_problem(sim, k: int, current: Optional[float], rate: Optional[float]) -> str:
    """'' if commanding stator ``k`` of simulator ``sim`` (its ``stator_names``, ``max_current``, ``max_rate``) to
    ``current`` A / ``rate`` rad/s (None: unchanged) is allowed, else the one-line reason naming the stator, the
    value and the limit (the in-process :meth:`Simulator.set_stators` and the simulator node's commands say the
    same)."""
    if current is not None:
        if not (math.isfinite(real_value(current)) and current >= 0):
            return f"stator {_name(sim, k)}: current = {preview(current)}: must be finite and ≥ 0 A"
        if current > sim.max_current[k]:
            return (f"stator {_name(sim, k)}: current = {_g(current)} A: beyond its largest current "
                    f"{_g(sim.max_current[k])} A (stators.{k}.max_current)")
    if rate is not None:
        if not math.isfinite(real_value(rate)):
            return f"stator {_name(sim, k)}: rate = {preview(rate)}: must be finite (rad/s)"
        if abs(rate) > sim.max_rate[k]:
            return (f"stator {_name(sim, k)}: rate = {_g(rate)} rad/s: beyond its largest field rate "
                    f"{_g(sim.max_rate[k])} rad/s (stators.{k}.max_rate)")
    return ""


def _name(sim, k: int) -> str:
    """Stator ``k``'s name as a refusal quotes it (made only for a refusal: a command a tick passes)."""
    return preview(sim.stator_names[k], 40)
