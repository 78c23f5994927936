"""The frozen-flow step: field oscillations and eddy modes in closed form, steps longer than a field turn.

Over a step [0, h] the kinetic moment is frozen at its mean value L̄ = (1/h)∫L ds; the rotor then
turns by the exact torque-free motion of an axisymmetric body with moment L̄ (case frame)

    R(s) = Rot(l̂, Ω_p s) R0 Rot(e_a, Ω_r s),   Ω_p = |L̄|/J_t,   Ω_r = (1/J_a − 1/J_t) L̄·R0 e_a,

with e_a the body's symmetry axis (J_t the transverse, J_a the axial moment; an isotropic body has
Ω_r = 0). Along that motion every field term is a sum of exponentials: with the spectral projectors
of a rotation about n, Rot(n, φ) = Σ_{m=−1,0,1} P_m(n) e^{imφ} (P_0 = n nᵀ,
P_±1 = ½(I − n nᵀ ∓ i[n]×)), a case phasor a e^{iνs} seen from the body is

    B_b(s) = Re Σ_{m1,m2} P_m2(e_a) R0ᵀ P_m1(l̂) a e^{i(ν − m1 Ω_p − m2 Ω_r) s},

so each eddy mode (τ_n ė_n + e_n = −τ_n dB_b/dt, :mod:`gyro_sim.kernels`) is solved exactly, the
induced moment m_b = c(Σ w_n e_n − T_tail dB_b/dt) is a sum of exponentials (each component of
the field answered with the conductor's response χ(f) = c(−Σ_n w_n i f/(1/τ_n + i f) − T_tail i f)
at its own body-frame frequency f, the free decay of the modes' initial mismatch on top), and so is
the torque N = (R m_b) × B (case frame). Its integral ΔL = ∫N ds and its first moment
∫(h − s)N ds (which gives the mean L̄ = L0 + (1/h)∫(h − s)N ds) are closed forms. Three passes: L̄ = L0,
then L̄ from the first pass's moment, then L̄* = L0 + (I2₁ + 2 I2₂)/(3h), the mean right to O(h³) (the first pass
misses J_N N̄ h³/6 of ∫(h − s)N, the second has J_N N̄ h³/12 too much; as the quasi-static flow step's).

The only approximation is the frozen L̄ inside the step: the rotation phase ∫Ω ds is right to
second order (L̄ is the mean, not the midpoint value, so the fast start of a step, where the modes
settle from the previous step's flow, costs no phase), the rest to first order in the change of L
over a step. Nothing here resolves the field frequency or the spin: the step is bounded by how fast
L changes (docs/numerics.md measures error against step). Valid for an isotropic or axisymmetric
rotor with electrodynamic torque only (no effects of physics.md §4).

An isotropic rotor without attitude (modes in the case frame, :mod:`gyro_sim.kernels`) takes
:func:`frozen_flow_step_case`: no R0, no nutation integrals; the moment's forced part is one term per phasor
at the field's own frequency (the body's turn cancels on the way back to the case frame).
"""
from __future__ import annotations

import cmath
import math

import numpy as np
from numba import njit

from gyro_sim.physics.frames import quat_to_matrix, symmetry_axis
from gyro_sim.compiled.kernels import _equal_steps, _pause, _resume_at, _rotl, _steps_now, record_sample

__all__ = ["integrate_frozen", "frozen_flow_step", "frozen_flow_step_case", "steady_modes", "supported",
           "torque_scale"]


def supported(J: np.ndarray) -> int:
    """Index (0, 1, 2) of the symmetry axis of principal moments ``J`` (2 for an isotropic body), −1 if
    triaxial (the frozen-flow step needs the free motion in closed form): :func:`gyro_sim.physics.frames.
    symmetry_axis`."""
    return symmetry_axis(J)


#: the local torque scale is taken no smaller than this fraction of the bound at the largest slip: a frozen-flow
#: step grows at most this many times as the torque dies away (a spin-up near synchronism, a nutation damped out)
LOCAL_SCALE_MIN = 1e-4


def torque_scale(Bre, Bim, om, L, Jt, Ja, e_a, c_m, w, tau, tail) -> float:
    """The size (N m) of the mean torque the field gives at the present slips, for the frozen-flow step: with the
    body turning about l̂ = L/|L| at Ω_p = |L|/J_t and about its axis e_a (case frame; None: isotropic) at
    Ω_r = (1/J_a − 1/J_t) L·e_a (the free motion of the module docstring), the part P_m(l̂) a of each phasor a
    (``Bre`` − i ``Bim``, T, rate ``om`` rad/s) meets the conductor at the body-frame frequencies
    f = ν − m Ω_p − m₂ Ω_r (m, m₂ ∈ {−1, 0, 1}), where its dissipative response is
    g(f) = Σ_n |w_n| |f|τ_n/(1 + (fτ_n)²) + T_tail|f| (at most ½Σ|w_n| + T_tail|f|: the bound
    :meth:`gyro_sim.engine.simulator.Simulator._torque_time` takes at the largest slip). Returns
    c (Σ_k |a_k|) Σ_k Σ_m |P_m(l̂) a_k| max_m₂ g(f): an upper bound of the mean torque now, which falls with the
    slip as a spin-up nears the field's rate and with the transverse field seen as a nutation is damped."""
    om = np.asarray(om, float)
    if not om.size:
        return math.inf
    has_axis = e_a is not None
    ea = np.asarray(e_a, float) if has_axis else np.zeros(3)
    return _torque_scale(np.ascontiguousarray(Bre, float), np.ascontiguousarray(Bim, float), om,
                         np.asarray(L, float), float(Jt), float(Ja), ea, has_axis, float(c_m),
                         np.abs(np.asarray(w, float)), np.asarray(tau, float), float(tail))


