"""Scene files: one YAML file (SI units) says everything about a run.

A scene is loaded into typed, validated objects; a wrong scene is refused at load with
one :class:`SceneError` whose message names the key, the value (previewed: at most 80 characters)
and what is allowed; at most ``MAX_ERRORS`` (10) errors are listed, then how many more.

Limits (refused at load, before the cost): the text is read by :func:`parse_scene_text`
(:mod:`gyro_sim.scene_text`: at most 1 MiB of UTF-8, at most 100 YAML aliases, 250,000 nodes with
aliases expanded, 50 levels of nesting, no key twice in a mapping; ``2.5e7`` and ``1e-3`` are numbers
as in YAML 1.2); a number is a number (``current: on``, a boolean, and ``'2.5'``, a text, are refused);
and a run's in-memory result may take at most ``MAX_RESULT_BYTES`` (4 GiB; the environment variable
``GYRO_SIM_MAX_RESULT_BYTES`` overrides it; see :func:`result_size`).

Format (all keys but ``rotor``, ``duration`` optional)::

    name: spinup_thin_shell          # defaults to the file name
    description: one line
    rotor:
      inertia: [J1, J2, J3]          # principal moments, kg·m², x3 = polar axis
      max_inertia_ratio: null        # largest J_max/J_min (default 1e4)
      conductor:                     # omit for a non-conducting rotor
        kind: thin_shell             # thin_shell | solid_sphere | shell
        outer_radius: 0.025          # r2, m
        thickness: 0.001             # r2 − r1, m (thin_shell, shell)
        conductivity: 2.5e7          # σ, S/m
    torque_model: lag                # none | quasi_static | lag  (physics.md §3)
    accuracy:                        # what the run must hold over its whole duration (docs/accuracy.md)
      rtol: 1.0e-6                   # relative tolerance on L (default 1e-6)
      attitude: 1.0e-6               # the directions of the rotor's axes, rad (default 1e-6: the angle between
                                     # the computed and the true symmetry axis; the whole attitude for a body
                                     # with three different moments; null: none, only rtol)
      phase: 1.0e-7                  # the spin phase about the symmetry axis, relative to the phase turned
                                     # (default 1e-7; never tighter than attitude; null: none)
      phase_atol: null               # rad: an absolute tolerance on the spin phase instead (it costs: the
                                     # phase error grows with the turns)
    modes: null                      # eddy modes kept by the lag model of a solid sphere / shell; default:
                                     # chosen from accuracy and the largest slip the run can meet (with or
                                     # without the static tail term); a number given here wins (a warning
                                     # where it misses the tolerance)
    stators:                         # rotating fields B_k = b_k I_k (e1k cos σ_k + e2k sin σ_k)
      - name: z3
        axis: [0, 0, 1]              # u_k (case frame), normalised on load
        coil_constant: 1.0e-3        # b_k, T/A
        current: 1.0                 # I_k, A (amplitude, ≥ 0)
        rate: 3141.59                # ν_k = dσ_k/dt, rad/s; the sign is the direction
        phase: 0.0                   # σ_k at t = 0, rad
        max_current: null            # largest current, A (commands, laws, the scene's own values; default:
                                     # 10 x the scene's largest field b·I, at least 0.1 T, over b_k; see Limits)
        max_rate: null               # largest |field rate|, rad/s (default: 10 x the scene's fastest rate, at
                                     # least 1e4 rad/s)
    field:                           # general uniform field B(t) = Re Σ B_p exp(−i ω_p t)
      - real: [0, 0, 1.0e-3]         # Re B_p, T
        imag: [0, 0, 0]              # Im B_p, T
        frequency: 0.0               # ω_p, rad/s
    commands:                        # piecewise-constant stator commands (field phase continuous)
      - {time: 30.0, stator: z3, current: 0.0}
    initial:
      spin: 0.0                      # |L| / J3, rad/s (or kinetic_moment: |L| in N·m·s)
      L_direction: [0, 0, 1]         # direction of L in the case frame
      psi: 0.0                       # Euler angles of the body in the L-frame, rad
      theta: 0.0
      phi: 0.0
    duration: 60.0                   # s
    output:
      rate: 100.0                    # samples per second of simulated time
      windows:                       # optional stretches sampled faster (full model there, see fidelity)
        - {start: 30.0, end: 30.5, rate: 10000.0}   # s, s, samples per second
      attitude: true                 # false: q, Euler angles not needed (isotropic rotor, no effects:
                                     # not integrated; NaN in the outputs; see Output)
    integrator:
      method: auto                   # lawson8 | etdrk4 | frozen_flow | qs_flow | auto: qs_flow or frozen_flow
                                     # where it applies and pays, else lawson8 unless an eddy mode is stiff
                                     # (h > 2τ_n), then etdrk4; frozen_flow: steps longer than a field turn
                                     # (axisymmetric rotor, no effects; gyro_sim/compiled/frozen_flow.py,
                                     # docs/numerics.md); qs_flow: the same for the quasi-static torque, third
                                     # order (gyro_sim/compiled/qs_flow.py)
      steps_per_turn: null           # lawson8/etdrk4: steps per period of the fastest rotation (spin or
                                     # field); free stepper: per turn of the body-frame motion; default:
                                     # chosen from accuracy and the run's turns (a number here wins, with a
                                     # warning where the error model says it misses the tolerance)
      rate_change: null              # frozen_flow, qs_flow: largest change of the body rate per step as a fraction
                                     # of the fastest rate, by the torque's scale (default: from accuracy)
      max_step: null                 # optional upper bound on the step, s
    controller:                      # optional: a law of gyro_ctl run every period (s)
      law: psi_switching             # spinup | psi_switching
      period: 0.001                  # s (default: the output period)
      params: {nu: 300.0, control_current: 1.0, spin_current: 1.0, spin_rate: 3000.0}

    fidelity: full                   # full | averaged | auto (gyro_sim/engine/fidelity.py)
    effects: {}                      # unbalance, gas_drag, magnetizable, flywheel, damper
                                     # (gyro_sim/scenes/effect_config.py; all off by default)

Physical limits (gyro_sim/scenes/limits.py): every field amplitude b_k I_k and field term at most 100 T, every
rate and the initial body rate at most 1e7 rad/s, J_max/J_min at most ``max_inertia_ratio``; commands (in-process,
over ROS, the laws' parameters) within each stator's ``max_current`` and ``max_rate``. A value beyond is refused in
one line naming the key, the value and the limit.

Fields are switched on at t = 0 on a rotor free of eddy currents.

The stator triad: e1k is the next case axis after u_k in cyclic order (z1→z2→z3→z1),
made orthogonal to u_k; e2k = u_k × e1k. For u = z3 this gives e1 = z1, e2 = z2.
"""
from __future__ import annotations

