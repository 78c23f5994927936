"""The physics terms of a scene's model (diffrax's ``_term.py``): what the steppers integrate, assembled once from
the scene and fixed over a run — the rotor's inertia, the eddy-mode model of its conductor (time constants τ_n,
weights w_n, tail, moment scale c_m), the effects packed into one float vector, the stators' triads and coil
constants, the general field's phasors, the free rotor's geometry — with the functions of the run's state they
give: the field's phasors, the eddy modes' answer to a field step, the electrodynamic torque, the effects' outputs,
the body rates. SI units; L in the case frame, the attitude quaternion body → case.

The state (t, y, stator currents, rates and phases) is not held here: it is the
:class:`~gyro_sim.engine.simulator.Simulator`'s, passed in (read, and written only where a function says so).
"""
from __future__ import annotations

import copy
import math

import numpy as np

from gyro_sim.compiled import effects, kernels
from gyro_sim.engine.model import _initial_attitude, body_rates, stator_triad
from gyro_sim.physics.conductor import DEFAULT_N_MODES, conductor_model
from gyro_sim.physics.frames import cross_rows, quat_to_matrix, symmetry_axis
from gyro_sim.scenes.accuracy import truncated_model
from gyro_sim.scenes.limits import stator_limits
from gyro_sim.scenes.scene import Scene

__all__ = ["Terms"]

#: phasors kept (:meth:`Terms.phasors`): the run's and its shadow's, at a check and the segment before
_PH_KEPT = 4