@njit(cache=True)
def _torque_scale(Bre, Bim, om, L, Jt, Ja, ea, has_axis, c_m, w, tau, tail):
    """:func:`torque_scale` in compiled code (``w``: |w_n|; ``has_axis`` False: no axis term)."""
    Lm = math.sqrt(L[0] * L[0] + L[1] * L[1] + L[2] * L[2])
    if Lm == 0.0:
        return math.inf
    n0, n1, n2 = L[0] / Lm, L[1] / Lm, L[2] / Lm
    om_p = Lm / Jt
    om_r = (1.0 / Ja - 1.0 / Jt) * (L[0] * ea[0] + L[1] * ea[1] + L[2] * ea[2]) if has_axis else 0.0
    N = 0.0
    a_sum = 0.0
    for k in range(om.shape[0]):
        a0 = complex(Bre[k, 0], -Bim[k, 0])
        a1 = complex(Bre[k, 1], -Bim[k, 1])
        a2 = complex(Bre[k, 2], -Bim[k, 2])
        a_sum += math.sqrt(abs(a0) ** 2 + abs(a1) ** 2 + abs(a2) ** 2)
        for m in (-1, 0, 1):
            p0, p1, p2 = _proj(m, n0, n1, n2, a0, a1, a2)
            amp = math.sqrt(abs(p0) ** 2 + abs(p1) ** 2 + abs(p2) ** 2)
            gm = 0.0
            for m2 in (-1, 0, 1):
                f = abs(om[k] - m * om_p - m2 * om_r)
                g = tail * f
                for j in range(w.shape[0]):
                    ft = f * tau[j]
                    g += w[j] * ft / (1.0 + ft * ft)
                gm = max(gm, g)
            N += amp * gm
    return c_m * a_sum * N


@njit(cache=True, inline="always")
def _proj(m, n0, n1, n2, v0, v1, v2):
    """P_m(n) v for m = −1, 0, 1 (complex v; n a real unit vector)."""
    d = n0 * v0 + n1 * v1 + n2 * v2
    if m == 0:
        return n0 * d, n1 * d, n2 * d
    g = -0.5j if m == 1 else 0.5j
    return (0.5 * (v0 - n0 * d) + g * (n1 * v2 - n2 * v1),
            0.5 * (v1 - n1 * d) + g * (n2 * v0 - n0 * v2),
            0.5 * (v2 - n2 * d) + g * (n0 * v1 - n1 * v0))


@njit(cache=True, inline="always")
def _integrals(z, ez, h):
    """I1 = ∫_0^h e^{zs} ds and I2 = ∫_0^h (h − s) e^{zs} ds (complex z; ez = e^{zh})."""
    zh = z * h
    if zh.real * zh.real + zh.imag * zh.imag < 1e-4:  # |zh| < 1e-2
        # Σ_k (zh)^k/(k+1)!, Σ_k (zh)^k/(k+2)!: the terms left out are < 1e-14 relative
        return (h * (1.0 + zh * (1.0 / 2 + zh * (1.0 / 6 + zh * (1.0 / 24 + zh / 120)))),
                h * h * (1.0 / 2 + zh * (1.0 / 6 + zh * (1.0 / 24 + zh * (1.0 / 120 + zh / 720)))))
    d = z.real * z.real + z.imag * z.imag  # 1/z without complex division (|z| ≥ 1e-2/h: no overflow)
    r = complex(z.real / d, -z.imag / d)
    i1 = (ez - 1.0) * r
    return i1, (i1 - h) * r  # (e^{zh} − 1 − zh)/z²



@njit(cache=True, inline="always")
def _mode_mismatch(y, S, n, scale):
    """``scale`` × (e_n − Re S_n): eddy mode n's departure from its particular solution S_n (T), whose free decay
    the pass adds to the moment (scale = c_m w_n gives A·m²)."""
    i0 = 7 + 3 * n
    return scale * (y[i0] - S[n, 0].real), scale * (y[i0 + 1] - S[n, 1].real), scale * (y[i0 + 2] - S[n, 2].real)


@njit(cache=True, inline="always")
def _field_half(A, q, sg, z, ez, om_q, eo_q):
    """Half sg of phasor q of B = ½ Σ_q (a_q e^{iν_q s} + conj) (T) times a moment term e^{z s}: (a or ā, the
    product's exponent z ± iν_q, its factor at s = h)."""
    a0, a1, a2 = A[q, 0], A[q, 1], A[q, 2]
    if sg == 1:
        return a0.conjugate(), a1.conjugate(), a2.conjugate(), z - 1j * om_q, ez * eo_q.conjugate()
    return a0, a1, a2, z + 1j * om_q, ez * eo_q


@njit(cache=True, inline="always")
def _half_cross(x0, x1, x2, a0, a1, a2):
    """½ x × a (complex 3-vectors)."""
    return 0.5 * (x1 * a2 - x2 * a1), 0.5 * (x2 * a0 - x0 * a2), 0.5 * (x0 * a1 - x1 * a0)


@njit(cache=True, inline="always")
def _torque_term(x0, x1, x2, a0, a1, a2, zq, ezq, h, out, end=True):
    """One product term of N = m × B, ½ x × a e^{zq s} (N·m): adds its ∫0^h to out[0:3] (only with ``end``: a
    pass whose ∫N the step's end reads) and its ∫0^h (h − s) to out[3:6]; returns ½ x × a."""
    i1, i2 = _integrals(zq, ezq, h)
    n0, n1, n2 = _half_cross(x0, x1, x2, a0, a1, a2)
    _add_integrals(n0, n1, n2, i1, i2, out, end)
    return n0, n1, n2


@njit(cache=True, inline="always")
def _add_integrals(n0, n1, n2, i1, i2, out, end):
    """out[0:3] += Re(n i1) (only with ``end``), out[3:6] += Re(n i2): a product term n e^{zs}'s ∫ and ∫(h − s)."""
    if end:
        out[0] += (n0 * i1).real
        out[1] += (n1 * i1).real
        out[2] += (n2 * i1).real
    out[3] += (n0 * i2).real
    out[4] += (n1 * i2).real
    out[5] += (n2 * i2).real

@njit(cache=True, inline="always")
def _epow(E, k):
    """E^k for |E| = 1 and k in −2 … 2."""
    if k == 0:
        return 1.0 + 0j
    if k == 1:
        return E
    if k == -1:
        return E.conjugate()
    if k == 2:
        return E * E
    return (E * E).conjugate()


#: what a pass of the frozen-flow step makes of K1 (the torque seen from the precession, _flow_pass): K1[1], which
#: only the axial mean moment out[15] reads (the predictor passes: the next pass's Ω_r), K1[0], which only the step's
#: end reads (the last pass), or both
K1_MEAN, K1_END, K1_BOTH = 1, 2, 3