import math
import os
import pickle
from collections import Counter
from pathlib import Path
from typing import Annotated, Any, Literal, Optional, Union, get_args, get_origin

import numpy as np
from pydantic import BaseModel, Field, StrictBool, ValidationError, field_validator, model_validator

from gyro_ctl.config import ControllerConfig, unknown_stators
from gyro_ctl.numbers import Finite, NonNegative, Positive, count, real
from gyro_ctl.strict_model import StrictModel

from gyro_sim.scenes.effect_config import Effects, unit_vector
from gyro_sim.scenes.limits import check_scene_limits
from gyro_sim.scenes.tolerance import DEFAULT_ATTITUDE, DEFAULT_PHASE, DEFAULT_RTOL
from gyro_sim.scenes.scene_text import SceneError, clip, human_bytes, parse_scene_text, preview, read_scene_file

__all__ = ["Scene", "SceneError", "load_scene", "check_valid", "builtin_scenes", "scene_from_dict", "config_dir",
           "parse_scene_text", "result_size", "check_command_times", "max_result_bytes", "MAX_RESULT_BYTES"]
__all__ += ["Rotor", "Conductor", "Stator", "FieldTerm", "Command", "Initial", "Output", "OutputWindow",  # sections
            "Integrator", "Accuracy"]

MAX_WINDOW_SAMPLES = 1e7  # output samples one window may ask for (memory: ~1 kB each with 50 modes)
MAX_WINDOWS = 100  # output windows of a scene (each one is merged into the sample times on its own)
MAX_RESULT_BYTES = 4 << 30  # bytes a run's in-memory result may take (4 GiB); see max_result_bytes
RESULT_BYTES_ENV = "GYRO_SIM_MAX_RESULT_BYTES"  # environment variable that overrides MAX_RESULT_BYTES
MAX_ERRORS = 10  # validation errors a SceneError lists (then "... and K more errors")
MAX_ERROR_LINE = 300  # characters of one listed error
Vec3 = Annotated[list[Finite], Field(min_length=3, max_length=3)]


_Strict = StrictModel  # (unknown keys refused, immutable: gyro_ctl/strict_model.py)


class Conductor(_Strict):
    """Homogeneous non-magnetic spherical conductor of the rotor."""

    kind: Literal["thin_shell", "solid_sphere", "shell"]
    """Shape of the conductor: thin_shell (thickness ≪ r2 and ≪ skin depth), solid_sphere, or shell (any thickness)."""
    outer_radius: real(ge=1e-6, le=10.0)  # m
    """Outer radius r2 of the conductor, m."""
    conductivity: real(ge=1e-3, le=1e12)  # S/m (metals: 1e6–1e8)
    """Electrical conductivity σ, S/m (metals: 1e6–1e8)."""
    thickness: Optional[real(ge=1e-9)] = None  # m
    """Wall thickness h = r2 − r1, m; required for thin_shell and shell (0 < h < r2), absent for solid_sphere."""

    @model_validator(mode="after")
    def _thickness(self) -> "Conductor":
        if self.kind == "solid_sphere":
            if self.thickness is not None:
                raise ValueError(f"thickness = {self.thickness}: a solid_sphere takes no thickness")
        else:
            if self.thickness is None:
                raise ValueError(f"thickness is missing: a {self.kind} needs thickness (m), 0 < thickness < outer_radius")
            if self.thickness >= self.outer_radius:
                raise ValueError(
                    f"thickness = {self.thickness}: must be less than outer_radius = {self.outer_radius} "
                    "(use kind: solid_sphere for a full sphere)"
                )
        return self

    @property
    def inner_radius(self) -> float:
        return 0.0 if self.thickness is None else self.outer_radius - self.thickness


