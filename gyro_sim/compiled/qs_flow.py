"""The quasi-static flow step (``qs_flow``): steps of many field turns for the quasi-static torque.

The frozen-flow step (:mod:`gyro_sim.frozen_flow`) moves the rotor over a step [0, h] by the exact torque-free
motion of an axisymmetric body with L frozen at its mean L̄, and integrates the torque along that motion in closed
form; it is second order in h, and its error is the spin phase: L̄ comes from a pass whose torque was evaluated at
L0, so the phase |L̄| h / J_t misses the torque's own change over the step (measured: the frozen-flow step's
attitude error on the default scene's quasi-static variant is a turn about L, 2.1e-5 rad over 2 s at h = 10 ms,
≈ μ N h² T / (6 J_t) with μ = k_e B²/J the torque's slope in L). This step keeps that motion and removes that
error, for the quasi-static torque [K] (1.2) alone, with its own closed forms (far fewer terms than the
frozen-flow step's general conductor response):

    N = k_e B × (B × Ω + dB/dt) = k_e [M(σ) Ω(σ) + g(σ)],   M = B Bᵀ − |B|² I,   g = B × dB/dt

(case frame; k_e = c_m τ_eff N·m·s/T², physics.md §3; Ω the body rate in the case frame).

*The field's part.* With B(σ) = ½ Σ_p (a_p e^{iν_p σ} + c.c.), a_p = (Bre_p − i Bim_p) e^{iν_p s} (σ the time in
the step, s its start in the command segment), M and g are sums over pairs of the 2P halves of the phasors:

- each phasor with its own conjugate gives constants: M0 = Σ_p ½(Bre Breᵀ + Bim Bimᵀ) − ½(|Bre|² + |Bim|²) I
  (the field-period mean of B Bᵀ − |B|² I) and g0 = Σ_p ν_p Bre_p × Bim_p (the rotating fields' drive, [K] (1.3));
- every other pair (u, v) of halves (P² of them, up to conjugation; frequency f the sum of theirs) gives a
  ripple M_t e^{i f σ} + c.c. with M_t = u vᵀ + v uᵀ − 2(u·v) I (u uᵀ − (u·u) I for a half with itself) and
  g_t = i(ν_v − ν_u) u × v. These are made once per command segment; a step only turns their phase.

*The body's part.* Along the free motion with L̄, the body rate in the case frame is
Ω(σ) = Ω_p l̂ + Ω_r x_a(σ) = o_0 + 2 Re(o_1 e^{iΩ_p σ}), with x_a(σ) = Rot(l̂, Ω_p σ) x_a(0) the symmetry axis,
Ω_p = |L̄|/J_t, Ω_r = (1/J_a − 1/J_t) L̄_a: o_0 = Ω_p l̂ + Ω_r P_0(l̂) x_a, o_1 = Ω_r P_1(l̂) x_a (the spectral
projectors of frozen_flow.py). So N(σ) = C_0 + 2 Re Σ_k C_k e^{z_k σ} with 1 + 3P² terms (z_k ∈ i{Ω_p, f_t,
f_t ± Ω_p}), and ∫N dσ, ∫(h − σ)N dσ and the same with e^{−iΩ_p σ} (the torque seen from the precession, which the
nutation angle and the rate about the axis need) are closed forms (frozen_flow._integrals).

*Three passes.* Pass 1 with L̄ = L0 gives I2_1 = ∫(h − σ)N dσ; pass 2 with L̄ = L0 + I2_1/h gives I2_2. The mean of
L over the step is ∫L/h = L0 + ∫(h − σ)N(L(σ)) dσ / h; with N's slope J_N in L and L(σ) ≈ L0 + N̄σ, pass 1 misses
J_N N̄ h³/6 of it and pass 2 has J_N N̄ h³/4 too much (its L̄ is the mean for all σ), so

    L̄* = L0 + (I2_1 + 2 I2_2) / (3h)

is right to O(h³) per step (and the mean of L_b·e_a, which sets Ω_r, by the same weights). Pass 3 with L̄* gives
ΔL = ∫N dσ and the attitude: the flow's R(h) = Rot(l̂, Ω_p h) R0 Rot(e_a, Ω_r h), turned by the least rotation that
takes R(h) L_b(h) onto L(h), L_b(h) by variation of constants as in frozen_flow.frozen_flow_step.

*The drift-ripple term.* A pass freezes L, but L drifts over the step (D = ΔL/h) while the field's ripple and the
axis's precession modulate the torque's slope in L: ΔL misses k_e ∫(σ − h/2) M(σ) K(σ) D dσ, K = ∂Ω/∂L =
I/J_t + c_r x_a x_aᵀ (:func:`_drift_ripple`), about |M̃ K D| h/f a step, which adds up where the step is a multiple
of the ripple's period (the 50 Hz samples of a 500 Hz field). It is added to the last pass's ΔL.

Measured on the default scene's quasi-static variant over 2 s (no controller, against lawson8 at 3072 steps per
turn), 100 steps (h = 20 ms, 10 field turns and up to 0.3 spin turns a step): 2.4e-10 in L, 1.2e-8 rad, where the
frozen-flow step gives 1.35e-8 and 4.2e-5 rad. The spin phase is third order on a spin-up (8x a halving); where the
ripple acts on a turning L the step is second order (docs/accuracy.md, docs/numerics.md, docs/benchmark.md).

Where it applies: the quasi-static torque model, an axisymmetric or isotropic rotor (frozen_flow.supported), no
effect of physics.md §4; an isotropic rotor without attitude takes the case-frame form (L alone: Ω = L/J).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from gyro_sim.compiled.frozen_flow import _integrals, _proj
from gyro_sim.compiled.kernels import _equal_steps, _pause, _resume_at, _rotl, _steps_now, record_sample

__all__ = ["applies", "integrate_qs", "qs_flow_step", "field_pairs"]


def applies(scene, J: np.ndarray, effects_on: bool) -> bool:
    """Whether the step applies to a scene: quasi-static torque model ([K] (1.2)) with a conductor, an axisymmetric
    or isotropic rotor (principal moments ``J``, kg·m²), no effect on."""
    from gyro_sim.compiled.frozen_flow import supported

    return (scene.torque_model == "quasi_static" and scene.rotor.conductor is not None and supported(J) >= 0
            and not effects_on)


@njit(cache=True)
def field_pairs(Bre, Bim, om, M0, g0, MT, GT, FT):
    """The field's part of the quasi-static torque for phasors (Bre, Bim, ω) (case frame, T, rad/s; referred to
    the segment's start): M0 (6,) the mean of B Bᵀ − |B|² I (T², packed symmetric: xx yy zz xy xz yz), g0 (3,)
    the mean of B × dB/dt (T²/s); per ripple pair t (P² of them) MT[t] (6,) complex (T²), GT[t] (3,) complex
    (T²/s) at phase time 0 and FT[t] its frequency (rad/s). See the module docstring."""
    P = om.shape[0]
    for j in range(6):
        M0[j] = 0.0
    for j in range(3):
        g0[j] = 0.0
    t = 0
    for p in range(P):
        r0, r1, r2 = Bre[p, 0], Bre[p, 1], Bre[p, 2]
        i0, i1, i2 = Bim[p, 0], Bim[p, 1], Bim[p, 2]
        hb = 0.5 * (r0 * r0 + r1 * r1 + r2 * r2 + i0 * i0 + i1 * i1 + i2 * i2)
        M0[0] += 0.5 * (r0 * r0 + i0 * i0) - hb
        M0[1] += 0.5 * (r1 * r1 + i1 * i1) - hb
        M0[2] += 0.5 * (r2 * r2 + i2 * i2) - hb
        M0[3] += 0.5 * (r0 * r1 + i0 * i1)
        M0[4] += 0.5 * (r0 * r2 + i0 * i2)
        M0[5] += 0.5 * (r1 * r2 + i1 * i2)
        # B × dB/dt of B = Bre cos νs + Bim sin νs: ν Bre × Bim
        g0[0] += om[p] * (r1 * i2 - r2 * i1)
        g0[1] += om[p] * (r2 * i0 - r0 * i2)
        g0[2] += om[p] * (r0 * i1 - r1 * i0)
        u0, u1, u2 = 0.5 * complex(r0, -i0), 0.5 * complex(r1, -i1), 0.5 * complex(r2, -i2)  # ½ a_p
        for q in range(p, P):
            a0, a1, a2 = 0.5 * complex(Bre[q, 0], -Bim[q, 0]), 0.5 * complex(Bre[q, 1], -Bim[q, 1]), \
                0.5 * complex(Bre[q, 2], -Bim[q, 2])  # ½ a_q
            for conj in range(2):
                if conj == 1:
                    if q == p:
                        break  # (a_p with ā_p: the constants above)
                    v0, v1, v2 = a0.conjugate(), a1.conjugate(), a2.conjugate()
                    wv = -om[q]
                else:
                    v0, v1, v2 = a0, a1, a2
                    wv = om[q]
                FT[t] = om[p] + wv
                if q == p:  # a half with itself: u uᵀ − (u·u) I, no drive
                    uu = u0 * u0 + u1 * u1 + u2 * u2
                    MT[t, 0], MT[t, 1], MT[t, 2] = u0 * u0 - uu, u1 * u1 - uu, u2 * u2 - uu
                    MT[t, 3], MT[t, 4], MT[t, 5] = u0 * u1, u0 * u2, u1 * u2
                    GT[t, 0] = GT[t, 1] = GT[t, 2] = 0.0
                else:  # u vᵀ + v uᵀ − 2 (u·v) I, g = i (ν_v − ν_u) u × v
                    uv2 = 2.0 * (u0 * v0 + u1 * v1 + u2 * v2)
                    MT[t, 0], MT[t, 1], MT[t, 2] = 2.0 * u0 * v0 - uv2, 2.0 * u1 * v1 - uv2, 2.0 * u2 * v2 - uv2
                    MT[t, 3], MT[t, 4], MT[t, 5] = u0 * v1 + u1 * v0, u0 * v2 + u2 * v0, u1 * v2 + u2 * v1
                    gi = 1j * (wv - om[p])
                    GT[t, 0] = gi * (u1 * v2 - u2 * v1)
                    GT[t, 1] = gi * (u2 * v0 - u0 * v2)
                    GT[t, 2] = gi * (u0 * v1 - u1 * v0)
                t += 1
    return t


@njit(cache=True, inline="always")
def _sym(M, o0, o1, o2):
    """M o for M packed symmetric (xx yy zz xy xz yz; real or complex entries) and a vector o."""
    return (M[0] * o0 + M[3] * o1 + M[4] * o2, M[3] * o0 + M[1] * o1 + M[5] * o2, M[4] * o0 + M[5] * o1 + M[2] * o2)


@njit(cache=True, inline="always")
def _add(c0, c1, c2, i1, i2, out):
    """Add the term 2 Re(c e^{zσ}) of N (N·m; i1, i2 its ∫0^h e^{zσ}, ∫0^h (h − σ)e^{zσ}) to out[0:3] (∫N) and
    out[3:6] (∫(h − σ)N)."""
    out[0] += 2.0 * (c0 * i1).real
    out[1] += 2.0 * (c1 * i1).real
    out[2] += 2.0 * (c2 * i1).real
    out[3] += 2.0 * (c0 * i2).real
    out[4] += 2.0 * (c1 * i2).real
    out[5] += 2.0 * (c2 * i2).real


@njit(cache=True, inline="always")
def _add_k(c0, c1, c2, a1, a2, b1, b2, K, both):
    """Add the term c e^{zσ} + c̄ e^{z̄σ} of N seen from the precession (times e^{−iΩ_p σ}) to K[1] (∫(h − σ)) and,
    with ``both``, K[0] (∫): a1, a2 the integrals of e^{(z − iΩ_p)σ}, b1, b2 those of e^{(z̄ − iΩ_p)σ}."""
    d0, d1, d2 = c0.conjugate(), c1.conjugate(), c2.conjugate()
    if both:
        K[0, 0] += c0 * a1 + d0 * b1
        K[0, 1] += c1 * a1 + d1 * b1
        K[0, 2] += c2 * a1 + d2 * b1
    K[1, 0] += c0 * a2 + d0 * b2
    K[1, 1] += c1 * a2 + d1 * b2
    K[1, 2] += c2 * a2 + d2 * b2


@njit(cache=True, inline="always")
def _qs_pass(Lx, Ly, Lz, La, La0, xa0, xa1, xa2, h, Jt, c_r, k_e, M0, g0, MT, GT, FT, EF, nt, need_k, final, out, K,
             TI):
    """One pass of the step with L frozen at L̄ = (Lx, Ly, Lz) (case, N·m·s) and the axial moment La (N·m·s: sets
    Ω_r = c_r La, c_r = 1/J_a − 1/J_t in 1/(kg·m²)); x_a the symmetry axis at σ = 0 (case), La0 = L0·x_a. MT, GT:
    the ripple pairs at the step's start phase, EF[t] = e^{i f_t h}; TI (nt, 5, 3) complex: the integrals
    (:func:`_integrals3`) of e^{i(f_t + mΩ_p)σ} at TI[t, m + 2].

    out[0:3] = ∫N dσ, out[3:6] = ∫(h − σ)N dσ (N·m·s, N·m·s²), out[10:13] = l̂, out[13] = Ω_p, out[14] = Ω_r (rad/s),
    out[15] = the step's mean of L·x_a (N·m·s; with ``need_k``); K[1] = ∫(h − σ)N e^{−iΩ_p σ} (with ``need_k``) and
    K[0] = ∫N e^{−iΩ_p σ} (with ``need_k`` and ``final``: the step's last pass); out[6], out[7] = e^{iΩ_p h}.

    Every exponent of N and of N e^{−iΩ_p σ} is i(f_t + mΩ_p), m = −2 … 2, or imΩ_p, m = −2 … 2 (the conjugate of
    a positive one, or 0): their integrals are computed once (TI[t, m + 2], J1, J2) and shared."""
    Ln = math.sqrt(Lx * Lx + Ly * Ly + Lz * Lz)
    if Ln > 0.0:
        l0, l1, l2 = Lx / Ln, Ly / Ln, Lz / Ln
    else:  # no rotation: any axis
        l0, l1, l2 = xa0, xa1, xa2
    Op = Ln / Jt
    Or = c_r * La
    Ep = complex(math.cos(Op * h), math.sin(Op * h))
    out[6], out[7] = Ep.real, Ep.imag
    wob = Or != 0.0
    both = need_k and final
    # the integrals of e^{i(f_t + mΩ_p)σ}: m = −1, 0, 1 for N; −2 … 2 for N e^{−iΩ_p σ}
    mlo, mhi = (-2, 3) if need_k else ((-1, 2) if wob else (0, 1))
    for t in range(nt):
        f = FT[t]
        ez = EF[t]
        for _ in range(-mlo):
            ez = ez * Ep.conjugate()
        for m in range(mlo, mhi):
            i1, i2, w = _integrals3(complex(0.0, f + m * Op), ez, h)
            TI[t, m + 2, 0] = i1
            TI[t, m + 2, 1] = i2
            if final:  # (the moments: the drift-ripple term's, after the last pass)
                TI[t, m + 2, 2] = w
            ez = ez * Ep
    j11, j12 = _integrals(complex(0.0, Op), Ep, h)  # e^{iΩ_p σ}
    # Ω(σ) = o0 + 2 Re(o1 e^{iΩ_p σ}) (case frame, rad/s)
    d = l0 * xa0 + l1 * xa1 + l2 * xa2
    o0, o1, o2 = (Op + Or * d) * l0, (Op + Or * d) * l1, (Op + Or * d) * l2
    p0, p1, p2 = _proj(1, l0, l1, l2, xa0 + 0j, xa1 + 0j, xa2 + 0j)
    p0, p1, p2 = Or * p0, Or * p1, Or * p2
    # the constant C0 = k_e (M0 o0 + g0)
    c0, c1, c2 = _sym(M0, o0, o1, o2)
    c0, c1, c2 = k_e * (c0 + g0[0]), k_e * (c1 + g0[1]), k_e * (c2 + g0[2])
    out[0], out[1], out[2] = c0 * h, c1 * h, c2 * h
    hh = 0.5 * h * h
    out[3], out[4], out[5] = c0 * hh, c1 * hh, c2 * hh
    if need_k:  # C0 e^{−iΩ_p σ}
        k1, k2 = j11.conjugate(), j12.conjugate()
        K[0, 0], K[0, 1], K[0, 2] = c0 * k1, c1 * k1, c2 * k1
        K[1, 0], K[1, 1], K[1, 2] = c0 * k2, c1 * k2, c2 * k2
    if wob:  # k_e M0 o1 e^{iΩ_p σ}
        a0, a1, a2 = _sym(M0, p0, p1, p2)
        a0, a1, a2 = k_e * a0, k_e * a1, k_e * a2
        _add(a0, a1, a2, j11, j12, out)
        if need_k:
            j21, j22 = _integrals(complex(0.0, 2.0 * Op), Ep * Ep, h)
            _add_k(a0, a1, a2, h + 0j, hh + 0j, j21.conjugate(), j22.conjugate(), K, both)
    for t in range(nt):
        M = MT[t]
        a0, a1, a2 = _sym(M, o0 + 0j, o1 + 0j, o2 + 0j)
        a0, a1, a2 = k_e * (a0 + GT[t, 0]), k_e * (a1 + GT[t, 1]), k_e * (a2 + GT[t, 2])
        _add(a0, a1, a2, TI[t, 2, 0], TI[t, 2, 1], out)
        if need_k:
            _add_k(a0, a1, a2, TI[t, 1, 0], TI[t, 1, 1], TI[t, 3, 0].conjugate(), TI[t, 3, 1].conjugate(), K,
                   both)
        if wob:
            for sg in range(2):  # k_e M_t o1 at f_t + Ω_p, k_e M_t ō1 at f_t − Ω_p
                if sg == 0:
                    a0, a1, a2 = _sym(M, p0, p1, p2)
                    m = 1
                else:
                    a0, a1, a2 = _sym(M, p0.conjugate(), p1.conjugate(), p2.conjugate())
                    m = -1
                a0, a1, a2 = k_e * a0, k_e * a1, k_e * a2
                _add(a0, a1, a2, TI[t, m + 2, 0], TI[t, m + 2, 1], out)
                if need_k:
                    _add_k(a0, a1, a2, TI[t, m + 1, 0], TI[t, m + 1, 1], TI[t, m + 3, 0].conjugate(),
                           TI[t, m + 3, 1].conjugate(), K, both)
    out[10], out[11], out[12] = l0, l1, l2
    out[13], out[14] = Op, Or
    if need_k:
        # mean over the step of L·x_a = L0·x_a + x_a·∫(h − σ) Rot(l̂, −Ω_p σ) N dσ / h
        g0_, g1_, g2_ = _proj(0, l0, l1, l2, out[3] + 0j, out[4] + 0j, out[5] + 0j)
        q0, q1, q2 = _proj(1, l0, l1, l2, K[1, 0], K[1, 1], K[1, 2])
        out[15] = La0 + (xa0 * (g0_.real + 2.0 * q0.real) + xa1 * (g1_.real + 2.0 * q1.real)
                         + xa2 * (g2_.real + 2.0 * q2.real)) / h


@njit(cache=True, inline="always")
def _integrals3(z, ez, h):
    """frozen_flow._integrals (I1 = ∫0^h e^{zσ} dσ, I2 = ∫0^h (h − σ) e^{zσ} dσ) and the moment
    W = ∫0^h (σ − h/2) e^{zσ} dσ (s, s², s²; complex z, ez = e^{zh}), with one reciprocal of z."""
    zh = z * h
    if zh.real * zh.real + zh.imag * zh.imag < 1e-4:  # |zh| < 1e-2: series, W = h² Σ_k k (zh)^k / (2 (k + 2)!)
        i1, i2 = _integrals(z, ez, h)
        return i1, i2, h * h * zh * (1.0 / 12 + zh * (1.0 / 48 + zh * (1.0 / 80 + zh * (1.0 / 360 + zh / 2016))))
    d = z.real * z.real + z.imag * z.imag  # 1/z without complex division (|z| ≥ 1e-2/h: no overflow)
    r = complex(z.real / d, -z.imag / d)
    i1 = (ez - 1.0) * r
    return i1, (i1 - h) * r, (h * ez - i1) * r - 0.5 * h * i1  # ∫σ e^{zσ} = (h e^{zh} − I1)/z


@njit(cache=True, inline="always")
def _drift_ripple(D0, D1, D2, h, Jt, c_r, k_e, xa0, xa1, xa2, out, M0, MT, nt, TI):
    """The part of ΔL = ∫N dσ (N·m·s) that a pass with L frozen misses where L drifts at D = (D0, D1, D2) (N·m) over
    the step while the field's ripple and the axis's precession modulate the torque's slope in L:
    k_e ∫(σ − h/2) M(σ) K(σ) D dσ, K = ∂Ω/∂L = I/J_t + c_r x_a x_aᵀ along the pass's flow (out[10:15]; TI its
    integrals). Over a step of many ripple periods a frozen pass makes an error of about |M̃ K D| h/f each step,
    which adds up where h is a multiple of the ripple's period (measured: a spin-up at θ = 0.5 with 1 ms steps and a
    500 Hz field, 9e-9 of |L| in 0.2 s without this term, 5e-16 with it)."""
    l0, l1, l2, Op = out[10], out[11], out[12], out[13]
    Ep = complex(out[6], out[7])
    # K D = u0 + 2 Re(u1 e^{iΩ_p σ} + u2 e^{2iΩ_p σ}), x_a(σ) = a + 2 Re(b e^{iΩ_p σ})
    d = l0 * xa0 + l1 * xa1 + l2 * xa2
    a0, a1, a2 = d * l0, d * l1, d * l2
    b0, b1, b2 = _proj(1, l0, l1, l2, xa0 + 0j, xa1 + 0j, xa2 + 0j)
    aD = a0 * D0 + a1 * D1 + a2 * D2
    bD = b0 * D0 + b1 * D1 + b2 * D2
    bc = bD.conjugate()
    u0 = (D0 / Jt + c_r * (a0 * aD + 2.0 * (b0 * bc).real), D1 / Jt + c_r * (a1 * aD + 2.0 * (b1 * bc).real),
          D2 / Jt + c_r * (a2 * aD + 2.0 * (b2 * bc).real))
    u1 = (c_r * (a0 * bD + b0 * aD), c_r * (a1 * bD + b1 * aD), c_r * (a2 * bD + b2 * aD))
    u2 = (c_r * b0 * bD, c_r * b1 * bD, c_r * b2 * bD)
    wob = c_r != 0.0
    # Σ_m w_m v_m first (w_m the moment of each exponent), then one product with each field matrix
    s0 = s1 = s2 = 0.0j
    if wob:  # M0 (u1 w(iΩ_p) + u2 w(2iΩ_p))
        _, _, w1 = _integrals3(complex(0.0, Op), Ep, h)
        _, _, w2 = _integrals3(complex(0.0, 2.0 * Op), Ep * Ep, h)
        s0, s1, s2 = _sym(M0, u1[0] * w1 + u2[0] * w2, u1[1] * w1 + u2[1] * w2, u1[2] * w1 + u2[2] * w2)
    for t in range(nt):  # M_t (u0, u1, ū1, u2, ū2) at f_t + mΩ_p, m = 0, 1, −1, 2, −2
        w = TI[t, 2, 2]
        v0, v1, v2 = u0[0] * w, u0[1] * w, u0[2] * w
        if wob:
            for m in (-2, -1, 1, 2):
                w = TI[t, m + 2, 2]
                if m == 1:
                    v0, v1, v2 = v0 + u1[0] * w, v1 + u1[1] * w, v2 + u1[2] * w
                elif m == -1:
                    v0, v1, v2 = (v0 + u1[0].conjugate() * w, v1 + u1[1].conjugate() * w,
                                  v2 + u1[2].conjugate() * w)
                elif m == 2:
                    v0, v1, v2 = v0 + u2[0] * w, v1 + u2[1] * w, v2 + u2[2] * w
                else:
                    v0, v1, v2 = (v0 + u2[0].conjugate() * w, v1 + u2[1].conjugate() * w,
                                  v2 + u2[2].conjugate() * w)
        c0, c1, c2 = _sym(MT[t], v0, v1, v2)
        s0, s1, s2 = s0 + c0, s1 + c1, s2 + c2
    return 2.0 * k_e * s0.real, 2.0 * k_e * s1.real, 2.0 * k_e * s2.real


@njit(cache=True)
def qs_flow_step(y, s, h, Jt, Ja, ax, k_e, M0, g0, MT0, GT0, FT, nt, MT, GT, EF, out, K, TI, case):
    """One step of length h (s) from phase time s (s since the segment's start) of the quasi-static flow step, in
    place on y (L case N·m·s, q body → case; y[3:7] untouched with ``case``: an isotropic rotor without attitude,
    J = Jt). M0, g0, MT0, GT0, FT, nt: :func:`field_pairs`; MT, GT, EF: scratch (nt, ·) complex; out (16,), K (2, 3)
    complex, TI (nt, 5, 3) complex. See the module docstring."""
    new_h = h != out[9]  # (equal steps between stops: e^{i f_t h} is kept from the step before)
    out[9] = h
    for t in range(nt):  # the ripple pairs' phase at the step's start, and over the step
        ph = complex(math.cos(FT[t] * s), math.sin(FT[t] * s))
        if new_h:
            EF[t] = complex(math.cos(FT[t] * h), math.sin(FT[t] * h))
        for j in range(6):
            MT[t, j] = MT0[t, j] * ph
        for j in range(3):
            GT[t, j] = GT0[t, j] * ph
    Lx, Ly, Lz = y[0], y[1], y[2]
    q0, q1, q2, q3 = y[3], y[4], y[5], y[6]
    if case:
        xa0, xa1, xa2, c_r, need = 0.0, 0.0, 1.0, 0.0, False
    else:
        # the symmetry axis x_a = R e_a (case)
        e0 = 1.0 if ax == 0 else 0.0
        e1 = 1.0 if ax == 1 else 0.0
        e2 = 1.0 if ax == 2 else 0.0
        xa0, xa1, xa2 = _rotl(q0, q1, q2, q3, e0, e1, e2)
        c_r = 1.0 / Ja - 1.0 / Jt
        need = c_r != 0.0  # (Ω_r enters the torque: its mean is needed at every pass)
    La0 = Lx * xa0 + Ly * xa1 + Lz * xa2
    _qs_pass(Lx, Ly, Lz, La0, La0, xa0, xa1, xa2, h, Jt, c_r, k_e, M0, g0, MT, GT, FT, EF, nt, need, False, out, K,
             TI)
    a0, a1, a2, la1 = out[3], out[4], out[5], out[15]
    _qs_pass(Lx + a0 / h, Ly + a1 / h, Lz + a2 / h, la1, La0, xa0, xa1, xa2, h, Jt, c_r, k_e, M0, g0, MT, GT, FT,
             EF, nt, need, False, out, K, TI)
    # the mean of L over the step to O(h³): (I2_1 + 2 I2_2)/(3h) (module docstring); the mean axial moment alike
    b0 = (a0 + 2.0 * out[3]) / (3.0 * h)
    b1 = (a1 + 2.0 * out[4]) / (3.0 * h)
    b2 = (a2 + 2.0 * out[5]) / (3.0 * h)
    la = (la1 + 2.0 * out[15]) / 3.0 if need else La0
    D0, D1, D2 = out[0] / h, out[1] / h, out[2] / h  # L's drift over the step (N·m), from pass 2
    _qs_pass(Lx + b0, Ly + b1, Lz + b2, la, La0, xa0, xa1, xa2, h, Jt, c_r, k_e, M0, g0, MT, GT, FT, EF, nt,
             not case, True, out, K, TI)
    r0, r1, r2 = _drift_ripple(D0, D1, D2, h, Jt, c_r, k_e, xa0, xa1, xa2, out, M0, MT, nt, TI)
    y[0] = Lx + out[0] + r0
    y[1] = Ly + out[1] + r1
    y[2] = Lz + out[2] + r2
    if case:
        return
    # the attitude as frozen_flow.frozen_flow_step makes it: L_b(h) = Rot(e_a, −Ω_r h)(L_b0 + R0ᵀ ∫Rot(l̂, −Ω_p σ)N),
    # the flow R(h) = Rot(l̂, Ω_p h) R0 Rot(e_a, Ω_r h) turned by the least rotation taking R(h) L_b(h) onto L(h)
    l0, l1, l2, Op, Or = out[10], out[11], out[12], out[13], out[14]
    g0_, g1_, g2_ = _proj(0, l0, l1, l2, out[0] + 0j, out[1] + 0j, out[2] + 0j)
    k0, k1, k2 = _proj(1, l0, l1, l2, K[0, 0], K[0, 1], K[0, 2])
    G0 = Lx + g0_.real + 2.0 * k0.real
    G1 = Ly + g1_.real + 2.0 * k1.real
    G2 = Lz + g2_.real + 2.0 * k2.real
    u0, u1, u2 = _rotl(q0, -q1, -q2, -q3, G0, G1, G2)  # R0ᵀ G
    ca, sa = math.cos(Or * h), math.sin(-Or * h)
    if ax == 0:
        u1, u2 = ca * u1 - sa * u2, sa * u1 + ca * u2
    elif ax == 1:
        u2, u0 = ca * u2 - sa * u0, sa * u2 + ca * u0
    else:
        u0, u1 = ca * u0 - sa * u1, sa * u0 + ca * u1
    cp, sp = math.cos(0.5 * Op * h), math.sin(0.5 * Op * h)
    cr, sr = math.cos(0.5 * Or * h), math.sin(0.5 * Or * h)
    r0 = sr if ax == 0 else 0.0
    r1 = sr if ax == 1 else 0.0
    r2 = sr if ax == 2 else 0.0
    # t = q0 ⊗ (cr, r), then f = (cp, sp l̂) ⊗ t
    t0 = q0 * cr - (q1 * r0 + q2 * r1 + q3 * r2)
    t1 = q0 * r0 + q1 * cr + (q2 * r2 - q3 * r1)
    t2 = q0 * r1 + q2 * cr + (q3 * r0 - q1 * r2)
    t3 = q0 * r2 + q3 * cr + (q1 * r1 - q2 * r0)
    p1, p2, p3 = sp * l0, sp * l1, sp * l2
    f0 = cp * t0 - (p1 * t1 + p2 * t2 + p3 * t3)
    f1 = cp * t1 + p1 * t0 + (p2 * t3 - p3 * t2)
    f2 = cp * t2 + p2 * t0 + (p3 * t1 - p1 * t3)
    f3 = cp * t3 + p3 * t0 + (p1 * t2 - p2 * t1)
    c0, c1, c2 = _rotl(f0, f1, f2, f3, u0, u1, u2)
    nc = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    nl = math.sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2])
    if nc > 0.0 and nl > 0.0:
        c0, c1, c2 = c0 / nc, c1 / nc, c2 / nc
        d0, d1, d2 = y[0] / nl, y[1] / nl, y[2] / nl
        w0 = 1.0 + c0 * d0 + c1 * d1 + c2 * d2
        w1, w2, w3 = c1 * d2 - c2 * d1, c2 * d0 - c0 * d2, c0 * d1 - c1 * d0
        nw = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2 + w3 * w3)
        if nw > 0.0:
            w0, w1, w2, w3 = w0 / nw, w1 / nw, w2 / nw, w3 / nw
            f0, f1, f2, f3 = (w0 * f0 - w1 * f1 - w2 * f2 - w3 * f3, w0 * f1 + w1 * f0 + w2 * f3 - w3 * f2,
                              w0 * f2 - w1 * f3 + w2 * f0 + w3 * f1, w0 * f3 + w1 * f2 - w2 * f1 + w3 * f0)
    nq = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2 + f3 * f3)
    y[3], y[4], y[5], y[6] = f0 / nq, f1 / nq, f2 / nq, f3 / nq


@njit(cache=True)
def integrate_qs(y, t0, t_seg, t_stops, record, h_max, Bre, Bim, om, Jinv, Jt, Ja, ax, c_m, w, tail, out_y, out_N,
                 k_out, case=None, pos=None, max_steps=0):
    """Integrate y from t0 (s) through each time in ``t_stops`` with quasi-static flow steps no longer than
    ``h_max`` (equal steps between stops), recording like :func:`gyro_sim.kernels.integrate` (phasors referred
    to t_seg; k_e = c_m × tail, tail = τ_eff). ``case``: an isotropic rotor without attitude (J = Jt). ``pos``,
    ``max_steps``: a bounded call, as :func:`gyro_sim.kernels.integrate`'s (what a step keeps from the step
    before, e^{i f_t h}, is the same numbers made afresh at a call's first step). Returns (k_out, steps)."""
    P = om.shape[0]
    nt = P * P
    M0 = np.empty(6)
    g0 = np.empty(3)
    MT0 = np.empty((max(nt, 1), 6), np.complex128)
    GT0 = np.empty((max(nt, 1), 3), np.complex128)
    FT = np.empty(max(nt, 1))
    nt = field_pairs(Bre, Bim, om, M0, g0, MT0, GT0, FT)
    MT = np.empty((max(nt, 1), 6), np.complex128)
    GT = np.empty((max(nt, 1), 3), np.complex128)
    EF = np.empty(max(nt, 1), np.complex128)
    TI = np.empty((max(nt, 1), 5, 3), np.complex128)
    out = np.zeros(16)
    out[9] = math.nan  # (the step before: none)
    K = np.zeros((2, 3), np.complex128)
    k_e = c_m * tail
    F = np.empty(y.shape[0])
    work = np.empty(25)
    cs = np.empty(P)
    sn = np.empty(P)
    steps = 0
    t = t0
    i0, j0 = _resume_at(pos)
    for i in range(i0, t_stops.shape[0]):
        span = t_stops[i] - t
        if span > 0.0:
            k, h = _equal_steps(span, h_max)
            j1 = _steps_now(pos, max_steps, steps, j0, k)
            for j in range(j0, j1):
                qs_flow_step(y, (t - t_seg) + j * h, h, Jt, Ja, ax, k_e, M0, g0, MT0, GT0, FT, nt, MT, GT, EF, out,
                             K, TI, case is not None)
            steps += j1 - j0
            if j1 < k:
                _pause(pos, i, j1, t)
                return k_out, steps
            j0 = 0
            t = t_stops[i]
        if record[i]:
            record_sample(t - t_seg, y, Bre, Bim, om, Jinv, c_m, w, tail, 0, None, cs, sn, F, work, out_y, out_N,
                          k_out, case)
            k_out += 1
    _pause(pos, t_stops.shape[0], 0, t)
    return k_out, steps
