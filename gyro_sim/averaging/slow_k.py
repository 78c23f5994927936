"""[K]'s averaged model as a fidelity level: three (any number of) stators and the ψ-switching law.

Slow state x = (L1, L2, L3, θ): the kinetic moment in the case frame (N·m·s) and the nutation angle
(rad). For an axisymmetric rotor (J1 = J2 = J, δ = 0) under the quasi-static torque, averaged over the
field phases σ_k and the precession ψ ([K] (1.3), (2.1); physics.md §5; SI as in :mod:`gyro_sim.averaged`):

    dL/dt = Σ_k c_k [ν_k u_k − ½ γΛ (y3 + a_3k u_k)],          c_k = k_e B_k², Λ = |L|/J, a_3k = y3·u_k
    dθ/dt = −¼ κ/(1+κ) g² sinθ cosθ − Σ_n V_n √(1 − a_3n²)/Λ,   g² = Σ_k (c_k/J)(3 − a_3k²)

φ drops out (δ = 0). The stators switched by ψ-switching ([K] (3.1): ν_n = ν sign(u_n·e⊥)) have ⟨ν_n⟩ = 0
over ψ in dL/dt and drive θ by V_n = (2/π) ν_n c_n/J ([K] (3.3) in the vector form of
:meth:`gyro_sim.averaged.PsiSwitchingK.rhs_vector`; docs/averaged_k.md §3).

Where it holds (:meth:`SlowK.check`, each test a ratio ≤ 1, so that ``auto`` never runs it outside):

* ``eps``: ε = Σ c_k/(J Λ) + Σ |V_n|/Λ² ≤ ``MU_MAX`` — the torque changes L little over a precession radian
  (the second term: a switched field's torque, reversed every half precession period, leaves a ripple of L of
  that relative size);
* ``resonance``: every torque harmonic (2|ν_k| and |ν_j| ± |ν_k|) away from 0, Λ and 2Λ: its amplitude A over
  J Λ d (d its distance to the nearest of 0, Λ, 2Λ) ≤ ``MU_MAX``. A = c_k |Ω_⊥k| for 2ν_k (Ω_⊥k the part of
  Ω normal to u_k, bounded from the slow state), √(c_j c_k)(|ν_j| + |ν_k| + Λ) for a pair;
* ``switched``: a switched field swings by ±Λ about |ν_n|: |ν_n| ≥ 10 Λ and ||ν_j| − |ν_k|| ≥ 10 Λ between
  switched stators (docs/averaged_k.md §4: at equal rates the cross terms do not average out);
* ``quasi_static``: the lag model is quasi-static at the body-frame field frequencies: (ω_b τ1)² ≤ ``MU_MAX``,
  ω_b = max|ν_k| + |Ω| (the torque-slip curve departs from its slope by (ω τ)²);
* ``switching``: under ψ-switching θ changes by at most ``PSI_STEP_MAX`` of sinθ in a precession period,
  2π V/(Λ² sinθ) ≤ ``PSI_STEP_MAX``: near θ = 0, π the switching is fast detail, left to the full model
  (and θ stays out of the law's dead band); with the control off (θ inside the dead band) only while θ stays
  inside it (``dead_band``).

And structurally: J1 = J2, no general field, no effect, a controller that is absent, constant
(``off``, ``hold``, ``manual``, ``spinup`` without ramp) or ``psi_switching``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from gyro_sim.averaging.averaged import k21_torque, k_e_of_scene
from gyro_sim.physics.frames import nutation_angle

MU_MAX = 1e-3  # the averaging parameter's bound of every averaged model in the hybrid (gyro_sim/engine/fidelity.py)
PSI_STEP_MAX = 0.05
ENTER_MARGIN = 0.8  # a run enters the region where every ratio is ≤ 0.8 and leaves it where one reaches 1
SWITCHED_RATIO_MIN = 10.0  # |ν_n| and ||ν_j| − |ν_k|| in units of Λ, switched stators
CONSTANT_LAWS = ("off", "hold", "manual", "spinup")


@dataclass(frozen=True)
class SlowK:
    """[K]'s averaged model for the stators that are on (see the module docstring; SI).

    J (kg·m², J1 = J2), J3 (kg·m²), axes (k, 3) unit u_k, c (k,) = k_e B_k² (N·m·s), nu (k,) signed ν_k
    (rad/s; for a switched stator the sign of its law's ν), switched (k,) bool, tau1 (s; 0 for the
    quasi-static torque), dead_band (rad; 0 without ψ-switching).
    """

    J: float
    J3: float
    axes: np.ndarray
    c: np.ndarray
    nu: np.ndarray
    switched: np.ndarray
    tau1: float
    psi: bool = False  # the stators' commands come from the ψ-switching law
    dead_band: float = 0.0  # rad, its dead band
    mu_max: float = MU_MAX  # the ``eps`` test's bound (the hybrid lowers it for a tight accuracy: fidelity.py)

    @property
    def kappa(self) -> float:
        return self.J3 / self.J - 1.0

    @property
    def rates(self) -> np.ndarray:
        """ν_k in dL/dt (rad/s): 0 for the switched stators (their ψ-average)."""
        return np.where(self.switched, 0.0, self.nu)

    @property
    def drive(self) -> np.ndarray:
        """V_n = (2/π) ν_n c_n/J (rad/s²) of the switched stators, 0 for the others ([K] (3.3))."""
        return np.where(self.switched, 2.0 / math.pi * self.nu * self.c / self.J, 0.0)

    # --- the equations -------------------------------------------------------------------------
    def torque(self, L, theta) -> np.ndarray:
        """Averaged torque dL/dt (N·m, case frame) at L (3,) or (n, 3) N·m·s, θ rad: [K] (2.1)."""
        return k21_torque(L, theta, self.J, self.kappa, self.axes, self.c, self.rates)

    def rhs(self, t: float, x: np.ndarray) -> np.ndarray:
        """d(L1, L2, L3, θ)/dt (N·m, rad/s)."""
        L, th = x[0:3], float(x[3])
        Ln = math.sqrt(float(L @ L))
        Lam = Ln / self.J
        a3 = self.axes @ (L / Ln)
        g2 = float(np.sum(self.c / self.J * (3.0 - a3 * a3)))
        s, co = math.sin(th), math.cos(th)
        dth = -0.25 * self.kappa / (1.0 + self.kappa) * g2 * s * co  # [K] (2.1), δ = 0
        if self.switched.any():
            sg = 1.0 if s > 0 else -1.0
            dth -= sg * float(np.sum(self.drive * np.sqrt(np.clip(1.0 - a3 * a3, 0.0, 1.0)))) / Lam  # [K] (3.3)
        dL = self.torque(L, th)
        return np.array([dL[0], dL[1], dL[2], dth])

    # --- where it holds ------------------------------------------------------------------------
    def eps_ratio(self, x: np.ndarray) -> float:
        """The ``eps`` test alone (value/limit) at the slow state x."""
        Ln = math.sqrt(float(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]))
        if not Ln > 0.0:
            return math.inf
        Lam = Ln / self.J
        return (self._C / (self.J * Lam) + self._V / (Lam * Lam)) / self.mu_max

    @property
    def _C(self) -> float:
        return float(np.sum(self.c))

    @property
    def _V(self) -> float:
        return float(np.sum(np.abs(self.drive)))

    def ratios(self, x: np.ndarray) -> dict:
        """Each region test at the slow state x as value/limit (≤ 1 inside); see the module docstring."""
        L, th = np.asarray(x[0:3], dtype=float), float(x[3])
        Ln = math.sqrt(float(L @ L))
        if not Ln > 0.0:
            return {"eps": math.inf}
        J, Lam = self.J, Ln / self.J
        y3 = L / Ln
        out = {"eps": self.eps_ratio(x)}
        # the body rate: Ω = L/J + (1/J3 − 1/J)(L·x3) x3, x3 at θ from y3 (ψ averaged: any side)
        w_ax = Lam * abs(math.cos(th)) * abs(J / self.J3 - 1.0)
        a3 = np.clip(self.axes @ y3, -1.0, 1.0)
        rho = np.arccos(np.abs(a3))  # angle of L from each stator axis
        om_perp = Lam * np.sin(rho) + w_ax * np.sin(np.minimum(rho + th, math.pi / 2))
        nu = np.abs(self.nu)
        amps, freqs = list(self.c * om_perp), list(2.0 * nu)
        k = len(nu)
        for i in range(k):
            for j in range(i + 1, k):
                a = math.sqrt(self.c[i] * self.c[j]) * (nu[i] + nu[j] + Lam)
                amps += [a, a]
                freqs += [nu[i] + nu[j], abs(nu[i] - nu[j])]
        d = np.min(np.abs(np.asarray(freqs)[:, None] - np.array([0.0, Lam, 2.0 * Lam])[None, :]), axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            res = np.where(np.asarray(amps) > 0, np.asarray(amps) / (J * Lam * d), 0.0)
        out["resonance"] = float(np.max(res, initial=0.0)) / MU_MAX
        sw = np.nonzero(self.switched)[0]
        if sw.size:
            worst = max(SWITCHED_RATIO_MIN * Lam / nu[i] for i in sw)
            for a in range(sw.size):
                for b in range(a + 1, sw.size):
                    gap = abs(nu[sw[a]] - nu[sw[b]])
                    worst = max(worst, SWITCHED_RATIO_MIN * Lam / gap if gap > 0 else math.inf)
            out["switched"] = worst
            V = float(np.sum(np.abs(self.drive) * np.sqrt(np.clip(1.0 - a3 * a3, 0.0, 1.0))))
            s = abs(math.sin(th))
            step = 2.0 * math.pi * V / (Lam * Lam * s) if s > 0 else math.inf
            band = 2.0 * self.dead_band / min(th, math.pi - th) if min(th, math.pi - th) > 0 else math.inf
            out["switching"] = max(step / PSI_STEP_MAX, band)
        elif self.psi:  # ψ-switching with its control off: only while θ stays in the dead band
            edge = min(th, math.pi - th)
            out["dead_band"] = edge / self.dead_band if self.dead_band > 0 else (0.0 if edge == 0 else math.inf)
        if self.tau1 > 0.0:
            out["quasi_static"] = self.quasi_static_ratio(x)
        return out

    def quasi_static_ratio(self, x: np.ndarray) -> float:
        """The ``quasi_static`` test alone: (ω_b τ1)²/MU_MAX, ω_b = max|ν_k| + |Ω| bounded by Λ(1 + |J/J3 − 1|)."""
        Lam = math.sqrt(float(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])) / self.J
        wb = float(np.max(np.abs(self.nu), initial=0.0)) + Lam * (1.0 + abs(self.J / self.J3 - 1.0))
        return (wb * self.tau1) ** 2 / MU_MAX

    def check(self, x: np.ndarray, margin: float = 1.0) -> tuple[bool, str]:
        """(ok, reason) of the region tests at the slow state x, each ratio ≤ ``margin`` (``ENTER_MARGIN`` where
        a run enters the model: it leaves at 1, so the full state's ripple cannot toggle it in and out)."""
        r = {"eps": self.eps_ratio(x)}  # the cheap tests first: most failures end here
        if self.tau1 > 0.0 and r["eps"] <= margin:
            r["quasi_static"] = self.quasi_static_ratio(x)
        if max(r.values()) <= margin:
            r = self.ratios(x)
        bad = {k: v for k, v in r.items() if not v <= margin}
        if not bad:
            return True, ", ".join(f"{k} {v:.2g}" for k, v in r.items()) + " of their limits"
        return False, "; ".join(f"{k}: {v:.3g} × its limit" for k, v in bad.items()) + \
            f" ([K]'s region, gyro_sim/averaging/slow_k.py: ε ≤ {MU_MAX:g}, ψ-step ≤ {PSI_STEP_MAX:g})"

    def exit_event(self):
        """solve_ivp event (terminal, falling): 1 − the largest ratio, ≥ 0 inside the region."""
        def leave(t, x):
            return 1.0 - max(self.ratios(x).values())

        leave.terminal, leave.direction = True, -1
        return leave


def slow_k_of(runner) -> tuple[Optional[SlowK], str]:
    """[K]'s averaged model for the runner's present commands, or (None, why it does not apply)."""
    scene, sim = runner.scene, runner.sim
    J = scene.inertia
    if abs(J[1] - J[0]) > 1e-9 * J[0]:
        return None, f"rotor.inertia = {list(J)}: [K]'s model here needs J1 = J2"
    if scene.field:
        return None, "a general field is present"
    if scene.effects.any:
        return None, "effects are on"
    if scene.torque_model not in ("quasi_static", "lag") or sim.conductor is None:
        return None, f"torque_model = {scene.torque_model!r}: [K]'s model is the eddy torque"
    ctl = scene.controller
    if ctl is not None and not (ctl.law == "psi_switching" or (ctl.law in CONSTANT_LAWS and getattr(ctl.params, "ramp", None) is None)):
        return None, f"controller law {ctl.law!r} does not hold its commands"
    on = np.nonzero(sim.current > 0)[0]
    if not on.size:
        return None, "no stator on"
    switched = np.zeros(on.size, dtype=bool)
    nu = sim.rate[on].astype(float)
    dead_band, psi = 0.0, ctl is not None and ctl.law == "psi_switching"
    if psi:
        p = ctl.params
        for i, name in enumerate(p.control_stators):
            k = sim.stator_names.index(name)
            hit = np.nonzero(on == k)[0]
            if hit.size:
                switched[hit[0]] = True
                nu[hit[0]] = math.copysign(abs(sim.rate[k]), p.rate(i))
        dead_band = p.dead_band
    c = k_e_of_scene(scene) * (sim.b[on] * sim.current[on]) ** 2
    tau1 = float(np.max(sim.tau)) if sim.tau.size else 0.0
    return SlowK(J=float(J[0]), J3=float(J[2]), axes=sim.axes[on].copy(), c=c, nu=nu, switched=switched,
                 tau1=tau1, psi=psi, dead_band=dead_band), ""


def slow_state(sim) -> np.ndarray:
    """(L1, L2, L3 N·m·s case frame, θ rad) of a simulator's present state."""
    return np.append(sim.y[0:3], nutation_angle(sim.y[3:7], sim.y[0:3]))


__all__ = ["SlowK", "slow_k_of", "slow_state", "MU_MAX", "PSI_STEP_MAX", "ENTER_MARGIN"]