class Rotor(_Strict):
    """The rotor (scene key ``rotor``): principal moments of inertia and the conductor."""

    inertia: Annotated[list[real(ge=1e-15, le=1e6)],
                       Field(min_length=3, max_length=3)]  # kg·m²
    """Principal moments of inertia [J1, J2, J3], kg·m²; x3 is the polar (symmetry) axis."""
    conductor: Optional[Conductor] = None
    """The rotor's conducting sphere or shell (eddy currents); None: a non-conducting rotor (no field torque)."""
    max_inertia_ratio: Optional[Positive] = None  # largest J_max/J_min (default: limits.MAX_INERTIA_RATIO)
    """Largest J_max/J_min accepted (dimensionless); None: the default limit 1e4."""

    @field_validator("inertia")
    @classmethod
    def _triangle(cls, J: list[float]) -> list[float]:
        for i in range(3):
            j, k = (i + 1) % 3, (i + 2) % 3
            if J[i] > (J[j] + J[k]) * (1 + 1e-12):
                raise ValueError(
                    f"inertia = {J}: J{i + 1} = {J[i]} exceeds J{j + 1} + J{k + 1} = {J[j] + J[k]}; "
                    "principal moments of a rigid body satisfy the triangle inequality"
                )
        return J


class Stator(_Strict):
    """A stator (an entry of ``stators``): a uniform field of amplitude b_k I_k rotating at ν_k about its axis u_k,
    B_k = b_k I_k (e1k cos σ_k + e2k sin σ_k), dσ_k/dt = ν_k."""

    name: Annotated[str, Field(min_length=1)]
    """The stator's name (unique in the scene; commands and control laws use it)."""
    axis: Vec3
    """Axis u_k of the stator in the case frame (dimensionless; normalised on load): the field rotates in the plane
    normal to it."""
    coil_constant: Positive
    """Coil constant b_k, T/A: the field amplitude is b_k·I_k."""
    current: NonNegative = 0.0
    """Current amplitude I_k at t = 0, A."""
    rate: Finite = 0.0
    """Field rotation rate ν_k = dσ_k/dt at t = 0, rad/s; the sign is the direction of rotation about the axis."""
    phase: Finite = 0.0
    """Field phase σ_k at t = 0, rad."""
    max_current: Optional[NonNegative] = None  # A; default: derived from the scene (gyro_sim/scenes/limits.py)
    """Largest current a command may set, A; None: 10 × the scene's largest field b·I (at least 0.1 T) over b_k."""
    max_rate: Optional[NonNegative] = None  # rad/s; default: derived from the scene
    """Largest |field rate| a command may set, rad/s; None: 10 × the scene's fastest rate, at least 1e4 rad/s."""

    @field_validator("axis")
    @classmethod
    def _axis(cls, a: list[float]) -> list[float]:
        return unit_vector(a, "axis")


class FieldTerm(_Strict):
    """A term of the general uniform field (an entry of ``field``): B(t) = Re Σ B_p exp(−i ω_p t), case frame."""

    real: Vec3
    """Re B_p of the term B(t) = Re Σ B_p exp(−i ω_p t), case frame, T."""
    imag: Vec3 = [0.0, 0.0, 0.0]
    """Im B_p, case frame, T."""
    frequency: NonNegative = 0.0
    """Angular frequency ω_p of the term, rad/s (0: a constant field)."""


class Command(_Strict):
    """A stator command at a given time (an entry of ``commands``); the field phase stays continuous."""

    time: NonNegative
    """When the command takes effect, s (simulated time)."""
    stator: str
    """Name of the stator it commands."""
    current: Optional[NonNegative] = None
    """New current amplitude, A; None: unchanged."""
    rate: Optional[Finite] = None
    """New field rotation rate, rad/s (signed); None: unchanged. The field phase stays continuous."""


class Initial(_Strict):
    """The state at t = 0 (``initial``): |L| (spin or kinetic_moment), the direction of L and the body's Euler
    angles ψ, θ, φ in the L-frame (z-x-z)."""

    spin: Optional[Finite] = None
    """Initial spin |L|/J3, rad/s (give this or kinetic_moment; neither: a rotor at rest)."""
    kinetic_moment: Optional[NonNegative] = None
    """Initial |L|, N·m·s (instead of spin)."""
    L_direction: Vec3 = [0.0, 0.0, 1.0]
    """Direction of the initial kinetic moment L in the case frame (dimensionless; normalised)."""
    psi: Finite = 0.0
    """Initial precession angle ψ of the body in the L-frame (z-x-z Euler angles), rad."""
    theta: real(ge=0, le=math.pi) = 0.0
    """Initial nutation angle θ between the polar axis x3 and L, rad (0 to π)."""
    phi: Finite = 0.0
    """Initial proper-rotation angle φ, rad."""

    @model_validator(mode="after")
    def _one_magnitude(self) -> "Initial":
        if self.spin is not None and self.kinetic_moment is not None:
            raise ValueError("give either spin (rad/s, |L| = J3·spin) or kinetic_moment (N·m·s), not both")
        if math.hypot(*self.L_direction) == 0:
            raise ValueError(f"L_direction = {self.L_direction}: must be a non-zero vector")
        return self


def sorted_union(*parts: np.ndarray) -> np.ndarray:
    """np.unique of the concatenated instants ``parts`` (s): its sort and its mask, the same array, without its
    ~10 µs of Python around them (a run makes several at its start)."""
    c = np.concatenate(parts).astype(float, copy=False).ravel()
    c.sort()
    if c.size < 2:
        return c
    keep = np.empty(c.size, np.bool_)
    keep[0] = True
    np.not_equal(c[1:], c[:-1], out=keep[1:])
    return c[keep]