@njit(cache=True, inline="always")
def _shifted(zq, ezq, Op, Ep, h, precess):
    """∫0^h and ∫0^h (h − s) of e^{(zq + iμΩ_p)s} for μ = −2 … 2 (ezq = e^{zq h}, Ep = e^{iΩ_p h}): ten complex
    numbers, (I1, I2) at μ = −2, −1, 0, 1, 2; without ``precess`` only μ = −1 … 1 (the others zero)."""
    Epc = Ep.conjugate()
    a1, a2 = _integrals(complex(zq.real, zq.imag - Op), ezq * Epc, h)
    b1, b2 = _integrals(zq, ezq, h)
    c1, c2 = _integrals(complex(zq.real, zq.imag + Op), ezq * Ep, h)
    if not precess:
        return 0j, 0j, a1, a2, b1, b2, c1, c2, 0j, 0j
    m1, m2 = _integrals(complex(zq.real, zq.imag - 2.0 * Op), ezq * (Epc * Epc), h)
    p1, p2 = _integrals(complex(zq.real, zq.imag + 2.0 * Op), ezq * (Ep * Ep), h)
    return m1, m2, a1, a2, b1, b2, c1, c2, p1, p2


@njit(cache=True, inline="always")
def _add_product(n0, n1, n2, i1, i2, lo1, lo2, hi1, hi2, out, K1, end, precess, k1_part):
    """Add one product term n e^{zs} (n = ½ x × a, N·m) of the torque: its ∫ (i1: only with ``end``) and
    ∫(h − s) (i2) to out[0:6], and to K1 the precession's view of it, ½(n e^{zs} + conj) e^{−iΩ_p s}: n times the ∫
    one shift below (lo1, lo2) and the conjugate of n times the ∫ one shift above (hi1, hi2)."""
    _add_integrals(n0, n1, n2, i1, i2, out, end)
    if not precess:
        return
    if k1_part & K1_END:
        K1[0, 0] += 0.5 * (n0 * lo1 + (n0 * hi1).conjugate())
        K1[0, 1] += 0.5 * (n1 * lo1 + (n1 * hi1).conjugate())
        K1[0, 2] += 0.5 * (n2 * lo1 + (n2 * hi1).conjugate())
    if k1_part & K1_MEAN:
        K1[1, 0] += 0.5 * (n0 * lo2 + (n0 * hi2).conjugate())
        K1[1, 1] += 0.5 * (n1 * lo2 + (n1 * hi2).conjugate())
        K1[1, 2] += 0.5 * (n2 * lo2 + (n2 * hi2).conjugate())


@njit(cache=True, inline="always")
def _family(X, j, zb, ezb, A, q, sg, om_q, eo_q, Op, Ep, h, out, K1, end, precess, k1_part):
    """The products with half sg of field phasor q of a family of three moment terms X[j + m3 + 1] e^{(zb + im3Ω_p)s}
    (m3 = −1, 0, 1; ezb = e^{zb h}): five ∫ serve its three terms and their views from the precession
    (:func:`_add_product`), where each term alone took three."""
    a0, a1, a2, zq, ezq = _field_half(A, q, sg, zb, ezb, om_q, eo_q)
    m1, m2, a1_, a2_, b1, b2, c1, c2, p1, p2 = _shifted(zq, ezq, Op, Ep, h, precess)
    n0, n1, n2 = _half_cross(X[j, 0], X[j, 1], X[j, 2], a0, a1, a2)  # m3 = −1
    _add_product(n0, n1, n2, a1_, a2_, m1, m2, b1, b2, out, K1, end, precess, k1_part)
    n0, n1, n2 = _half_cross(X[j + 1, 0], X[j + 1, 1], X[j + 1, 2], a0, a1, a2)  # m3 = 0
    _add_product(n0, n1, n2, b1, b2, a1_, a2_, c1, c2, out, K1, end, precess, k1_part)
    n0, n1, n2 = _half_cross(X[j + 2, 0], X[j + 2, 1], X[j + 2, 2], a0, a1, a2)  # m3 = 1
    _add_product(n0, n1, n2, c1, c2, b1, b2, p1, p2, out, K1, end, precess, k1_part)


#: from this many eddy modes on, a pass sums the modes' free-decay terms mode by mode before the products with the
#: field (_decay_sums): each term is linear in its mode's mismatch D_n, so per mode only its five ∫ remain, against
#: three terms' projections and products; below, the fixed work of the sums costs more than it saves
MODE_SUM_MIN = 4


@njit(cache=True)
def _decay_sums(X, EZ, k, nm, lam, R, ax, l0, l1, l2, A, om, EO, Op, Or, Ep, Er, h, out, K1, end, precess, k1_part):
    """The products of the modes' free decay with the field, summed over the modes first: the term of mode n,
    (m2, m3) is P_m3(l̂) R0 P_m2(e_a) D_n e^{(−1/τ_n + i(m3Ω_p + m2Ω_r))s} (D_n = X[k + n] real, e^{−h/τ_n} =
    EZ[k + n]), so for each (m2, field half, shift μ) W = R0 P_m2(e_a) Σ_n D_n ∫ e^{(…)s} is one vector, and the
    products are those of P_m3(l̂) W: what :func:`_family` adds term by term, to the same sums."""
    e0 = 1.0 if ax == 0 else 0.0
    e1 = 1.0 if ax == 1 else 0.0
    e2 = 1.0 if ax == 2 else 0.0
    lo, hi = (-2, 3) if precess else (-1, 2)
    far = True
    for n in range(nm):
        far = far and lam[n] * h >= 1e-2
    for m2 in range(-1, 2):
        for q in range(om.shape[0]):
            for sg in range(2):
                a0, a1, a2, zq, ezq = _field_half(A, q, sg, complex(0.0, m2 * Or), _epow(Er, m2), om[q], EO[q])
                for mu in range(lo, hi):
                    zi = zq.imag + mu * Op
                    em = ezq * _epow(Ep, mu)
                    s10 = s11 = s12 = s20 = s21 = s22 = 0j
                    for n in range(nm):
                        if far:  # (|zh| ≥ h/τ_n ≥ 1e-2 for every mode: _integrals' closed form, without its test)
                            d = 1.0 / (lam[n] * lam[n] + zi * zi)
                            rz = complex(-lam[n] * d, -zi * d)  # 1/z
                            i1 = (EZ[k + n].real * em - 1.0) * rz
                            i2 = (i1 - h) * rz
                        else:
                            i1, i2 = _integrals(complex(-lam[n], zi), EZ[k + n].real * em, h)
                        d0, d1, d2 = X[k + n, 0].real, X[k + n, 1].real, X[k + n, 2].real
                        if end:
                            s10 += d0 * i1
                            s11 += d1 * i1
                            s12 += d2 * i1
                        s20 += d0 * i2
                        s21 += d1 * i2
                        s22 += d2 * i2
                    W0, W1, W2 = _body_to_case(m2, e0, e1, e2, s20, s21, s22, R)  # R0 P_m2(e_a) Σ D_n ∫(h − s)
                    V0, V1, V2 = _body_to_case(m2, e0, e1, e2, s10, s11, s12, R)  # R0 P_m2(e_a) Σ D_n ∫
                    if -1 <= mu <= 1:  # the term m3 = μ itself
                        n0, n1, n2 = _seen(mu, l0, l1, l2, W0, W1, W2, a0, a1, a2, False)
                        out[3] += n0.real
                        out[4] += n1.real
                        out[5] += n2.real
                        if end:
                            n0, n1, n2 = _seen(mu, l0, l1, l2, V0, V1, V2, a0, a1, a2, False)
                            out[0] += n0.real
                            out[1] += n1.real
                            out[2] += n2.real
                    if not precess:
                        continue
                    # the view from the precession: the term m3 = μ + 1 times this shift, the conjugate of m3 = μ − 1's
                    for side in range(2):
                        m3, cj = mu + 1 - 2 * side, side == 1
                        if m3 < -1 or m3 > 1:
                            continue
                        if k1_part & K1_END:
                            n0, n1, n2 = _seen(m3, l0, l1, l2, V0, V1, V2, a0, a1, a2, cj)
                            K1[0, 0] += 0.5 * n0
                            K1[0, 1] += 0.5 * n1
                            K1[0, 2] += 0.5 * n2
                        if k1_part & K1_MEAN:
                            n0, n1, n2 = _seen(m3, l0, l1, l2, W0, W1, W2, a0, a1, a2, cj)
                            K1[1, 0] += 0.5 * n0
                            K1[1, 1] += 0.5 * n1
                            K1[1, 2] += 0.5 * n2


