"""The output of a run (diffrax's ``_saveat.py``): the instants a run records (:func:`output_times`), the sample
rows the steppers write turned into the arrays a caller reads (:func:`sample_arrays`: a chunk of rows;
:func:`run_result`: the whole run as a :class:`~gyro_sim.engine.result.RunResult`). SI units; L in the case frame,
the attitude quaternion body → case, Ω_b in the body frame.

The rows themselves (the state y and the torque at each output instant, the stators' columns) are written by the
steppers and the compiled tick loop into the :class:`~gyro_sim.engine.runner.Runner`'s buffers.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from gyro_sim.compiled import effects
from gyro_sim.engine.model import body_rates, kinetic_energy, system_energy
from gyro_sim.engine.result import RunResult
from gyro_sim.physics.frames import euler_angles, quat_to_matrix
from gyro_sim.scenes.scene import Scene, merge_times

__all__ = ["output_times", "sample_arrays", "run_result"]


def output_times(scene: Scene, T: float, period: Optional[float] = None) -> tuple[np.ndarray, np.ndarray]:
    """(output instants, tick instants), s, sorted, of a run of ``scene`` over ``T`` s: the scene's output grid with
    a tick every ``period`` s (None: no ticks) merged in (a tick is exact: a sample within round-off is it). The
    :class:`~gyro_sim.engine.runner.Runner`'s grid; a bag's reader maps the ns stamps back onto it
    (:func:`gyro_sim.results.read_bag`)."""
    ticks = np.arange(int(math.ceil(T / period - 1e-9))) * period if period is not None else np.zeros(0)
    return merge_times(scene.output.sample_times(T), ticks), ticks


def sample_arrays(scene: Scene, terms, attitude: bool, t_rows: np.ndarray, Y: np.ndarray, N: np.ndarray,
                  cur: np.ndarray, rate: np.ndarray, phase: np.ndarray, euler: bool = True,
                  energy: bool = True) -> dict:
    """Output rows as arrays: t, L, q, omega_b, euler (None unless ``euler``), torque, energy (None unless
    ``energy``), current, rate, phase, modes, effects (without attitude: q and euler NaN, omega_b in the case frame).
    ``t_rows`` (s), ``Y`` (the states), ``N`` (N m, the torques), ``cur``, ``rate``, ``phase`` (A, rad/s, rad: the
    stators' columns): the rows; ``terms``: the run's model (:class:`gyro_sim.engine.terms.Terms`)."""
    L, q = Y[:, 0:3], Y[:, 3:7]
    extra = {}
    E: Optional[np.ndarray] = None
    if not attitude:
        omega_b = terms.body_rates(t_rows, Y)
        if energy:
            E = kinetic_energy(terms.J, omega_b)  # isotropic: frame-free
    elif terms.eff[effects.ON]:
        t = t_rows
        omega_b = terms.body_rates(t, Y)
        extra = terms.effect_outputs(t, Y)
        if energy:
            E = system_energy(scene, omega_b, extra)  # the body's and its internal bodies'
    else:
        _, omega_b = body_rates(terms.J, L, q)
        if energy:
            E = kinetic_energy(terms.J, omega_b)
    eul = None
    if euler:
        eul = euler_angles(quat_to_matrix(q), L) if attitude else np.full((L.shape[0], 3), np.nan)
    return {"t": t_rows, "L": L, "q": q, "omega_b": omega_b, "euler": eul, "torque": N,
            "energy": E, "current": cur, "rate": rate, "phase": phase,
            "modes": Y[:, 7:7 + 3 * terms.tau.size], "effects": extra}


def run_result(scene: Scene, terms, attitude: bool, s: dict, steps: int, commands: list, wall_time: float,
               compile_time: float, error_estimate, failure: Optional[str]) -> RunResult:
    """The whole run as a :class:`RunResult`: its rows' arrays ``s`` (:func:`sample_arrays`), its ``steps``, the
    ``commands`` applied, its ``wall_time`` and ``compile_time`` (s), its error estimate and ``failure`` (None:
    none)."""
    return RunResult(scene=scene, t=s["t"], L=s["L"], q=s["q"], omega_b=s["omega_b"],
                     torque=s["torque"], energy=s["energy"], stator_names=list(terms.stator_names),
                     current=s["current"], field_rate=s["rate"], field_phase=s["phase"],
                     modes=s["modes"], wall_time=wall_time, compile_time=compile_time,
                     steps=steps, commands=commands, effects=s["effects"], attitude=attitude,
                     error_estimate=error_estimate, failure=failure)