def merge_times(times: np.ndarray, exact: np.ndarray) -> np.ndarray:
    """The sorted union of two sets of instants (s), where a time of ``times`` within round-off (1e-9
    relative) of one of ``exact`` is that one: no near-duplicate output rows (np.union1d's array:
    :func:`sorted_union`)."""
    if not exact.size:
        return sorted_union(times)
    j = exact.searchsorted(times)
    n = exact.size - 1
    lo, hi = np.maximum(j - 1, 0), np.minimum(j, n)  # (np.clip's indices, without its dispatch)
    near = np.minimum(np.abs(exact[lo] - times), np.abs(exact[hi] - times)) <= 1e-9 * np.maximum(1.0, np.abs(times))
    return sorted_union(exact, times[~near])


class OutputWindow(_Strict):
    """A stretch [start, end] (s) sampled at ``rate`` (samples per simulated second) on top of the scene's
    rate. ``fidelity: auto`` runs the full model inside it (the detail was asked for)."""

    start: NonNegative
    """Start of the stretch, s."""
    end: Positive
    """End of the stretch, s (after start)."""
    rate: Positive
    """Samples per second of simulated time within the stretch, 1/s."""

    @model_validator(mode="after")
    def _ordered(self) -> "OutputWindow":
        if not self.end > self.start:
            raise ValueError(f"end = {self.end}: must be greater than start = {self.start}")
        return self

    def samples_within(self, T: float) -> float:
        """How many samples the window asks for within a run of T s."""
        return max(0.0, min(self.end, T) - self.start) * self.rate


class Output(_Strict):
    """What a run reports. ``rate``: samples per simulated second. ``attitude``: false: the run need not
    report the attitude; for an isotropic rotor (J1 = J2 = J3) without effects, at ``fidelity: full`` and
    with no controller law that reads the attitude (psi_switching, reorient), the attitude is then not
    integrated (the eddy modes are carried in the case frame) and q, the Euler angles and θ are NaN
    (gyro_sim.simulate.Simulator). Where the rotor is not isotropic, an effect is on, the fidelity is
    averaged/auto or the controller reads the attitude, the dynamics need it: false is accepted and
    changes nothing. The ROS simulator node and a run that records a bag always integrate it."""

    rate: Positive = 100.0
    """Samples per second of simulated time, 1/s."""
    attitude: StrictBool = True
    """False: the run need not report the attitude (an isotropic rotor without effects then skips it; q, Euler angles
    NaN)."""
    windows: Annotated[list[OutputWindow], Field(max_length=MAX_WINDOWS)] = []
    """Stretches sampled faster than rate (full model there under fidelity: auto)."""

    def sample_count(self, T: float) -> float:
        """An upper bound on ``sample_times(T).size``, computed without allocating (T s may ask for 1e20
        samples): the regular grid, T itself, and every window's samples as if no two coincided."""
        n = T * self.rate + 2.0
        for w in self.windows:
            if w.start < T:
                n += w.samples_within(T) + 1.0
        return n

    def check_windows(self, T: float) -> None:
        """ValueError naming the window if one asks for more than ``MAX_WINDOW_SAMPLES`` within a run of T s."""
        for i, w in enumerate(self.windows):
            n = w.samples_within(T)
            if n > MAX_WINDOW_SAMPLES:
                raise ValueError(f"output.windows.{i}: rate = {w.rate}: {n:.3g} samples in [{w.start}, "
                                 f"{min(w.end, T)}] s; at most {MAX_WINDOW_SAMPLES:.0e} a window")

    def sample_times(self, T: float) -> np.ndarray:
        """All output instants in [0, T] (s, sorted, unique): every 1/rate, T itself, and the windows' samples."""
        try:
            self.check_windows(T)
        except ValueError as exc:
            raise SceneError(f"duration = {T:g} s: {exc}") from None
        dt = 1.0 / self.rate
        t = np.arange(int(math.floor(T / dt + 1e-9)) + 1) * dt
        if t[-1] < T * (1 - 1e-12):
            t = np.append(t, T)
        for w in self.windows:
            if w.start < T:
                end = min(w.end, T)
                n = int(math.floor((end - w.start) * w.rate + 1e-9))
                t = merge_times(w.start + np.arange(n + 1) / w.rate, t)
        return t

    def window_at(self, t: float) -> Optional["OutputWindow"]:
        """The window holding time t (s) with its end excluded, or None."""
        return next((w for w in self.windows if w.start <= t < w.end), None)

    def next_window_start(self, t: float) -> float:
        """The first window start after t (s), or inf."""
        return min((w.start for w in self.windows if w.start > t), default=math.inf)


class Integrator(_Strict):
    """The time stepper (``integrator``) and its knobs; the defaults are chosen from ``accuracy``."""

    method: Literal["auto", "lawson8", "etdrk4", "frozen_flow", "qs_flow"] = "auto"
    """Time stepper: auto (chosen per scene), lawson8, etdrk4 (stiff eddy modes), frozen_flow or qs_flow (long steps,
    axisymmetric rotor)."""
    steps_per_turn: Optional[count(ge=4, le=100000)] = None  # default: from accuracy (gyro_sim/scenes/accuracy.py)
    """Steps per period of the fastest rotation (spin or field), a count; None: chosen from accuracy."""
    rate_change: Optional[real(gt=0.0, le=0.1)] = None  # frozen_flow, qs_flow; default: from accuracy
    """frozen_flow, qs_flow: largest change of the body rate per step as a fraction of the fastest rate
    (dimensionless); None: from accuracy."""
    max_step: Optional[Positive] = None
    """Upper bound on the step, s; None: none."""