@njit(cache=True, inline="always")
def _body_to_case(m2, e0, e1, e2, s0, s1, s2, R):
    """R0 P_m2(e_a) s: a body-frame vector's part m2 about the symmetry axis e_a, in the case frame."""
    c0, c1, c2 = _proj(m2, e0, e1, e2, s0, s1, s2)
    return (R[0, 0] * c0 + R[0, 1] * c1 + R[0, 2] * c2, R[1, 0] * c0 + R[1, 1] * c1 + R[1, 2] * c2,
            R[2, 0] * c0 + R[2, 1] * c1 + R[2, 2] * c2)


@njit(cache=True, inline="always")
def _seen(m, l0, l1, l2, W0, W1, W2, a0, a1, a2, cj):
    """½ P_m(l̂)W × a (its conjugate with ``cj``): the product of a case-frame moment's part m about l̂ with a field
    half."""
    x0, x1, x2 = _proj(m, l0, l1, l2, W0, W1, W2)
    n0, n1, n2 = _half_cross(x0, x1, x2, a0, a1, a2)
    if cj:
        return n0.conjugate(), n1.conjugate(), n2.conjugate()
    return n0, n1, n2


@njit(cache=True)
def _flow_pass(Lx, Ly, Lz, La, y, R, s, h, Bre, Bim, om, Jt, Ja, ax, lam, w, c_m, tail, nm, A, X, Z, EZ, EO, S, E_end,
               out, K1, precess=True, k1_part=K1_BOTH):
    """One pass of the step with L̄ = (Lx, Ly, Lz) (case): out[0:3] = ∫N ds, out[3:6] = ∫(h − s)N ds,
    out[6:10] = the attitude quaternion at s = h; E_end (nm, 3) complex receives the oscillating part of
    each mode at s = h. ``R`` is R0 (body → case), ``A`` (P, 3) the case phasors a_p = (Bre − iBim)e^{iν s},
    EO (P,) = e^{iν_p h}. Every exponential of the step is a product of e^{iν_p h}, e^{iΩ_p h}, e^{iΩ_r h}
    and e^{−h/τ_n} (EZ[k] = e^{Z[k] h}): a few exp calls a pass, not three per term. The moment's terms X[k]
    e^{Z[k] s} come in families of three (m3 = −1, 0, 1), whose products with the field share five ∫
    (:func:`_family`); from :data:`MODE_SUM_MIN` modes on, the modes' free-decay terms are summed over the modes
    before those products (:func:`_decay_sums`; X[k + n] then holds D_n, EZ[k + n] e^{−h/τ_n}). ``precess`` False:
    K1 is not made and out[15] takes ∫(h − s)N along e_a without the precession's part (K1's): a pass whose K1 and
    out[15] serve only Ω_r = (1/J_a − 1/J_t) L̄_a, which is zero for an isotropic body whatever L̄_a (its first two
    passes: two fifths of their ∫). ``k1_part``: which of K1's rows the pass makes
    (:data:`K1_MEAN`, :data:`K1_END`, :data:`K1_BOTH`): each pass reads only one of them (the predictors K1[1],
    through out[15]; the last K1[0]; the row left out stays zero; without K1[1], out[15] is NaN). Without K1_END
    (a predictor) the pass also leaves out what only the step's end reads: out[0:3] (∫N ds) stays zero and E_end is
    not made."""
    P = om.shape[0]
    end = (k1_part & K1_END) != 0  # (the pass whose ∫N, modes and K1[0] the step's end reads)
    Ln = math.sqrt(Lx * Lx + Ly * Ly + Lz * Lz)
    xa0, xa1, xa2 = R[0, ax], R[1, ax], R[2, ax]  # symmetry axis in the case frame
    if Ln > 0.0:
        l0, l1, l2 = Lx / Ln, Ly / Ln, Lz / Ln
    else:  # no rotation: any axis
        l0, l1, l2 = xa0, xa1, xa2
    Op = Ln / Jt
    if math.isnan(La):
        La = Lx * xa0 + Ly * xa1 + Lz * xa2
    Or = (1.0 / Ja - 1.0 / Jt) * La
    Ep = complex(math.cos(Op * h), math.sin(Op * h))
    Er = complex(math.cos(Or * h), math.sin(Or * h))
    for n in range(nm):
        for j in range(3):
            S[n, j] = 0.0
            E_end[n, j] = 0.0
    k = 0  # terms X[k] e^{Z[k] s} of the case-frame moment
    for p in range(P):
        for m1 in range(-1, 2):
            v0, v1, v2 = _proj(m1, l0, l1, l2, A[p, 0], A[p, 1], A[p, 2])
            # body frame: R0ᵀ v
            b0 = R[0, 0] * v0 + R[1, 0] * v1 + R[2, 0] * v2
            b1 = R[0, 1] * v0 + R[1, 1] * v1 + R[2, 1] * v2
            b2 = R[0, 2] * v0 + R[1, 2] * v1 + R[2, 2] * v2
            u0 = u1 = u2 = 0.0j
            for m2 in range(-1, 2):
                e0 = 1.0 if ax == 0 else 0.0
                e1 = 1.0 if ax == 1 else 0.0
                e2 = 1.0 if ax == 2 else 0.0
                c0, c1, c2 = _proj(m2, e0, e1, e2, b0, b1, b2)
                f = om[p] - m1 * Op - m2 * Or
                chi = -tail * 1j * f
                ef = EO[p] * _epow(Ep, -m1) * _epow(Er, -m2)  # e^{ifh}
                ff2 = f * f
                for n in range(nm):
                    # mode n's particular solution is Re(g b e^{ifs}), g = −if/(1/τ_n + if) (in real arithmetic)
                    ln = lam[n]
                    dn = 1.0 / (ln * ln + ff2)
                    g = complex(-ff2 * dn, -f * ln * dn)
                    chi += w[n] * g
                    S[n, 0] += g * c0
                    S[n, 1] += g * c1
                    S[n, 2] += g * c2
                    if end:  # (the modes' state at s = h: the step's end reads the last pass's)
                        ge = g * ef
                        E_end[n, 0] += ge * c0
                        E_end[n, 1] += ge * c1
                        E_end[n, 2] += ge * c2
                chi *= c_m
                u0 += chi * c0
                u1 += chi * c1
                u2 += chi * c2
            # back to the case frame, split over the precession's projectors
            U0 = R[0, 0] * u0 + R[0, 1] * u1 + R[0, 2] * u2
            U1 = R[1, 0] * u0 + R[1, 1] * u1 + R[1, 2] * u2
            U2 = R[2, 0] * u0 + R[2, 1] * u1 + R[2, 2] * u2
            for m3 in range(-1, 2):
                X[k, 0], X[k, 1], X[k, 2] = _proj(m3, l0, l1, l2, U0, U1, U2)
                Z[k] = 1j * (om[p] + (m3 - m1) * Op)
                EZ[k] = EO[p] * _epow(Ep, m3 - m1)
                k += 1
    # free decay of each mode's mismatch with its particular solution: D_n e^{−s/τ_n} (body, real), seen from the
    # case as Σ_{m2,m3} P_m3(l̂) R0 P_m2(e_a) D_n e^{(−1/τ_n + i(m3 Ω_p + m2 Ω_r))s}
    summed = nm >= MODE_SUM_MIN
    for n in range(nm):
        d0, d1, d2 = _mode_mismatch(y, S, n, c_m * w[n])
        dec = math.exp(-lam[n] * h)
        if summed:  # (D_n and e^{−h/τ_n} for _decay_sums: the rows past the forced terms')
            X[k + n, 0], X[k + n, 1], X[k + n, 2] = d0, d1, d2
            EZ[k + n] = dec
            continue
        for m2 in range(-1, 2):
            e0 = 1.0 if ax == 0 else 0.0
            e1 = 1.0 if ax == 1 else 0.0
            e2 = 1.0 if ax == 2 else 0.0
            c0, c1, c2 = _proj(m2, e0, e1, e2, d0 + 0j, d1 + 0j, d2 + 0j)
            U0 = R[0, 0] * c0 + R[0, 1] * c1 + R[0, 2] * c2
            U1 = R[1, 0] * c0 + R[1, 1] * c1 + R[1, 2] * c2
            U2 = R[2, 0] * c0 + R[2, 1] * c1 + R[2, 2] * c2
            for m3 in range(-1, 2):
                X[k, 0], X[k, 1], X[k, 2] = _proj(m3, l0, l1, l2, U0, U1, U2)
                Z[k] = -lam[n] + 1j * (m3 * Op + m2 * Or)
                EZ[k] = dec * _epow(Ep, m3) * _epow(Er, m2)
                k += 1
    # N = m_c × B_c with B_c = ½ Σ_q (a_q e^{iν_q s} + conj): ∫ and ∫(h − s) of each product, and with
    # K1[0] = ∫ N e^{−iΩ_p s} ds and K1[1] = ∫ (h − s) N e^{−iΩ_p s} ds (the torque seen from the precession). The
    # terms come in families of three, m3 = −1, 0, 1, whose exponents differ by iΩ_p; N e^{−iΩ_p s} shifts them by
    # one: a family's ∫ at the five shifts μ = −2 … 2 serve all its products (_family)
    for j in range(6):
        out[j] = 0.0
    for j in range(3):
        K1[0, j] = 0.0
        K1[1, j] = 0.0
    for f in range(k // 3):
        for q in range(P):
            for sg in range(2):
                _family(X, 3 * f, Z[3 * f + 1], EZ[3 * f + 1], A, q, sg, om[q], EO[q], Op, Ep, h, out, K1, end,
                        precess, k1_part)
    if summed:
        _decay_sums(X, EZ, k, nm, lam, R, ax, l0, l1, l2, A, om, EO, Op, Or, Ep, Er, h, out, K1, end, precess, k1_part)
    # attitude: q(h) = q(l̂, Ω_p h) ⊗ q0 ⊗ q(e_a, Ω_r h)
    cp, sp = math.cos(0.5 * Op * h), math.sin(0.5 * Op * h)
    cr, sr = math.cos(0.5 * Or * h), math.sin(0.5 * Or * h)
    q0, q1, q2, q3 = y[3], y[4], y[5], y[6]
    r0 = sr if ax == 0 else 0.0
    r1 = sr if ax == 1 else 0.0
    r2 = sr if ax == 2 else 0.0
    # t = q0 ⊗ (cr, r)
    t0 = q0 * cr - (q1 * r0 + q2 * r1 + q3 * r2)
    t1 = q0 * r0 + q1 * cr + (q2 * r2 - q3 * r1)
    t2 = q0 * r1 + q2 * cr + (q3 * r0 - q1 * r2)
    t3 = q0 * r2 + q3 * cr + (q1 * r1 - q2 * r0)
    p1, p2, p3 = sp * l0, sp * l1, sp * l2
    out[6] = cp * t0 - (p1 * t1 + p2 * t2 + p3 * t3)
    out[7] = cp * t1 + p1 * t0 + (p2 * t3 - p3 * t2)
    out[8] = cp * t2 + p2 * t0 + (p3 * t1 - p1 * t3)
    out[9] = cp * t3 + p3 * t0 + (p1 * t2 - p2 * t1)
    out[10], out[11], out[12] = l0, l1, l2
    out[13], out[14] = Op, Or
    # the mean over the step of L_b·e_a (what sets Ω_r): L_b0 + R0ᵀ ∫(h − s) Rot(l̂, −Ω_p s) N ds / h, along e_a
    g0, g1, g2 = _proj(0, l0, l1, l2, out[3] + 0j, out[4] + 0j, out[5] + 0j)
    if not precess:  # (only Ω_r = 0 · L̄_a reads it: L̄_a's part along l̂, its sign that of the whole)
        out[15] = y[0] * xa0 + y[1] * xa1 + y[2] * xa2 + (xa0 * g0.real + xa1 * g1.real + xa2 * g2.real) / h
        return
    if not k1_part & K1_MEAN:
        out[15] = math.nan  # (not made: no pass after reads it)
        return
    k0, k1, k2 = _proj(1, l0, l1, l2, K1[1, 0], K1[1, 1], K1[1, 2])
    out[15] = (y[0] * xa0 + y[1] * xa1 + y[2] * xa2
               + (xa0 * (g0.real + 2.0 * k0.real) + xa1 * (g1.real + 2.0 * k1.real)
                  + xa2 * (g2.real + 2.0 * k2.real)) / h)


@njit(cache=True)
def frozen_flow_step(y, s, h, Bre, Bim, om, Jt, Ja, ax, lam, w, c_m, tail, nm, A, X, Z, EZ, EO, S, E_end, out, R,
                     K1):
    """One frozen-flow step of length h (s) from phase time s (in place on y; see the module docstring)."""
    P = om.shape[0]
    for p in range(P):
        EO[p] = complex(math.cos(om[p] * h), math.sin(om[p] * h))
        e = cmath.exp(1j * om[p] * s)
        for j in range(3):
            A[p, j] = (Bre[p, j] - 1j * Bim[p, j]) * e
    q0, q1, q2, q3 = y[3], y[4], y[5], y[6]
    R[0, 0] = 1 - 2 * (q2 * q2 + q3 * q3)
    R[0, 1] = 2 * (q1 * q2 - q0 * q3)
    R[0, 2] = 2 * (q1 * q3 + q0 * q2)
    R[1, 0] = 2 * (q1 * q2 + q0 * q3)
    R[1, 1] = 1 - 2 * (q1 * q1 + q3 * q3)
    R[1, 2] = 2 * (q2 * q3 - q0 * q1)
    R[2, 0] = 2 * (q1 * q3 - q0 * q2)
    R[2, 1] = 2 * (q2 * q3 + q0 * q1)
    R[2, 2] = 1 - 2 * (q1 * q1 + q2 * q2)
    Lx, Ly, Lz = y[0], y[1], y[2]
    # (an isotropic body's first two passes need no K1: they serve only its Ω_r, which is zero)
    pre = Ja != Jt
    # (the predictor passes make K1[1] only, for out[15]; the last K1[0] only, for the step's end: the same bits)
    _flow_pass(Lx, Ly, Lz, math.nan, y, R, s, h, Bre, Bim, om, Jt, Ja, ax, lam, w, c_m, tail, nm, A, X, Z, EZ, EO, S,
               E_end, out, K1, pre, K1_MEAN)
    a0, a1, a2, la1 = out[3], out[4], out[5], out[15]
    _flow_pass(Lx + a0 / h, Ly + a1 / h, Lz + a2 / h, la1, y, R, s, h, Bre, Bim, om, Jt, Ja, ax, lam,
               w, c_m, tail, nm, A, X, Z, EZ, EO, S, E_end, out, K1, pre, K1_MEAN)
    # third pass at the mean of L right to O(h³): (I2_1 + 2 I2_2)/(3h) (the first pass, frozen at L0, misses
    # J_N N̄ h³/6 of ∫(h − s)N ds, the second, frozen at L0 + I2_1/h, has J_N N̄ h³/12 too much); the mean axial
    # moment alike. The flow's phases ∫Ω_p, ∫Ω_r then come from a mean right to third order: the spin and
    # precession phases err at O(h²) a run, not O(h) (docs/numerics.md)
    _flow_pass(Lx + (a0 + 2.0 * out[3]) / (3.0 * h), Ly + (a1 + 2.0 * out[4]) / (3.0 * h),
               Lz + (a2 + 2.0 * out[5]) / (3.0 * h), (la1 + 2.0 * out[15]) / 3.0, y, R, s, h, Bre, Bim, om, Jt, Ja,
               ax, lam, w, c_m, tail, nm, A, X, Z, EZ, EO, S, E_end, out, K1, True, K1_END)
    y[0] = Lx + out[0]
    y[1] = Ly + out[1]
    y[2] = Lz + out[2]
    # L in the body frame by variation of constants of L̇_b = −Ω_r e_a × L_b + N_b along the flow:
    # L_b(h) = Rot(e_a, −Ω_r h) (L_b0 + R0ᵀ ∫ Rot(l̂, −Ω_p s) N ds), Rot(l̂, −Ω_p s) = Σ_m P_m(l̂) e^{−imΩ_p s}
    l0, l1, l2, Or = out[10], out[11], out[12], out[14]
    g0, g1, g2 = _proj(0, l0, l1, l2, out[0] + 0j, out[1] + 0j, out[2] + 0j)
    k0, k1, k2 = _proj(1, l0, l1, l2, K1[0, 0], K1[0, 1], K1[0, 2])
    G0 = Lx + g0.real + 2.0 * k0.real
    G1 = Ly + g1.real + 2.0 * k1.real
    G2 = Lz + g2.real + 2.0 * k2.real
    u0 = R[0, 0] * G0 + R[1, 0] * G1 + R[2, 0] * G2
    u1 = R[0, 1] * G0 + R[1, 1] * G1 + R[2, 1] * G2
    u2 = R[0, 2] * G0 + R[1, 2] * G1 + R[2, 2] * G2
    # Rot(e_a, −Ω_r h) about the symmetry axis: (u_{a+1}, u_{a+2}) turned by −Ω_r h
    ca, sa = math.cos(Or * h), math.sin(-Or * h)
    if ax == 0:
        u1, u2 = ca * u1 - sa * u2, sa * u1 + ca * u2
    elif ax == 1:
        u2, u0 = ca * u2 - sa * u0, sa * u2 + ca * u0
    else:
        u0, u1 = ca * u0 - sa * u1, sa * u0 + ca * u1
    # the attitude: the flow's, turned by the least rotation that takes its R(h) L_b(h) onto L(h)
    f0, f1, f2, f3 = out[6], out[7], out[8], out[9]
    c0, c1, c2 = _rotl(f0, f1, f2, f3, u0, u1, u2)
    nc = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    nl = math.sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2])
    if nc > 0.0 and nl > 0.0:
        c0, c1, c2 = c0 / nc, c1 / nc, c2 / nc
        d0, d1, d2 = y[0] / nl, y[1] / nl, y[2] / nl
        r0 = 1.0 + c0 * d0 + c1 * d1 + c2 * d2
        r1, r2, r3 = c1 * d2 - c2 * d1, c2 * d0 - c0 * d2, c0 * d1 - c1 * d0
        nr = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
        r0, r1, r2, r3 = r0 / nr, r1 / nr, r2 / nr, r3 / nr
        f0, f1, f2, f3 = (r0 * f0 - r1 * f1 - r2 * f2 - r3 * f3, r0 * f1 + r1 * f0 + r2 * f3 - r3 * f2,
                          r0 * f2 - r1 * f3 + r2 * f0 + r3 * f1, r0 * f3 + r1 * f2 - r2 * f1 + r3 * f0)
    nq = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2 + f3 * f3)
    y[3], y[4], y[5], y[6] = f0 / nq, f1 / nq, f2 / nq, f3 / nq
    # modes: e_n(h) = e^{−h/τ_n}(e_n(0) − Re S_n) + Re E_end_n
    for n in range(nm):
        dec = math.exp(-lam[n] * h)
        i0 = 7 + 3 * n
        for j in range(3):
            y[i0 + j] = dec * (y[i0 + j] - S[n, j].real) + E_end[n, j].real


