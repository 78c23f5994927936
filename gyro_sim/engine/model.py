"""The pieces of a run every part of the engine shares: step knobs, the lawson8 table, which runs integrate the
attitude, the controller period, stator triads, body rates and kinetic energy (SI); the output grid is
:func:`gyro_sim.engine.saving.output_times`.
"""
from __future__ import annotations

import math
from functools import lru_cache
from typing import Optional, Sequence

import numpy as np

from gyro_sim.compiled import kernels
from gyro_sim.physics.frames import _matrix, attitude_from_euler, quat_to_matrix
from gyro_sim.scenes.scene import Scene


#: the fixed step knobs of the runs before the accuracy plan (issue 19): steps per turn of the fastest rotation and
#: the frozen-flow rate_change. Runs now choose their knobs from the scene's ``accuracy`` (gyro_sim/scenes/accuracy.py,
#: ``Simulator.step_plan``); these stay as the benchmark's "today's defaults" (gyro_sim/apps/bench.py)
DEFAULT_STEPS_PER_TURN = {"lawson8": 12, "etdrk4": 48, "free": 48}
DEFAULT_RATE_CHANGE = 1e-4
#: a frozen-flow step costs about this many lawson8 steps per (1 + number of eddy modes) and field phasor: 8 µs
#: against 1.9 µs with one phasor and one mode, 17–28 µs with ten modes (measured on the default scene and
#: spinup_solid_sphere); ``auto`` takes it where its step is that many times longer (:func:`frozen_flow_cost`)
FROZEN_FLOW_COST = 2.0
#: control laws that read only t, L and the stators (not q, θ or Ω_b): with one of them (or none) a scene may
#: run without attitude; any other law (psi_switching, reorient: θ and the polar axis) keeps it
LAWS_WITHOUT_ATTITUDE = frozenset({"spinup", "off", "hold", "manual"})
#: (A, b, c) of each field stepper for kernels.integrate: DOP853's for lawson8, empty for ETDRK4 (made on first use:
#: a process that runs no lawson8 step reads no table)
_TABLEAU: dict = {}


def _tableau(method: str) -> tuple:
    """(A, b, c) of ``method`` ('lawson8' or 'etdrk4') for kernels.integrate, kept once made."""
    if method not in _TABLEAU:
        _TABLEAU[method] = (kernels.dop853_tableau() if method == "lawson8"
                            else (np.empty((0, 0)), np.empty(0), np.empty(0)))
    return _TABLEAU[method]


def integrates_attitude(scene: Scene, attitude: Optional[bool] = None) -> bool:
    """Whether a run of ``scene`` integrates the attitude q. ``attitude``: what the caller needs (None: the
    scene's ``output.attitude``; True: always, as the ROS node and a recorded run do).

    Without attitude only where nothing needs it: the rotor isotropic (J1 = J2 = J3: Ω = L/J does not depend
    on q, and the spherical conductor's eddy-mode filter is rotation-covariant, so the modes can be carried
    in the case frame), no effect on (their torques and states need the body frame), ``fidelity: full``
    (fidelity.py's hand-overs read and rebuild q) and no controller law outside :data:`LAWS_WITHOUT_ATTITUDE`.
    Elsewhere ``output.attitude: false`` is accepted and changes nothing."""
    want = scene.output.attitude if attitude is None else bool(attitude)
    if want:
        return True
    J = scene.rotor.inertia
    ctl = scene.controller
    return not (J[0] == J[1] == J[2] and not scene.effects.any and scene.fidelity == "full"
                and (ctl is None or ctl.law in LAWS_WITHOUT_ATTITUDE))


@lru_cache(maxsize=64)
def _initial_attitude(direction: tuple, psi: float, theta: float, phi: float) -> np.ndarray:
    """:func:`attitude_from_euler` of a scene's initial state (L direction, Euler angles rad), kept per value: a pure
    function, the same bits, ~15 µs each Simulator made of a scene spent once. Read only."""
    q = attitude_from_euler(np.array(direction), psi, theta, phi)
    q.flags.writeable = False
    return q


def controller_period(scene: Scene) -> Optional[float]:
    """s between the ticks of the scene's controller: its ``period``, else one per output sample; None without a
    controller section."""
    ctl = scene.controller
    return (ctl.period or 1.0 / scene.output.rate) if ctl is not None else None