class Accuracy(_Strict):
    """What a run must hold over its whole duration against the converged solution of the scene's model, in terms
    of what an engineer observes:

    * ``rtol``: relative on L (max over the run of |L − L_true| / max|L_true|): the direction of L and the spin
      rate with it;
    * ``attitude`` (rad): the directions of the rotor's axes up to its spin about the symmetry axis (the angle
      between the computed and the true symmetry axis: nutation and precession); for a body with no symmetry
      axis (three different moments) the whole attitude;
    * ``phase``: the spin phase about the symmetry axis, relative to the phase the rotor turns through over the
      run (an error of 1e-7 of 1e5 rad is 1e-2 rad); ``phase_atol`` (rad): an absolute tolerance on the spin
      phase instead, on request.

    Defaults 1e-6, 1e-6 rad, 1e-7 (:mod:`gyro_sim.scenes.tolerance`, which says why). ``attitude`` and the phase
    are not results where the attitude is not integrated or was averaged out. The run chooses its eddy modes and
    step knobs for them and reports its estimated error (``RunResult.error_estimate``; docs/accuracy.md)."""

    rtol: real(ge=1e-13, le=0.1) = DEFAULT_RTOL
    """Relative tolerance on L over the run: max |L − L_true| / max |L_true| (dimensionless)."""
    attitude: Optional[real(ge=1e-13, le=10.0)] = DEFAULT_ATTITUDE  # null: no direction tolerance (only rtol)
    """Tolerance on the directions of the rotor's axes, rad (the symmetry axis; the whole attitude of a body with three
    different moments); None: only rtol."""
    phase: Optional[real(ge=1e-15, le=0.1)] = DEFAULT_PHASE  # relative to the phase turned; null: none
    """Tolerance on the spin phase about the symmetry axis, relative to the phase turned over the run (dimensionless);
    None: none."""
    phase_atol: Optional[real(ge=1e-13, le=1e6)] = None  # rad, absolute; wins over ``phase``
    """Absolute tolerance on the spin phase, rad (instead of phase; it costs: the error grows with the turns); None:
    none."""


class Scene(_Strict):
    """A validated scene. ``source`` is the file it came from (None when built from a dict)."""

    name: str = "scene"
    """The scene's name (default: the file name)."""
    description: str = ""
    """One line saying what the scene shows."""
    rotor: Rotor
    """The rotor: inertia and conductor."""
    torque_model: Literal["none", "quasi_static", "lag"] = "lag"
    """Electrodynamic torque: none, quasi_static ([K] (1.2), slips ≪ 1/τ) or lag (eddy-current modes, any slip;
    docs/physics.md §3)."""
    accuracy: Accuracy = Accuracy()
    """What the run must hold over its whole duration (tolerances on L, attitude and spin phase)."""
    modes: Optional[count(ge=1, le=500)] = None  # None: chosen from accuracy (gyro_sim.accuracy.mode_plan)
    """Eddy-current modes kept by the lag model of a solid sphere or shell, a count; None: chosen from accuracy."""
    stators: list[Stator] = []
    """The stators: rotating fields B_k = b_k I_k (e1k cos σ_k + e2k sin σ_k)."""
    field: list[FieldTerm] = []
    """A general uniform field B(t) = Re Σ B_p exp(−i ω_p t), T, added to the stators' fields."""
    commands: list[Command] = []
    """Piecewise-constant stator commands at given times (the field phase stays continuous)."""
    initial: Initial = Initial()
    """The state at t = 0: kinetic moment and the body's Euler angles in the L-frame."""
    duration: Positive
    """Simulated time of the run, s."""
    output: Output = Output()
    """What the run reports: sample rate (1/s), windows sampled faster, attitude or not."""
    integrator: Integrator = Integrator()
    """The time stepper and its knobs (defaults chosen from accuracy)."""
    controller: Optional[ControllerConfig] = None
    """A control law of gyro_ctl run every period (s); None: no controller (commands only)."""
    fidelity: Literal["full", "averaged", "auto"] = "full"
    """full (the full model), averaged (the slow averaged equations) or auto (averaged where they hold)."""
    effects: Effects = Effects()
    """Other torques and internal bodies: unbalance, gas_drag, magnetizable, flywheel, damper (all off by default)."""
    source: Optional[str] = None
    """The file the scene was loaded from (None when built from a dict)."""

    @model_validator(mode="after")
    def _consistent(self) -> "Scene":
        names = [s.name for s in self.stators]
        dup = sorted(n for n, k in Counter(names).items() if k > 1)
        if dup:
            raise ValueError(f"stators: name {preview(dup[0])} is used twice; stator names must be unique")
        known = set(names)
        for i, c in enumerate(self.commands):
            if c.stator not in known:
                raise ValueError(
                    f"commands.{i}.stator = {preview(c.stator)}: unknown stator; allowed: "
                    f"{preview(names) if names else 'none defined'}"
                )
            if c.current is None and c.rate is None:
                raise ValueError(f"commands.{i}: a command sets current and/or rate; it has neither")
        if self.controller is not None:
            err = unknown_stators(self.controller, names)
            if err:
                raise ValueError(f"controller.params.{err}")
        meth = self.integrator.method
        if meth in ("frozen_flow", "qs_flow"):
            J = self.rotor.inertia
            if not (J[0] == J[1] or J[1] == J[2] or J[0] == J[2]):
                raise ValueError(
                    f"integrator.method = {meth!r} needs an axisymmetric rotor (two equal rotor.inertia); "
                    f"rotor.inertia = {list(J)}: use lawson8, etdrk4 or auto"
                )
            if self.effects.any:
                on = [k for k in type(self.effects).model_fields if getattr(self.effects, k) is not None]
                raise ValueError(
                    f"integrator.method = {meth!r} takes the electrodynamic torque only; effects {on} are on: "
                    f"use lawson8, etdrk4 or auto"
                )
        if meth == "qs_flow" and self.torque_model != "quasi_static":
            raise ValueError(
                f"integrator.method = 'qs_flow' integrates the quasi-static torque ([K] (1.2)); torque_model = "
                f"{self.torque_model!r}: use torque_model: quasi_static, or frozen_flow, lawson8, etdrk4 or auto"
            )
        check_scene_limits(self)  # (before the accuracy plan and the result size compute with the values)
        self.output.check_windows(self.duration)
        check_result_size(self)
        if (self.stators or self.field) and self.torque_model != "none" and self.rotor.conductor is None:
            raise ValueError(
                f"torque_model = {self.torque_model!r} needs rotor.conductor; add one or set torque_model: none"
            )
        return self

    # --- derived quantities -------------------------------------------------------------
    @property
    def inertia(self) -> np.ndarray:
        return np.array(self.rotor.inertia, dtype=float)

    def stator_index(self, name: str) -> int:
        return [s.name for s in self.stators].index(name)

    # --- changed copies -----------------------------------------------------------------
    def replace(self, changes: Optional[dict] = None, /, **fields: Any) -> "Scene":
        """A copy of the scene with some values changed, validated again (a scene is immutable).

        ``changes`` maps dotted keys from the scene's top to values (list items by index), the keys of
        ``gyro-sim run --set`` and of a sweep; ``fields`` sets top-level keys::

            scene.replace({"stators.2.current": 0.5, "initial.theta": 0.1})
            scene.replace(duration=5.0, controller=None)

        Values are given as in a scene file (SI units: a list for a vector, a mapping for a section). An invalid
        result raises :class:`SceneError` with one line per wrong key (the key, the value, what is allowed), as
        loading a file does; a scheduled command after a shortened ``duration`` is dropped by the run as with
        ``--duration``, not refused. ``source`` stays that of this scene (docs/scenes.md)."""
        data = apply_overrides(self.model_dump(exclude={"source"}), {**(changes or {}), **fields})
        where = self.source or ""
        scene = scene_from_dict(data, where=where, default_name=self.name)
        check_command_times(scene, self.duration, where=where)
        return scene


