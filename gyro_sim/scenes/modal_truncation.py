"""The eddy modes a run carries (:mod:`gyro_sim.scenes.accuracy`, "Modal error measure"): the truncation error of
a conductor's modal model against the closed forms [M] (2.14), (2.13) over the slips a run can meet, the fewest
modes (and the tail term) within the tolerance's share, and the scene's conductor built from that plan."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Optional

import numpy as np

from gyro_sim.physics.conductor import (ModalModel, g_shell, g_solid_sphere, modal_shell, modal_solid_sphere,
                                        modal_thin_shell, shell_tau_eff)
from gyro_sim.physics.constants import MU0
from gyro_sim.scenes.tolerance import (LEGACY_MODES, MAX_MODES, MODE_SHARE, MODE_TOL_FLOOR, _GRID, field_rates,
                                      is_legacy, planning_attitude, spin_reach, warn)

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


@lru_cache(maxsize=256)
def step_times(kind: str, r2: float, sigma: float, thickness: Optional[float], n: int,
               slip: float) -> tuple[float, float]:
    """(K, T_miss) s: what a field step ΔB costs the modal model of ``n`` modes in torque impulse, beyond the
    steady-state error :func:`modal_error` bounds (issue 28; docs/accuracy.md, "The eddy modes at a field step").

    A field step ΔB (a stator switched on, t = 0 included: the fields are switched on on a rotor free of eddy
    currents) sets every mode e_k −= ΔB (the modes screen it, ĝ → −1); each then decays to its steady state over
    τ_k. The modes k > n the truncated model leaves out do the same in the conductor, but its tail term
    (−T_tail dB/dt) answers at once and keeps no memory of the step: the modes left out make a transient the model
    lacks. From τ_k ė_k + e_k = −τ_k dB_b/dt in a field of amplitude B rotating at slip ω after the step, mode k's
    transient moment, e_k(0+) − ĝ_k B = −ΔB/(1 − iωτ_k) for a step from no field, gives (× c = 2π r2³/μ0, × |B|²
    for a switch-on) the torque impulse c w_k Im[τ_k/(1 − iωτ_k)²] |B|² = c w_k 2ωτ_k²/(1 + ω²τ_k²)² |B|²
    (measured on spinup_solid_sphere: 5, 2, 10 modes against 172, the impulse 2.00 to 2.06 times the same
    formula without the screening; test_estimate_honest). ``K``: the largest Σ_{k>n} of it over slips (0, slip],
    per c |ΔB| |B_after|. A part of ΔB across the field there was makes a torque at once, not through the slip:
    c w_k τ_k |ΔB × B_before| per mode, ``T_miss`` = Σ_{k>n} w_k τ_k per c |ΔB × B_before|. Modes beyond
    :data:`MAX_MODES` count by the bound max_ω 2ωτ²/(1 + ω²τ²)² = (3√3/8) τ and their tail."""
    if kind == "thin_shell" or not slip > 0:
        return 0.0, 0.0
    full = _full_model(kind, float(r2), float(sigma), None if thickness is None else float(thickness))
    tau, w = full.tau[n:], full.weight[n:]
    beyond = max(float(full.tail_tau), 0.0)  # Σ_{k>MAX_MODES} w_k τ_k ([M] (2.14); a shell's: (2.13)'s slope less)
    om = slip * np.geomspace(1e-4, 1.0, _GRID)
    wt = om[:, None] * tau[None, :]
    k = np.sum(w * 2.0 * wt * tau / (1.0 + wt * wt) ** 2, axis=1) if tau.size else np.zeros(om.size)
    return float(np.max(k)) + 3.0 * math.sqrt(3.0) / 8.0 * beyond, float(np.sum(w * tau)) + beyond


def best_tail(kind: str, r2: float, sigma: float, thickness: Optional[float], n: int, slip: float) -> bool:
    """With ``n`` modes given: the tail choice with the smaller error up to ``slip`` (the tail unless it hurts)."""
    if kind == "thin_shell" or not slip > 0 or n > MAX_MODES:
        return kind != "thin_shell"
    a = modal_error(kind, r2, sigma, thickness, n, True, slip)
    b = modal_error(kind, r2, sigma, thickness, n, False, slip)
    return max(a) <= max(b)


def mode_tolerances(rtol: float, attitude: Optional[float], om_reach: float, T: float) -> tuple[float, float]:
    """(tol_g, tol_im) of the modal truncation: :data:`MODE_SHARE` of rtol for both; the Im part also within
    MODE_SHARE × attitude / (Ω_reach T) (the spin phase error ε ∫|Ω − Ω0| dt), where the attitude counts
    (``attitude``: the phases' tolerance, :func:`gyro_sim.scenes.tolerance.planning_attitude`)."""
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

    def step_times(self, slip: float) -> tuple[float, float]:
        """(K, T_miss) s of this truncation up to ``slip`` (rad/s): the torque impulses a field step makes in the
        modes left out and the truncated model lacks (:func:`step_times`; (0, 0) without modes or for a thin
        shell)."""
        if self.kind in (None, "thin_shell") or self.n == 0:
            return 0.0, 0.0
        return step_times(self.kind, self.radius, self.sigma, self.thickness, self.n, slip)

    def step_error(self, slip: float, steps, t: float, c_m: float, J_min: float) -> tuple[float, float]:
        """(N m s, rad): the torque impulse the field steps ``steps`` (Σ |ΔB| |B_after|, Σ t_k |ΔB| |B_after|,
        Σ |ΔB × B_before|, Σ t_k |ΔB × B_before|; T², T² s) made in the modes left out, and the phase it has
        turned by now (``t`` s; the spin rate errs by the impulse over J from each step on)."""
        K, T_miss = self.step_times(max(slip, 0.0))
        if not (K or T_miss):
            return 0.0, 0.0
        a, at, p, pt = (float(x) for x in steps)
        return c_m * (K * a + T_miss * p), c_m * (K * (t * a - at) + T_miss * (t * p - pt)) / J_min


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
    # the Im part's error turns the phases and, through the rates, the axis' cone: the tighter of the two tolerances
    att_plan = min(planning_attitude(scene, om, T), acc.attitude or math.inf) if attitude else math.inf
    tol_g, tol_im = mode_tolerances(acc.rtol, att_plan if math.isfinite(att_plan) else None, om, T)
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