def holds(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """np.isin(a, b) for instants ``b`` sorted (s): whether each of ``a`` is one of them."""
    if not b.size:
        return np.zeros(a.shape, np.bool_)
    i = np.minimum(np.searchsorted(b, a), b.size - 1)
    return b[i] == a


def _case_flag(attitude: bool) -> tuple:
    """The trailing ``case`` argument of the compiled integrators and :func:`kernels.record_sample`: None with
    the attitude (numba prunes the case-frame code: it compiles only what the scene runs), True without."""
    return (None,) if attitude else (True,)


def stator_triad(u: Sequence[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Right-handed triad (e1, e2, u) of a stator axis u: e1 = next case axis (cyclic) ⟂ u. (Scalar code: a
    Simulator makes one per stator, and np.cross costs ~5 µs a call.)"""
    a = [float(v) for v in u]
    n = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    u0, u1, u2 = a[0] / n, a[1] / n, a[2] / n
    i = max(range(3), key=lambda k: abs((u0, u1, u2)[k]))  # (the first of equal ones, as np.argmax)
    z = [0.0, 0.0, 0.0]
    z[(i + 1) % 3] = 1.0
    d = z[0] * u0 + z[1] * u1 + z[2] * u2
    e = [z[0] - d * u0, z[1] - d * u1, z[2] - d * u2]
    m = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    e0, e1, e2 = e[0] / m, e[1] / m, e[2] / m
    return (np.array([e0, e1, e2]), np.array([u1 * e2 - u2 * e1, u2 * e0 - u0 * e2, u0 * e1 - u1 * e0]),
            np.array([u0, u1, u2]))

#: the averaged models' error of L is at most about this times their averaging parameter ε at entry (measured on
#: the built-in scenes: 0.01 for the spin-up model, 0.04 for [K] on three_stators, 0.4 for [K] ψ-switching on
#: nutation_slow; docs/benchmark.md): entry needs ε ≤ accuracy.rtol / AVERAGED_ERROR (and ≤ MU_MAX)
AVERAGED_ERROR = 0.5


def frozen_flow_cost(n_modes: int, n_phasors: int = 1) -> float:
    """A frozen-flow step's CPU time in lawson8 steps with ``n_modes`` eddy modes and ``n_phasors`` field phasors:
    :data:`FROZEN_FLOW_COST` (1 + modes) a phasor. Its terms are products of a phasor with each of the moment's
    9 (phasors + modes) terms, so it grows with the phasors (a lawson8 step barely does): measured on a thin shell
    (one mode) 6.9, 15.8, 28.5 µs with 1, 2, 3 phasors against lawson8's 1.9 µs (3.6x, 8.5x, 15x); with ten modes
    28, 56, 88 µs against 2.1 µs (13x, 27x, 40x). ``auto`` takes frozen_flow where its step is this many times
    lawson8's (:meth:`gyro_sim.engine.step_size.StepSize.choose`)."""
    return FROZEN_FLOW_COST * (1 + n_modes) * n_phasors


def lawson8_cost(n_modes: int) -> float:
    """A lawson8 step's CPU time in ETDRK4 steps with ``n_modes`` eddy modes: measured 2.1 (one mode), 3.3 (50),
    4.7 (200) on constant_field and spinup_solid_sphere (1.6, 2.7, 7.2 µs against 0.8, 0.8, 1.6 µs)."""
    return 2.0 + 0.013 * n_modes


def body_rates(J: np.ndarray, L: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """L_b = Rᵀ L (N·m·s) and Ω_b = J⁻¹ L_b (rad/s) of states (..., 3), (..., 4).

    Written element by element (no BLAS) so a row gives the same bits alone or in a batch:
    the in-process controller and the controller node see identical numbers.
    """
    if q.size == 4 and L.size == 3 and q.shape[:-1] == L.shape[:-1]:  # one state (a tick's): scalar code, the same
        M = _matrix(*q.ravel().tolist())  # bits (the same IEEE operations in the same order), ~3 µs, not ~20
        L0, L1, L2 = L.ravel().tolist()
        Lb = [M[0][j] * L0 + M[1][j] * L1 + M[2][j] * L2 for j in range(3)]
        J0, J1, J2 = (J.tolist() if isinstance(J, np.ndarray) else [float(v) for v in J])
        return (np.array(Lb).reshape(L.shape),
                np.array([Lb[0] / J0, Lb[1] / J1, Lb[2] / J2]).reshape(L.shape))
    R = quat_to_matrix(q)
    Lb = R[..., 0, :] * L[..., 0:1] + R[..., 1, :] * L[..., 1:2] + R[..., 2, :] * L[..., 2:3]
    return Lb, Lb / J


def kinetic_energy(J: np.ndarray, omega_b: np.ndarray) -> np.ndarray:
    """Rotational kinetic energy ½ Ω_b·J Ω_b (J) of body rates (n, 3) rad/s, J the principal moments (kg·m²)."""
    return 0.5 * np.einsum("ni,i,ni->n", omega_b, J, omega_b)


def system_energy(scene: Scene, omega_b: np.ndarray, effects: dict) -> np.ndarray:
    """Mechanical energy (J) of the rotor with its internal bodies, per sample (``RunResult.energy``).

    Without effects ½ Ω_b·J Ω_b (:func:`kinetic_energy`). With a flywheel the gyrostat's, body and wheel (J with
    the wheel locked; :func:`gyro_sim.physics.flywheel.wheel_energy`, ``effects["flywheel_speed"]``); with a
    damper the body's, the mass's ½ m|v + Ω × r|² and the spring's ½ c|u|² (:func:`gyro_sim.physics.klt.damper_energy`,
    ``effects["damper_offset"]``, ``["damper_velocity"]``). ``omega_b``: (n, 3) rad/s, body frame; ``effects``:
    the effects' outputs of the same rows (:meth:`Simulator.effect_outputs`). The electrodynamic torque, the
    unbalance, gas drag and the wheel's motor do work on the system; the damper's friction takes it."""
    J = scene.inertia
    fly, damper = scene.effects.flywheel, scene.effects.damper
    if damper is not None and "damper_offset" in effects:
        from gyro_sim.physics.klt import damper_energy

        E = damper_energy(omega_b, list(J), damper.mass, damper.radius, damper.stiffness, effects["damper_offset"],
                          effects["damper_velocity"])
    else:
        E = kinetic_energy(J, omega_b)
    if fly is not None and "flywheel_speed" in effects:
        from gyro_sim.physics.flywheel import wheel_energy

        E = E + wheel_energy(omega_b, fly.inertia, fly.axis, effects["flywheel_speed"])
    return E