# --- the memory a run's result takes --------------------------------------------------------

def max_result_bytes() -> float:
    """Bytes a scene's in-memory run result may take: :data:`MAX_RESULT_BYTES` (4 GiB), or the environment
    variable ``GYRO_SIM_MAX_RESULT_BYTES`` (a number of bytes, e.g. ``8e9``) where it is set."""
    env = os.environ.get(RESULT_BYTES_ENV, "").strip()
    if not env:
        return float(MAX_RESULT_BYTES)
    try:
        value = float(env)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise SceneError(f"{RESULT_BYTES_ENV} = {preview(env)}: must be a positive number of bytes (e.g. 8e9)")
    return value


def _eddy_modes(scene: "Scene") -> int:
    """Eddy modes a run carries (3 states each): the lag model's modes of the conductor (one for a thin
    shell, ``modes`` or the number chosen from ``accuracy`` for a solid sphere or a shell: gyro_sim.accuracy.
    mode_plan), none without a conductor or with another torque model."""
    cond = scene.rotor.conductor
    if cond is None or scene.torque_model != "lag":
        return 0
    if cond.kind == "thin_shell":
        return 1
    if scene.modes is not None:
        return scene.modes
    from gyro_sim.scenes.accuracy import mode_plan

    return mode_plan(scene, quiet=True).n


def result_size(scene: "Scene", duration: Optional[float] = None) -> tuple[float, float, int]:
    """(output samples, controller ticks, bytes per row) of a run of ``scene`` to its ``duration`` (or to
    ``duration`` s where given: a run cut short or made longer, ``gyro-sim run --duration``), counted
    without allocating; the result takes at most (samples + ticks) × bytes per row.

    Samples: an upper bound on the output instants (:meth:`Output.sample_count`: rate, duration, windows).
    Ticks: duration / controller period (its ``period``, else the output period) + 1, 0 without a controller;
    a tick logs a command, counted as one more row. Bytes per row: 8 bytes (float64) × (t 1 + L 3 + q 4 +
    Ω 3 + torque 3 + energy 1 + Euler angles 3 + 3 per stator (current, rate, phase) + 3 per eddy mode) as
    a :class:`gyro_sim.simulate.RunResult` holds them (the effects' outputs are not counted)."""
    T = scene.duration if duration is None else float(duration)
    samples = scene.output.sample_count(T)
    ticks = 0.0
    if scene.controller is not None:  # the period of gyro_sim.simulate.controller_period
        ticks = T / (scene.controller.period or 1.0 / scene.output.rate) + 1.0
    row = 8 * (1 + 3 + 4 + 3 + 3 + 1 + 3 + 3 * len(scene.stators) + 3 * _eddy_modes(scene))
    return samples, ticks, row