class Terms:
    """The model of ``scene`` (see the module docstring): the eddy-mode model planned by ``mode_plan``
    (:func:`gyro_sim.scenes.accuracy.mode_plan`), the eddy modes in the body frame where ``attitude`` (else in the
    case frame, an isotropic rotor).

    Attributes: ``J``, ``Jinv`` (kg m², 1/(kg m²)); ``conductor`` (None without a torque model); ``tau``, ``w``
    (s, -: the modes' time constants and weights), ``tail`` (s), ``c_m`` (the moment scale), ``tau_min`` (s, the
    fastest mode's, inf without modes), ``lam`` (the linear part's rates λ of y, 1/s); ``eff`` (the effects'
    vector, :func:`gyro_sim.compiled.effects.pack_effects`), ``n_extra`` (the effects' states in y);
    ``stator_names``, ``e1``, ``e2``, ``axes`` (unit vectors, case frame), ``control_axes`` (e1 × e2 as np.cross
    gives it: what a control law is handed), ``b`` (T/A), ``max_current``,
    ``max_rate`` (A, rad/s: :func:`gyro_sim.scenes.limits.stator_limits`); ``field_B`` (T, complex), ``field_om``
    (rad/s): the general field B(t) = Re Σ B_p exp(−i ω_p t); ``free_axis``, ``inv_ref``: the free stepper's
    geometry (:func:`gyro_sim.compiled.kernels.integrate_free`)."""

    def __init__(self, scene: Scene, attitude: bool, mode_plan):
        self.scene = scene
        self.attitude = attitude
        J = scene.inertia
        self.J = J
        self.Jinv = 1.0 / J
        # --- eddy-current model (physics.md §3)
        cond = scene.rotor.conductor
        self.conductor = None
        tau = np.zeros(0)
        w = np.zeros(0)
        tail = 0.0
        c_m = 0.0
        if cond is not None and scene.torque_model == "lag" and scene.effects.magnetizable is not None:
            # the magnetizable body replaces the modes; the conductor gives its default P1, P2 (effects.py)
            self.conductor = conductor_model(cond.kind, cond.outer_radius, cond.conductivity, thickness=cond.thickness,
                                             n_modes=scene.modes or DEFAULT_N_MODES)
        elif cond is not None and scene.torque_model == "lag":
            mp = mode_plan
            self.conductor = truncated_model(cond.kind, cond.outer_radius, cond.conductivity, cond.thickness, mp.n,
                                             mp.tail)
        elif cond is not None and scene.torque_model != "none":
            self.conductor = conductor_model(cond.kind, cond.outer_radius, cond.conductivity,
                                             thickness=cond.thickness)  # quasi-static: τ_eff alone (exact)
        if self.conductor is not None:
            c_m = float(self.conductor.moment_scale)
            if scene.torque_model == "quasi_static":
                tail = float(self.conductor.tau_eff)  # [K] (1.2)
            else:
                tau = np.asarray(self.conductor.tau, dtype=float)
                w = np.asarray(self.conductor.weight, dtype=float)
                tail = float(self.conductor.tail_tau)
        # --- effects (physics.md §4, [BS]); the magnetizable body replaces the eddy-mode model
        self.eff = effects.pack_effects(scene, self.conductor)
        self.n_extra = int(self.eff[effects.NE])
        if scene.effects.magnetizable is not None:
            tau, w, tail, c_m = np.zeros(0), np.zeros(0), 0.0, 0.0
            if scene.torque_model == "none":
                self.eff[effects.MAG] = 0.0
        self.tau, self.w, self.tail, self.c_m = tau, w, tail, c_m
        self.tau_min = float(np.min(tau)) if tau.size else math.inf  # the fastest eddy mode's time constant, s
        self.lam = np.concatenate([np.zeros(7), np.repeat(-1.0 / tau, 3) if tau.size else np.zeros(0),
                                   np.zeros(self.n_extra)])
        # --- stators
        st = scene.stators
        self.stator_names = [s.name for s in st]
        triads = [stator_triad(s.axis) for s in st]
        self.e1 = np.array([t[0] for t in triads]).reshape(-1, 3)
        self.e2 = np.array([t[1] for t in triads]).reshape(-1, 3)
        self.axes = np.array([t[2] for t in triads]).reshape(-1, 3)  # unit stator axes u = e1 × e2
        # e1 × e2 as np.cross takes it: the stator axes a control law sees (ControlInput.stator_axes, the tick loop's)
        self.control_axes = cross_rows(self.e1, self.e2)
        self.b = np.array([s.coil_constant for s in st], dtype=float)
        # each stator's largest current (A) and |field rate| (rad/s): a command beyond is refused (scenes/limits.py)
        self.max_current, self.max_rate = stator_limits(scene)
        # --- general field B(t) = Re Σ B_p exp(−i ω_p t)
        self.field_B = np.array([np.array(f.real) + 1j * np.array(f.imag) for f in scene.field]).reshape(-1, 3)
        self.field_om = np.array([f.frequency for f in scene.field], dtype=float)
        # --- free-rotor geometry: reference inertia and the axis carrying H_r
        if J[0] == J[1] == J[2]:
            self.free_axis, ref = -2, J[0]
        elif J[0] == J[1]:
            self.free_axis, ref = 2, J[0]
        elif J[1] == J[2]:
            self.free_axis, ref = 0, J[1]
        elif J[0] == J[2]:
            self.free_axis, ref = 1, J[0]
        else:
            self.free_axis, ref = -1, J[0]
        if not attitude:
            self.free_axis = -3  # isotropic, modes in the case frame (kernels.free_step)
        self.inv_ref = 1.0 / ref
        # (phasors: the last few, with their keys; shared with the copies: a shadow run at the run's time, currents,
        # rates and phases gets the same phasors, the same bits)
        self._ph: list = []
        self._scratch: dict = {}  # (torque: record_sample's scratch arrays by the phasors' count)
        self._e12 = (self.e1.tolist(), self.e2.tolist(), self.b.tolist())  # (_phasors: Python floats)
        # --- scalars the step plan asks for at every segment (Python floats: no NumPy call there)
        self.sym_axis = symmetry_axis(J)  # the symmetry axis (frozen_flow.supported: −1 triaxial)
        self.Jinv_max = max(self.Jinv.tolist())  # 1/(kg m²)
        self.field_om_max = max(self.field_om.tolist(), default=0.0)  # the general field's largest ω_p (rad/s)
        self.inv_tau = 1.0 / self.tau  # the modes' rates (1/s; the frozen-flow stepper's argument)
        # (the step plan's constants of the model, as StepSize.torque_time and frozen_flow.torque_scale take them)
        self.b_sqrt2 = [math.sqrt(2.0) * b for b in self.b.tolist()]  # √2 b_k (T/A): a stator's |B| an ampere
        self.w_half = 0.5 * sum(abs(v) for v in self.w.tolist())  # ½Σ|w_n|
        self.field_B_norm = sum(float(np.linalg.norm(f)) for f in self.field_B) if self.field_B.size else 0.0
        self.field_om_absmax = max((abs(f) for f in self.field_om.tolist()), default=0.0)  # rad/s
        self.J_min = min(J.tolist())  # kg m²
        self.w_abs = np.abs(np.asarray(self.w, float))

    def copy(self) -> "Terms":
        """A copy for another simulator of the same run (a shadow): the arrays are shared (read only), but for the
        effects' vector (the steppers write its time into it) and the kept phasors."""
        other = copy.copy(self)
        other.eff = self.eff.copy()
        other._scratch = {}
        return other

    # --- the state -------------------------------------------------------------------------------
    def initial_state(self) -> np.ndarray:
        """y at t = 0 from the scene's ``initial`` section: L (N m s, case frame), q (body → case; NaN without
        attitude), the eddy modes at rest (T) and the effects' states (the damper's offset and velocity)."""
        scene = self.scene
        ini = scene.initial
        d = np.asarray(ini.L_direction, dtype=float)
        d /= np.linalg.norm(d)
        Lmag = ini.kinetic_moment if ini.kinetic_moment is not None else self.J[2] * (ini.spin or 0.0)
        y = np.zeros(7 + 3 * self.tau.size + self.n_extra)
        y[0:3] = Lmag * d
        y[3:7] = (_initial_attitude(tuple(d.tolist()), float(ini.psi), float(ini.theta), float(ini.phi))
                  if self.attitude else math.nan)
        if scene.effects.damper is not None:
            k0 = 7 + 3 * self.tau.size
            y[k0:k0 + 3] = scene.effects.damper.offset
            y[k0 + 3:k0 + 6] = scene.effects.damper.velocity
        return y

    # --- the field -------------------------------------------------------------------------------
    def phasors(self, t: float, current: np.ndarray, rate: np.ndarray,
                phase: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(Bre, Bim, ω) of the field from ``t`` on, referred to s = t' − t (case frame, T), under the stators'
        ``current`` (A), ``rate`` (rad/s) and ``phase`` (rad) at ``t``. Kept while the time, currents, rates and
        phases are the same (a run asks for them at its start, its first sample and its step plan): read them, do
        not write into them."""
        key = (t, current.tobytes(), rate.tobytes(), phase.tobytes())
        kept = self._ph
        for k, ph in kept:
            if k == key:
                return ph
        ph = self._phasors(t, current, rate, phase)
        if len(kept) >= _PH_KEPT:
            del kept[0]
        kept.append((key, ph))
        return ph

    def _phasors(self, t: float, current: np.ndarray, rate: np.ndarray,
                 phase: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if not self.field_om.size:
            # the stators alone: the expressions below element by element in Python floats (the same bits; the
            # cosines and sines NumPy's, of the same array), ~5 µs instead of ~9
            cl = current.tolist()
            idx = [i for i, c in enumerate(cl) if c > 0]
            # (one stator on, the usual case: its slice, the mask's elements without the mask)
            on = slice(idx[0], idx[0] + 1) if len(idx) == 1 else current > 0
            pon = phase[on]
            cs, ss = np.cos(pon).tolist(), np.sin(pon).tolist()
            E1, E2, bl = self._e12
            re: list = []
            im: list = []
            for c, s, i in zip(cs, ss, idx, strict=True):
                a, u, v = bl[i] * cl[i], E1[i], E2[i]  # (b I, e1, e2)
                re += (a * (u[0] * c + v[0] * s), a * (u[1] * c + v[1] * s), a * (u[2] * c + v[2] * s))
                im += (a * (-u[0] * s + v[0] * c), a * (-u[1] * s + v[1] * c), a * (-u[2] * s + v[2] * c))
            n = len(idx)
            return (np.array(re, dtype=float).reshape(n, 3), np.array(im, dtype=float).reshape(n, 3),
                    rate[on].copy() if n == 1 else rate[on])  # (ω: a copy, as the mask makes; kept phasors)
        return self._phasors_array(t, current, rate, phase)

    def _phasors_array(self, t: float, current: np.ndarray, rate: np.ndarray,
                       phase: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`_phasors` in NumPy arrays (the general field's terms too; test/test_same_bits.py: the stators' alone
        give the Python-float code's bits)."""
        on = current > 0
        c, s = np.cos(phase[on]), np.sin(phase[on])
        amp = (self.b * current)[on][:, None]
        e1, e2 = self.e1[on], self.e2[on]
        # b I (e1 cos(σ + ν s) + e2 sin(σ + ν s))
        Bre = amp * (e1 * c[:, None] + e2 * s[:, None])
        Bim = amp * (-e1 * s[:, None] + e2 * c[:, None])
        om = rate[on]
        if self.field_om.size:
            # Re(B_p e^{−iω t}) = Re(B̃) cos ωs + Im(B̃) sin ωs with B̃ = B_p e^{−iω t_now}
            Bt = self.field_B * np.exp(-1j * self.field_om * t)[:, None]
            Bre = np.vstack([Bre, Bt.real])
            Bim = np.vstack([Bim, Bt.imag])
            om = np.concatenate([om, self.field_om])
        return np.ascontiguousarray(Bre).reshape(-1, 3), np.ascontiguousarray(Bim).reshape(-1, 3), np.asarray(om, float)

    def field_step(self, y: np.ndarray, before: np.ndarray, after: np.ndarray) -> None:
        """Instant response of the eddy modes of state ``y`` (written in place) to a field step from ``before`` to
        ``after`` (T, case frame): e_n −= Rᵀ ΔB (τ_n ė_n + e_n = −τ_n dB_b/dt); without attitude (modes in the case
        frame) e_n −= ΔB."""
        if self.tau.size == 0:
            return
        dBb = quat_to_matrix(y[3:7]).T @ (after - before) if self.attitude else after - before
        y[7:7 + 3 * self.tau.size] -= np.tile(dBb, self.tau.size)

    # --- what the state gives ----------------------------------------------------------------------
    def torque(self, t: float, y: np.ndarray, ph: tuple) -> np.ndarray:
        """Electrodynamic torque (case frame, N·m) of state ``y`` at ``t`` (s) under the field's phasors ``ph``
        referred to ``t`` (:meth:`phasors`), the effects' torques included."""
        Bre, Bim, om = ph
        F = np.zeros(y.size)
        if not self.attitude:  # the phasors are referred to now: cos, sin(ω_p · 0)
            kernels.nonlinear_part_case(np.ones(om.size), np.zeros(om.size), y, Bre, Bim, om, self.Jinv,
                                        self.c_m, self.w, self.tail, self.tau.size, F, np.zeros(25))
            return F[0:3].copy()
        self.eff[effects.T0] = t
        eff = self.eff if self.eff[effects.ON] != 0.0 else None  # (None: as the frozen / quasi-static flow record)
        sc = self._scratch.get(om.size)  # (record_sample's scratch: it sets F, work and its outputs itself)
        if sc is None or sc[2].size != y.size:
            sc = self._scratch[om.size] = (np.empty(om.size), np.empty(om.size), np.zeros(y.size), np.zeros(25),
                                           np.empty((1, y.size)), np.zeros((1, 3)))
        cs, sn, F, work, out_y, out_N = sc
        # (record_sample: the steppers' own torque, compiled once for both)
        kernels.record_sample(0.0, y, Bre, Bim, om, self.Jinv, self.c_m, self.w, self.tail, self.tau.size,
                              eff, cs, sn, F, work, out_y, out_N, 0, None)
        return out_N[0].copy()

    def effect_outputs(self, t: np.ndarray, Y: np.ndarray) -> dict:
        """Outputs of the effects that are on, for states ``Y`` (rows) at times ``t`` (s), SI:

        ``flywheel_speed`` Ω_f (rad/s), ``flywheel_angle`` ∫Ω_f dt (rad); ``damper_offset`` u and
        ``damper_velocity`` u̇ (body frame, m, m/s); ``vertical_angle`` Θ between x3 and the unbalance's
        vertical (rad).
        """
        ef, out = self.scene.effects, {}
        t = np.asarray(t, float)
        if ef.flywheel is not None:
            out["flywheel_speed"] = np.array([effects.flywheel_speed(float(x), self.eff)[0] for x in t])
            out["flywheel_angle"] = effects.flywheel_angle(t, self.eff)
        if ef.damper is not None:
            k0 = 7 + 3 * self.tau.size
            out["damper_offset"] = Y[:, k0:k0 + 3].copy()
            out["damper_velocity"] = Y[:, k0 + 3:k0 + 6].copy()
        if ef.unbalance is not None:
            x3 = quat_to_matrix(Y[:, 3:7])[:, :, 2]
            out["vertical_angle"] = np.arccos(np.clip(x3 @ np.asarray(ef.unbalance.vertical), -1.0, 1.0))
        return out

    def body_rates(self, t: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """Ω_b (rad/s, body frame) of states ``Y`` (rows) at times ``t`` (s), effects included; without attitude
        Ω = L/J in the case frame."""
        Y = np.atleast_2d(Y)
        if not self.attitude:
            return Y[:, 0:3] * self.Jinv
        if self.eff[effects.ON] == 0.0:
            return body_rates(self.J, Y[:, 0:3], Y[:, 3:7])[1]
        Lb, _ = body_rates(self.J, Y[:, 0:3], Y[:, 3:7])
        k0 = 7 + 3 * self.tau.size
        return np.array([effects.body_rate(float(ti), *Lb[i], Y[i], k0, self.Jinv, self.eff)
                         for i, ti in enumerate(np.broadcast_to(t, (Y.shape[0],)))]).reshape(-1, 3)

    def effect_rate(self, t: float, y: np.ndarray) -> float:
        """Fastest rate (rad/s) an effect brings in state ``y`` at ``t`` (s): the body rate the flywheel drives, the
        damper's spring (0 with no effect on)."""
        if self.eff[effects.ON] == 0.0:
            return 0.0
        ef = self.scene.effects
        rate = float(np.linalg.norm(self.body_rates(t, y)[0]))
        if ef.flywheel is not None:
            fw = ef.flywheel
            rate += fw.inertia * max(abs(v) for v in fw.profile.speed) * float(np.linalg.norm(self.Jinv * fw.axis))
        if ef.damper is not None:
            d = ef.damper
            rate = max(rate, math.sqrt(d.stiffness / d.mass), d.damping / d.mass)
        return rate