@njit(cache=True)
def _case_pass(Lx, Ly, Lz, y, h, om, J, lam, w, c_m, tail, nm, A, X, Z, EZ, EO, S, E_end, out):
    """One pass of the case-frame step of an isotropic rotor without attitude, L̄ = (Lx, Ly, Lz) (case,
    N·m·s), J (kg·m²): out[0:3] = ∫N ds, out[3:6] = ∫(h − s)N ds (N·m·s, N·m·s²), out[10:13] = l̂,
    out[13] = Ω_p = |L̄|/J (rad/s); S, E_end (nm, 3) receive each mode's particular solution at s = 0 and h
    (case frame, T, complex: take the real part).

    The body turns by Rot(l̂, Ω_p s); a case phasor's part P_m(l̂) a is seen from the body at
    f = ν − m Ω_p, so mode n answers it with g_n(f) = −i f/(1/τ_n + i f) and, turned back with the body,
    at the field's own frequency ν: the particular solution is Re Σ_m g_n(f_m) P_m(l̂) a e^{iνs} and the
    moment's forced part is one term per phasor, Re Σ_m χ(f_m) P_m(l̂) a e^{iνs}. The modes' mismatch with
    it, D_n (case), decays while it turns with the body: Σ_m P_m(l̂) D_n e^{(−1/τ_n + imΩ_p)s}."""
    P = om.shape[0]
    Ln = math.sqrt(Lx * Lx + Ly * Ly + Lz * Lz)
    if Ln > 0.0:
        l0, l1, l2 = Lx / Ln, Ly / Ln, Lz / Ln
    else:  # no rotation: any axis
        l0, l1, l2 = 0.0, 0.0, 1.0
    Op = Ln / J
    Ep = complex(math.cos(Op * h), math.sin(Op * h))
    for n in range(nm):
        for j in range(3):
            S[n, j] = 0.0
            E_end[n, j] = 0.0
    k = 0  # terms X[k] e^{Z[k] s} of the case-frame moment
    for p in range(P):
        X[k, 0] = X[k, 1] = X[k, 2] = 0.0
        for m1 in range(-1, 2):
            v0, v1, v2 = _proj(m1, l0, l1, l2, A[p, 0], A[p, 1], A[p, 2])
            f = om[p] - m1 * Op
            chi = -tail * 1j * f
            for n in range(nm):
                g = -1j * f / (lam[n] + 1j * f)
                chi += w[n] * g
                S[n, 0] += g * v0
                S[n, 1] += g * v1
                S[n, 2] += g * v2
                ge = g * EO[p]
                E_end[n, 0] += ge * v0
                E_end[n, 1] += ge * v1
                E_end[n, 2] += ge * v2
            chi *= c_m
            X[k, 0] += chi * v0
            X[k, 1] += chi * v1
            X[k, 2] += chi * v2
        Z[k] = 1j * om[p]
        EZ[k] = EO[p]
        k += 1
    for n in range(nm):
        d0, d1, d2 = _mode_mismatch(y, S, n, c_m * w[n])
        dec = math.exp(-lam[n] * h)
        for m3 in range(-1, 2):
            X[k, 0], X[k, 1], X[k, 2] = _proj(m3, l0, l1, l2, d0 + 0j, d1 + 0j, d2 + 0j)
            Z[k] = -lam[n] + 1j * m3 * Op
            EZ[k] = dec * _epow(Ep, m3)
            k += 1
    # N = m × B, B = ½ Σ_q (a_q e^{iν_q s} + conj): ∫ and ∫(h − s) of each product
    for j in range(6):
        out[j] = 0.0
    for j in range(k):
        x0, x1, x2 = X[j, 0], X[j, 1], X[j, 2]
        for q in range(P):
            for sg in range(2):
                a0, a1, a2, zq, ezq = _field_half(A, q, sg, Z[j], EZ[j], om[q], EO[q])
                n0, n1, n2 = _torque_term(x0, x1, x2, a0, a1, a2, zq, ezq, h, out)
    out[10], out[11], out[12] = l0, l1, l2
    out[13] = Op