def check_result_size(scene: "Scene", duration: Optional[float] = None, name: str = "duration") -> None:
    """ValueError (one line: samples, bytes per sample, total, the limit and what to lower) if a run of
    ``scene`` (to ``duration`` s where given, named ``name`` in the message, e.g. ``--duration``) would hold
    more than :func:`max_result_bytes` in memory."""
    T = scene.duration if duration is None else float(duration)
    samples, ticks, row = result_size(scene, T)
    total, limit = (samples + ticks) * row, max_result_bytes()
    if not total <= limit:  # (NaN or inf too: a duration of 1e308 s)
        ctl = f" + {ticks:.3g} controller ticks" if ticks else ""
        tick_rate = 1.0 / (scene.controller.period or 1.0 / scene.output.rate) if scene.controller else 0.0
        per_s = row * (scene.output.rate + sum(w.rate for w in scene.output.windows) + tick_rate)  # (bytes/s, ≥)
        fits = f" (about {limit / per_s:.2g} s fits)" if per_s > 0 and math.isfinite(per_s) else ""
        raise ValueError(
            f"{name} = {T:g} s at output.rate = {scene.output.rate:g} /s: a run would hold "
            f"{samples:.3g} output samples{ctl} × {row} bytes = {total:.3g} bytes ({human_bytes(total)}) in "
            f"memory; the limit is {limit:.3g} bytes ({human_bytes(limit)}, {RESULT_BYTES_ENV}): lower {name}{fits}, "
            f"output.rate or output.windows{', or raise controller.period' if ticks else ''}")


# --- loading ------------------------------------------------------------------------------

def config_dir() -> Path:
    """Folder of the built-in scenes: the repository's config/, or share/gyro_sim/config when installed."""
    here = Path(__file__).resolve()
    for parent in here.parents:
        for cand in (parent / "config", parent / "share" / "gyro_sim" / "config"):
            if (cand / "spinup_thin_shell.yaml").is_file():
                return cand
    import sys

    cand = Path(sys.prefix) / "share" / "gyro_sim" / "config"
    return cand


def builtin_scenes() -> dict[str, Path]:
    """Built-in scene names → files (every YAML file in config/ that has a ``rotor`` key)."""
    out: dict[str, Path] = {}
    d = config_dir()
    if d.is_dir():
        for p in sorted(d.glob("*.yaml")):
            try:
                data = parse_scene_text(read_scene_file(p), str(p))
            except SceneError:
                continue
            if isinstance(data, dict) and "rotor" in data:
                out[p.stem] = p
    return out


def _model_at(model: type[BaseModel], loc: tuple) -> Optional[type[BaseModel]]:
    """The pydantic model class that owns the key at ``loc`` (for listing allowed keys)."""
    cur: Any = model
    for part in loc[:-1]:
        if isinstance(part, int):
            continue
        if not (isinstance(cur, type) and issubclass(cur, BaseModel)) or part not in cur.model_fields:
            return None
        cur = cur.model_fields[part].annotation
        # unwrap Optional[...] / list[...]
        for _ in range(3):
            origin = get_origin(cur)
            if origin in (list, Union) or str(origin) == "typing.Union" or origin is not None and "UnionType" in str(origin):
                args = [a for a in get_args(cur) if a is not type(None)]
                cur = args[0] if args else cur
            else:
                break
    return cur if isinstance(cur, type) and issubclass(cur, BaseModel) else None


def _loc_text(loc: tuple) -> str:
    """A dotted key of a pydantic error location; a union member's tag (``function-after[…]``, ``list[…]``:
    pydantic's, not the scene's) is left out and each part is previewed (a hostile key may be long)."""
    parts = [p for p in loc if p != "__root__" and not (isinstance(p, str) and p.endswith("]") and "[" in p)]
    return ".".join(p if isinstance(p, str) and len(p) <= 40 and p.isprintable() else preview(p, 40)
                    if not isinstance(p, int) else str(p) for p in parts) or "(scene)"


def _error_line(e: dict) -> str:
    """One line of a validation error: the key, the value (previewed) and what is allowed."""
    loc = tuple(x for x in e["loc"] if x != "__root__")
    key = _loc_text(loc)
    msg = e["msg"].removeprefix("Value error, ")
    if e["type"] == "extra_forbidden":
        owner = _model_at(Scene, loc)
        allowed = sorted(k for k in owner.model_fields if k != "source") if owner else []
        return f"{key}: unknown key; allowed keys here: {', '.join(allowed)}"
    if e["type"] == "missing":
        return f"{key}: required key is missing"
    if e["type"] in ("value_error", "assertion_error"):
        if key == "(scene)":
            return msg
        if " = " not in msg and not isinstance(e.get("input"), (dict, BaseModel)):
            return f"{key} = {preview(e.get('input'))}: {msg}"  # a field's check that does not quote the value
        return f"{key}: {msg}"
    return f"{key} = {preview(e.get('input'))}: {msg}"


def _format_errors(err: ValidationError, where: str) -> str:
    """The message of a SceneError for a validation error: one line per error (each at most
    :data:`MAX_ERROR_LINE` characters), at most :data:`MAX_ERRORS` of them, then '... and K more errors'."""
    errors = err.errors(include_url=False, include_context=False)
    lines = [clip(_error_line(e), MAX_ERROR_LINE) for e in errors[:MAX_ERRORS]]
    if len(errors) > MAX_ERRORS:
        lines.append(f"... and {len(errors) - MAX_ERRORS} more errors")
    head = f"invalid scene {where}" if where else "invalid scene"
    if len(lines) == 1:
        return f"{head}: {lines[0]}"
    return head + ":\n  " + "\n  ".join(lines)


def scene_from_dict(data: Any, where: str = "", default_name: str = "scene") -> Scene:
    """Validate a scene given as a dict (parsed YAML). Raises SceneError."""
    if not isinstance(data, dict):
        raise SceneError(f"invalid scene {where}: the top level must be a mapping of keys, got "
                         f"{clip(type(data).__name__, 40)}")
    data = dict(data)
    data.setdefault("name", default_name)
    if "source" in data:
        raise SceneError(f"invalid scene {where}: source: unknown key (it is set by the loader)")
    data["source"] = where or None
    try:
        return Scene.model_validate(data)
    except ValidationError as err:
        raise SceneError(_format_errors(err, where)) from None


#: the scenes that validated last (their model_dump pickled: it tells 1, 1.0, True, -0.0 and None apart): a run of
#: a scene whose data validated before skips validating it again (check_valid)
_VALID: dict = {}
_VALID_KEPT = 16


def check_valid(scene: Scene) -> None:
    """SceneError (the one-line errors of a scene file) where ``scene`` does not validate: a copy made by pydantic's
    ``model_copy(update=...)`` or ``model_construct``, which skip validation. Costs about 0.1 ms, ~11 µs for data
    that validated before (kept by value: its model_dump); a run calls it."""
    data = scene.model_dump(warnings=False)
    key = pickle.dumps(data, 5)
    if key in _VALID:
        return
    try:
        Scene.model_validate(data)
    except ValidationError as err:
        raise SceneError(_format_errors(err, scene.source or "")) from None
    if len(_VALID) >= _VALID_KEPT:
        del _VALID[next(iter(_VALID))]
    _VALID[key] = True


def load_scene(name_or_path: Union[str, Path], overrides: Optional[dict] = None) -> Scene:
    """Load and validate a scene from a YAML file or a built-in scene name.

    ``overrides`` maps dotted keys from the scene's top (``"initial.theta"``, ``"stators.2.current"``: list items
    by index) to values applied before validation, as ``gyro-sim run --set`` does; :meth:`Scene.replace` makes the
    same change to a scene already loaded (docs/scenes.md).
    """
    p = Path(name_or_path)
    try:
        is_file = p.is_file()
    except (OSError, ValueError):  # a name too long for the file system, a NUL in it
        is_file = False
    if not is_file:
        scenes = builtin_scenes()
        key = p.stem if p.suffix in (".yaml", ".yml") else str(name_or_path)
        if key in scenes and p.parent == Path("."):
            p = scenes[key]
        else:
            raise SceneError(
                f"scene {preview(str(name_or_path))}: no such file and no built-in scene of that name; "
                f"built-in scenes: {', '.join(scenes) or 'none found'}"
            )
    data = parse_scene_text(read_scene_file(p), str(p))
    written = data.get("duration") if isinstance(data, dict) else None  # (before the overrides)
    if overrides:
        data = apply_overrides(data, overrides)
    scene = scene_from_dict(data, where=str(p), default_name=p.stem)
    check_command_times(scene, written, where=str(p))
    return scene


def check_command_times(scene: Scene, written: Any = None, where: str = "") -> None:
    """SceneError (one line: the command's field, its time and the allowed range) for a scheduled command at or
    after the end of the run, which would never be applied. The end is the scene's ``duration``, or the one its
    file says where that is longer (``written``, before an override shortened the run: the commands after the
    shortened end are the part of the scene the run leaves out)."""
    end = scene.duration
    if isinstance(written, (int, float)) and not isinstance(written, bool) and math.isfinite(written):
        end = max(end, float(written))
    for i, c in enumerate(scene.commands):
        if not c.time < end:
            head = f"invalid scene {where}" if where else "invalid scene"
            raise SceneError(f"{head}: commands.{i}.time = {c.time:g} s: at or after the end of the run, it would "
                             f"never be applied; allowed: 0 <= time < {end:g} s (duration)")


def apply_overrides(data: dict, overrides: dict) -> dict:
    """Copy of ``data`` with dotted keys set (list items by index: ``stators.0.current``); missing mappings on
    the way are made. SceneError naming the dotted key where a part cannot be followed (an index beyond
    its list, a key below a value that is not a mapping)."""
    import copy

    out = copy.deepcopy(data)
    for dotted, value in overrides.items():
        cur = out
        parts = str(dotted).split(".")
        for depth, part in enumerate(parts):
            last = depth == len(parts) - 1
            if isinstance(cur, list):
                if not (part.isdigit() and int(part) < len(cur)):
                    raise SceneError(f"override {preview(dotted)}: {preview(part)} is not an index of "
                                     f"{'.'.join(parts[:depth]) or 'the scene'} ({len(cur)} items)")
                if last:
                    cur[int(part)] = value
                else:
                    cur = cur[int(part)]
            elif isinstance(cur, dict):
                if last:
                    cur[part] = value
                else:
                    cur = cur.setdefault(part, {})
            else:
                raise SceneError(f"override {preview(dotted)}: {'.'.join(parts[:depth]) or 'the scene'} = "
                                 f"{preview(cur)} is not a mapping or a list")
    return out