@njit(cache=True)
def frozen_flow_step_case(y, s, h, Bre, Bim, om, J, lam, w, c_m, tail, nm, A, X, Z, EZ, EO, S, E_end, out):
    """One frozen-flow step of length h (s) from phase time s for an isotropic rotor without attitude (in
    place on y: L and the case-frame modes; y[3:7] untouched; see :func:`_case_pass`). Three passes as
    :func:`frozen_flow_step`; the modes end at e_n(h) = e^{−h/τ_n} Rot(l̂, Ω_p h)(e_n(0) − Re S_n) + Re E_end_n."""
    P = om.shape[0]
    for p in range(P):
        EO[p] = complex(math.cos(om[p] * h), math.sin(om[p] * h))
        e = cmath.exp(1j * om[p] * s)
        for j in range(3):
            A[p, j] = (Bre[p, j] - 1j * Bim[p, j]) * e
    Lx, Ly, Lz = y[0], y[1], y[2]
    _case_pass(Lx, Ly, Lz, y, h, om, J, lam, w, c_m, tail, nm, A, X, Z, EZ, EO, S, E_end, out)
    a0, a1, a2 = out[3], out[4], out[5]
    _case_pass(Lx + a0 / h, Ly + a1 / h, Lz + a2 / h, y, h, om, J, lam, w, c_m, tail, nm, A, X, Z, EZ,
               EO, S, E_end, out)
    # the third pass at the mean of L right to O(h³), as frozen_flow_step's
    _case_pass(Lx + (a0 + 2.0 * out[3]) / (3.0 * h), Ly + (a1 + 2.0 * out[4]) / (3.0 * h),
               Lz + (a2 + 2.0 * out[5]) / (3.0 * h), y, h, om, J, lam, w, c_m, tail, nm, A, X, Z, EZ, EO, S, E_end,
               out)
    y[0] = Lx + out[0]
    y[1] = Ly + out[1]
    y[2] = Lz + out[2]
    l0, l1, l2 = out[10], out[11], out[12]
    c, sn = math.cos(out[13] * h), math.sin(out[13] * h)
    for n in range(nm):
        dec = math.exp(-lam[n] * h)
        i0 = 7 + 3 * n
        e0, e1, e2 = _mode_mismatch(y, S, n, 1.0)
        d = (l0 * e0 + l1 * e1 + l2 * e2) * (1.0 - c)  # Rodrigues: Rot(l̂, φ) e
        y[i0] = dec * (e0 * c + (l1 * e2 - l2 * e1) * sn + l0 * d) + E_end[n, 0].real
        y[i0 + 1] = dec * (e1 * c + (l2 * e0 - l0 * e2) * sn + l1 * d) + E_end[n, 1].real
        y[i0 + 2] = dec * (e2 * c + (l0 * e1 - l1 * e0) * sn + l2 * d) + E_end[n, 2].real


def steady_modes(y, Bre, Bim, om, Jt, Ja, ax, lam, w, c_m, tail) -> np.ndarray:
    """(N, 3) eddy-mode states (body frame, T) in their steady response to the field (phasors referred to
    s = 0) along the free motion of the state ``y``: the particular solution of a frozen-flow pass, with
    no switch-on transient. ``lam`` (N,) = 1/τ_n."""
    nm, P = lam.shape[0], om.shape[0]
    h = 1e-3  # any step: the particular solution at s = 0 does not depend on it
    R = quat_to_matrix(y[3:7])
    S = np.zeros((nm, 3), np.complex128)
    k = 9 * (P + nm)
    _flow_pass(y[0], y[1], y[2], math.nan, y, R, 0.0, h, Bre, Bim, om, Jt, Ja, ax, lam, w, c_m, tail, nm,
               (Bre - 1j * Bim).astype(np.complex128), np.empty((k, 3), np.complex128), np.empty(k, np.complex128),
               np.empty(k, np.complex128), np.exp(1j * om * h).astype(np.complex128), S,
               np.empty((nm, 3), np.complex128), np.empty(16), np.empty((2, 3), np.complex128))
    return S.real


@njit(cache=True, nogil=True)
def integrate_frozen(y, t0, t_seg, t_stops, record, h_max, Bre, Bim, om, Jinv, Jt, Ja, ax, c_m, w, tail, lam_modes,
                     out_y, out_N, k_out, case=None, pos=None, max_steps=0):
    """Integrate y from t0 through each time in ``t_stops`` with frozen-flow steps no longer than ``h_max``
    (equal steps between stops), recording like :func:`gyro_sim.kernels.integrate`. ``lam_modes`` (N,)
    = 1/τ_n; ``case``: isotropic rotor without attitude, modes in the case frame
    (:func:`frozen_flow_step_case`, J = Jt). ``pos``, ``max_steps``: a bounded call, as
    :func:`gyro_sim.kernels.integrate`'s (a step's numbers depend on y, the span's start, its index and h only).
    Returns (k_out, steps)."""
    P = om.shape[0]
    nm = lam_modes.shape[0]
    A = np.empty((P, 3), np.complex128)
    X = np.empty((9 * (P + nm), 3), np.complex128)
    Z = np.empty(9 * (P + nm), np.complex128)
    EZ = np.empty(9 * (P + nm), np.complex128)
    EO = np.empty(P, np.complex128)
    S = np.empty((max(nm, 1), 3), np.complex128)
    E_end = np.empty((max(nm, 1), 3), np.complex128)
    out = np.empty(16)
    K1 = np.empty((2, 3), np.complex128)
    R = np.empty((3, 3))
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
                if case is not None:
                    frozen_flow_step_case(y, (t - t_seg) + j * h, h, Bre, Bim, om, Jt, lam_modes, w, c_m, tail, nm,
                                          A, X, Z, EZ, EO, S, E_end, out)
                else:
                    frozen_flow_step(y, (t - t_seg) + j * h, h, Bre, Bim, om, Jt, Ja, ax, lam_modes, w, c_m, tail,
                                     nm, A, X, Z, EZ, EO, S, E_end, out, R, K1)
            steps += j1 - j0
            if j1 < k:
                _pause(pos, i, j1, t)
                return k_out, steps
            j0 = 0
            t = t_stops[i]
        if record[i]:
            record_sample(t - t_seg, y, Bre, Bim, om, Jinv, c_m, w, tail, nm, None, cs, sn, F, work, out_y, out_N,
                          k_out, case)
            k_out += 1
    _pause(pos, t_stops.shape[0], 0, t)
    return k_out, steps
