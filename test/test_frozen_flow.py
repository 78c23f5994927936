"""The frozen-flow step (gyro_sim/compiled/frozen_flow.py) against the 8th-order Lawson stepper resolving every turn.

Each test reports the difference it measured against a stated tolerance. References: lawson8 at many steps
per turn (its own error on these horizons is below 1e-10, docs/numerics.md).
"""

import numpy as np
import pytest

from gyro_sim.physics.frames import euler_angles, quat_to_matrix
from gyro_sim.scenes.scene import SceneError, load_scene, scene_from_dict
from gyro_sim.engine.simulate import Simulator, run

SHELL = {"kind": "thin_shell", "outer_radius": 0.025, "thickness": 0.001, "conductivity": 2.5e7}


def report(name, err, tol):
    print(f"\n{name}: measured {err:.3e}, tolerance {tol:.1e}")
    assert err <= tol, f"{name}: {err:.3e} > {tol:.1e}"


def final_error(a: Simulator, b: Simulator) -> tuple[float, float]:
    """(|ΔL|/|L|, min |Δq| over the sign of q) of two simulators' states."""
    eL = float(np.linalg.norm(a.y[0:3] - b.y[0:3]) / np.linalg.norm(b.y[0:3]))
    eq = float(min(np.linalg.norm(a.y[3:7] - b.y[3:7]), np.linalg.norm(a.y[3:7] + b.y[3:7])))
    return eL, eq


def advanced(name: str, T: float, integrator: dict, **ov) -> Simulator:
    sim = Simulator(load_scene(name, overrides={"controller": None, "duration": T, "integrator": integrator, **ov}))
    sim.advance(T)
    return sim


def test_default_scene_two_seconds_and_the_third_pass():
    """Default scene, 2 s from rest (1000 field turns): rate_change 1e-4 (356 steps, 5.6 ms each, 2.8 field turns)
    against lawson8 at 96 steps per turn. The two-pass step of before erred by 2.5e-7 in the attitude (its spin
    phase, second order: 16x more for a 4x longer step); the third pass at the mean of L right to O(h³) takes that
    term out (3.0e-8 measured), and what is left falls about as the step (3.6x for 4x): the error control estimates
    frozen-flow stretches at order 1 (step_control.ORDER)."""
    ref = advanced("spinup_thin_shell", 2.0, {"method": "lawson8", "steps_per_turn": 96})
    sims = {eps: advanced("spinup_thin_shell", 2.0, {"method": "frozen_flow", "rate_change": eps})
            for eps in (4e-4, 1e-4)}
    assert sims[1e-4].steps < 400
    eL, eq = final_error(sims[1e-4], ref)
    report("frozen_flow (rate_change 1e-4), default scene 2 s, L", eL, 1e-9)
    report("frozen_flow (rate_change 1e-4), default scene 2 s, attitude q", eq, 1e-7)
    ratio = final_error(sims[4e-4], ref)[1] / eq
    print(f"  attitude error ratio for a 4x longer step: {ratio:.1f} (first order: 4)")
    assert 2.0 < ratio < 32.0


def test_solid_sphere_ten_modes():
    """Solid sphere with 10 modes and the static tail (ν τ_1 = 1.25), 2 s: every mode solved in closed form."""
    # (modes: 10 given: the scene now chooses its modes for its accuracy, gyro_sim/scenes/accuracy.py)
    ref = advanced("spinup_solid_sphere", 2.0, {"method": "lawson8", "steps_per_turn": 384}, modes=10)
    ff = advanced("spinup_solid_sphere", 2.0, {"method": "frozen_flow", "rate_change": 1e-4}, modes=10)
    eL, eq = final_error(ff, ref)
    print(f"  {ff.steps} frozen-flow steps")
    report("frozen_flow, solid sphere 2 s, L", eL, 1e-8)
    report("frozen_flow, solid sphere 2 s, attitude q", eq, 1e-6)


@pytest.mark.parametrize("J3", [8e-6, 4e-6])
def test_nutation_angle_drift_of_an_axisymmetric_rotor(J3):
    """A spinning oblate (J3/J1 = 1.43) or prolate (0.72) rotor at θ = 0.3 in the default field: the eddy torque
    moves θ (the part of the torque that turns with the body axis). A frozen motion alone keeps θ; the step
    gets it from L_b by variation of constants. Over 1 s the change of θ agrees with lawson8 (24 steps per turn)."""
    ov = {"rotor": {"inertia": [5.592e-6, 5.592e-6, J3], "conductor": SHELL},
          "initial": {"spin": 1000.0, "L_direction": [0, 0, 1], "theta": 0.3}}
    ref = advanced("spinup_thin_shell", 1.0, {"method": "lawson8", "steps_per_turn": 24}, **ov)
    ff = advanced("spinup_thin_shell", 1.0, {"method": "frozen_flow"}, **ov)
    th0 = 0.3
    d_ref = euler_angles(quat_to_matrix(ref.y[3:7]), ref.y[0:3])[1] - th0
    d_ff = euler_angles(quat_to_matrix(ff.y[3:7]), ff.y[0:3])[1] - th0
    print(f"  Δθ over 1 s: lawson8 {d_ref:.4e}, frozen_flow {d_ff:.4e} rad ({ff.steps} steps)")
    assert abs(d_ref) > 1e-5  # the effect is there to be missed
    report(f"frozen_flow Δθ relative to lawson8 (J3 = {J3:g})", abs(d_ff - d_ref) / abs(d_ref), 1e-3)
    eL, eq = final_error(ff, ref)
    report(f"frozen_flow attitude after 1 s (J3 = {J3:g})", eq, 1e-5)


def test_shipped_scene_with_controller_and_outputs():
    """The default scene as shipped (spin-up law every 20 ms, 50 Hz output) through 10 s: auto takes frozen_flow,
    and every output sample (spin, θ, torque) agrees with a lawson8 run within the two runs' estimated errors of L
    (since lawson8 may coarsen to 8 steps a turn, ErrorControl.coarsest, its own spin error is 4.0e-8 against lawson8
    at 48 a turn, estimated 1.1e-7; frozen_flow's 8.9e-10, estimated 4.5e-9)."""
    sc = load_scene("spinup_thin_shell", overrides={"duration": 10.0})
    assert Simulator(sc)._method() == "frozen_flow"
    ff = run(sc)
    l8 = run(load_scene("spinup_thin_shell", overrides={"duration": 10.0, "integrator": {"method": "lawson8"}}))
    assert ff.t.shape == l8.t.shape and np.array_equal(ff.t, l8.t)
    spin = float(np.max(np.abs(ff.spin_rate - l8.spin_rate)) / np.max(np.abs(l8.spin_rate)))
    theta = float(np.max(np.abs(ff.theta - l8.theta)))
    torque = float(np.max(np.linalg.norm(ff.torque - l8.torque, axis=1)) / np.max(np.linalg.norm(l8.torque, axis=1)))
    print(f"  steps: frozen_flow {ff.steps}, lawson8 {l8.steps}")
    est = ff.error_estimate.L + l8.error_estimate.L
    assert est <= 2 * ff.scene.accuracy.rtol  # (each run within its tolerance by its own estimate)
    report("spin rate over 10 s (relative; bound: the two runs' estimates of L)", spin, est)
    # (both hold the axis' cone, θ with it, to the scene's 1e-6 rad; measured 2.6e-8 with 581 frozen-flow steps)
    report("θ over 10 s (rad)", theta, 1e-7)
    report("torque samples (relative to the largest)", torque, 1e-4)


def test_frozen_flow_is_refused_where_it_does_not_apply():
    """A triaxial rotor or an effect: one message naming the field and what is allowed."""
    base = {"rotor": {"inertia": [1e-5, 1.1e-5, 1.2e-5], "conductor": SHELL}, "duration": 1.0,
            "integrator": {"method": "frozen_flow"}}
    with pytest.raises(SceneError, match=r"integrator.method = 'frozen_flow' needs an axisymmetric rotor"):
        scene_from_dict(base)
    eff = {**base, "rotor": {"inertia": [1e-5, 1e-5, 1.2e-5], "conductor": SHELL},
           "effects": {"gas_drag": {"transverse": [1e-9], "axial": [1e-9]}}}
    with pytest.raises(SceneError, match=r"effects \['gas_drag'\] are on"):
        scene_from_dict(eff)
    with pytest.raises(SceneError, match="rate_change"):
        scene_from_dict({**base, "rotor": eff["rotor"], "integrator": {"method": "frozen_flow", "rate_change": 0.5}})


def test_step_follows_the_torque_of_a_spin_up():
    """A 300 s spin-up (the default scene, L only, output 0.1 Hz so samples do not bound the step; spin-up time
    constant ~70 s): the frozen-flow step follows the mean torque at the slip now (frozen_flow.torque_scale, re-planned
    at the error control's checks), so the run takes fewer steps than the start's step would give over the whole run
    (before: the step of t = 0 throughout), and its L still holds rtol 1e-6 against a run with 20x smaller
    rate_change (400x less error), and the estimate covers the error measured."""
    ov = {"controller": None, "duration": 300.0, "accuracy": {"attitude": None}, "output": {"rate": 0.1}}
    sc = load_scene("spinup_thin_shell", overrides=ov)
    r = run(sc)
    h0 = Simulator(sc)._frozen_flow_step()
    ref = run(load_scene("spinup_thin_shell", overrides={**ov, "integrator": {"method": "frozen_flow",
                                                                                "rate_change": r_change(sc) / 20}}))
    steps_fixed = 300.0 / h0
    print(f"\nsteps {r.steps} against {steps_fixed:.0f} at the first step throughout")
    assert r.steps < steps_fixed / 2
    err = float(np.max(np.linalg.norm(r.L - ref.L, axis=1)) / np.max(np.linalg.norm(ref.L, axis=1)))
    report("L against the reference (relative)", err, 1e-6)
    print(f"estimate {r.error_estimate.L:.2e}")
    assert r.error_estimate.L >= 0.5 * err


def r_change(scene) -> float:
    """The rate_change the run of ``scene`` plans for its accuracy."""
    return Simulator(scene).step_plan.rate_change


def _torque_scale_numpy(Bre, Bim, om, L, Jt, Ja, e_a, c_m, w, tau, tail):
    """The frozen-flow step's torque scale as NumPy states it (the formula of frozen_flow.torque_scale's
    docstring, term by term): the oracle of the compiled one."""
    Lm = float(np.linalg.norm(L))
    n = np.asarray(L, float) / Lm
    om_p = Lm / Jt
    om_r = (1.0 / Ja - 1.0 / Jt) * float(np.dot(L, e_a)) if e_a is not None else 0.0
    a = np.asarray(Bre, float) - 1j * np.asarray(Bim, float)
    along = (a @ n)[:, None] * n
    perp = a - along
    cross = np.cross(n, perp)
    amp = {0: np.linalg.norm(along, axis=1), 1: np.linalg.norm(0.5 * (perp - 1j * cross), axis=1),
           -1: np.linalg.norm(0.5 * (perp + 1j * cross), axis=1)}
    w, tau = np.abs(np.asarray(w, float)), np.asarray(tau, float)

    def g(f):
        f = np.abs(f)[:, None]
        return np.sum(w * f * tau / (1.0 + (f * tau) ** 2), axis=1) + tail * f[:, 0]

    N = sum(float(np.sum(amp[m] * np.max([g(om - m * om_p - m2 * om_r) for m2 in (-1, 0, 1)], axis=0)))
            for m in (-1, 0, 1))
    return c_m * float(np.sum(np.linalg.norm(a, axis=1))) * N


def test_the_compiled_torque_scale_is_the_formula():
    """frozen_flow.torque_scale (compiled: it is asked at every command segment and check) against the formula in
    NumPy: 300 random fields, rates, moments and mode sets, with and without the symmetry axis' term."""
    from gyro_sim.compiled.frozen_flow import torque_scale

    rng = np.random.default_rng(1)
    worst = 0.0
    for i in range(300):
        k, n = int(rng.integers(1, 5)), int(rng.integers(1, 20))
        args = (rng.normal(size=(k, 3)), rng.normal(size=(k, 3)), rng.normal(size=k) * 1000, rng.normal(size=3),
                1.0 + rng.random(), 1.0 + rng.random(), rng.normal(size=3) if i % 2 else None, rng.random(),
                rng.normal(size=n), rng.random(n) * 1e-3, rng.random() * 1e-3)
        a, b = _torque_scale_numpy(*args), torque_scale(*args)
        worst = max(worst, abs(a - b) / abs(a))
    report("compiled torque scale against the formula (relative)", worst, 1e-13)


def test_auto_counts_the_field_phasors_in_the_frozen_flow_cost():
    """A frozen-flow step's terms are products of each field phasor with the moment's 9 (phasors + modes) terms, so
    it costs more the more stators are on (measured on a thin shell: 3.6x, 8.5x, 15x a lawson8 step with 1, 2, 3
    phasors); ``auto`` weighs FROZEN_FLOW_COST (1 + modes) lawson8 steps a phasor (model.frozen_flow_cost). The
    ψ-switching scenes' three stators on: lawson8 (before: frozen_flow, its step 4.3x lawson8's at 15x the cost, and
    the run 8x the old defaults' CPU); z3 alone, or with z1: frozen_flow; the old defaults' runs keep their rule."""
    from gyro_sim.engine.model import FROZEN_FLOW_COST, frozen_flow_cost
    from gyro_sim.scenes.tolerance import legacy

    on = {"controller": None, "stators.0.current": 0.316, "stators.1.current": 0.316, "stators.2.current": 0.5,
          "stators.0.rate": 3000.0, "stators.1.rate": 5000.0}

    def method(**ov):
        return Simulator(load_scene("nutation_oblate", overrides={**on, **ov}))._method()

    assert frozen_flow_cost(1) == FROZEN_FLOW_COST * 2 and frozen_flow_cost(1, 3) == 3 * frozen_flow_cost(1)
    assert method() == "lawson8"
    assert method(**{"stators.1.current": 0.0}) == "frozen_flow"
    assert method(**{"stators.0.current": 0.0, "stators.1.current": 0.0}) == "frozen_flow"
    with legacy():
        assert method() == "lawson8"


def _step_cases(seed: int, bodies):
    """Random frozen-flow steps: for each (J_t, J_a) of ``bodies`` and (phasors P, modes nm) of (1, 1), (2, 3),
    the step's inputs (a dict); the symmetry axis is z."""
    rng = np.random.default_rng(seed)
    for Jt, Ja in bodies:
        for P, nm in ((1, 1), (2, 3)):
            q = rng.normal(size=4)
            yield dict(Bre=rng.normal(size=(P, 3)) * 5e-3, Bim=rng.normal(size=(P, 3)) * 5e-3,
                       om=np.array([0.0, 300.0][:P]), lam=1.0 / (2.6e-4 * (1 + np.arange(nm))), w=rng.normal(size=nm),
                       c_m=0.3, tail=1e-5, h=3e-3, s=0.25, Jt=Jt, Ja=Ja, P=P, nm=nm,
                       y0=np.concatenate([rng.normal(size=3) * 1e-3 * Jt / 5.592e-6, q / np.linalg.norm(q),
                                          rng.normal(size=3 * nm) * 1e-3]))


def _work(P: int, nm: int) -> tuple:
    """The frozen-flow step's work arrays (A, X, Z, EZ, EO, S, E_end, out, R, K1)."""
    k = 9 * (P + nm)
    return (np.empty((P, 3), np.complex128), np.empty((k, 3), np.complex128), np.empty(k, np.complex128),
            np.empty(k, np.complex128), np.empty(P, np.complex128), np.empty((nm, 3), np.complex128),
            np.empty((nm, 3), np.complex128), np.empty(16), np.empty((3, 3)), np.empty((2, 3), np.complex128))


def _step_and_full_passes(c: dict) -> tuple:
    """Case ``c`` (:func:`_step_cases`) through the frozen-flow step, and through the three passes in full
    (precession integrals and both rows of K1 in each, as the step made them before issue 28), from the step's own
    phasors A, e^{iνh} EO and R0 (the kernel's bits). Returns (y after the step, its out and K1; the full passes' out,
    K1, S and E_end)."""
    import math

    from gyro_sim.compiled import frozen_flow as ff

    y0, h, P, nm = c["y0"], c["h"], c["P"], c["nm"]
    consts = (c["Bre"], c["Bim"], c["om"], c["Jt"], c["Ja"], 2, c["lam"], c["w"], c["c_m"], c["tail"], nm)
    y = y0.copy()
    A, X, Z, EZ, EO, S, E_end, out, R, K1 = _work(P, nm)
    ff.frozen_flow_step(y, c["s"], h, *consts, A, X, Z, EZ, EO, S, E_end, out, R, K1)
    new_out, new_K1 = out.copy(), K1.copy()
    _, X, Z, EZ, _, S, E_end, out, _, K1 = _work(P, nm)
    args = (y0, R, c["s"], h, *consts, A, X, Z, EZ, EO, S, E_end, out, K1, True, ff.K1_BOTH)
    L0 = y0[0:3]
    ff._flow_pass(*L0, math.nan, *args)
    a, la1 = out[3:6].copy(), out[15]
    ff._flow_pass(*(L0 + a / h), la1, *args)
    ff._flow_pass(*(L0 + (a + 2.0 * out[3:6]) / (3.0 * h)), (la1 + 2.0 * out[15]) / 3.0, *args)
    return y, new_out, new_K1, out, K1, S, E_end


def test_an_isotropic_body_skips_the_precession_integrals_of_its_first_passes_with_the_same_bits():
    """Issue 28 (constant_field 10 µs a step): an isotropic body's Ω_r is zero whatever its mean axial moment, so the
    first two passes of its frozen-flow step need not integrate the torque seen from the precession (K1): two thirds
    of their ∫ terms (measured 7.5 → 5.4 µs a step). The step must keep every bit of the three full passes."""
    for c in _step_cases(28, ((5.592e-6, 5.592e-6), (1.0, 1.0))):
        y, _, _, out, _, S, E_end = _step_and_full_passes(c)
        y0, nm = c["y0"], c["nm"]
        assert np.array_equal(y[0:3], y0[0:3] + out[0:3])
        # (the modes' end state from the same particular solutions; NumPy's arithmetic here, not the kernel's)
        dec = np.exp(-c["lam"] * c["h"])
        modes = dec[:, None] * (y0[7:].reshape(nm, 3) - S.real) + E_end.real
        assert np.allclose(y[7:], modes.ravel(), rtol=1e-13, atol=0)


def test_each_pass_makes_only_the_precession_integrals_it_reads_with_the_same_bits():
    """Each pass of an axisymmetric body's frozen-flow step used to make both rows of K1 (the torque seen from the
    precession), though the two predictor passes read only K1[1] (through the mean axial moment out[15]) and the last
    only K1[0] (the step's end); and ∫N ds and the modes' end state, which the step reads of the last pass only: a
    third of each pass's work on the torque terms (the default scene's step 8.7 µs before). The passes must keep every
    bit the step reads: L, the end's inputs out[0:15] and K1[0]."""
    import math

    for c in _step_cases(29, ((5.592e-6, 8.4e-6), (1.0, 0.7))):
        y, new_out, new_K1, out, K1, _, _ = _step_and_full_passes(c)
        assert np.array_equal(y[0:3], c["y0"][0:3] + out[0:3])
        assert np.array_equal(new_out[0:15], out[0:15]) and np.array_equal(new_K1[0], K1[0])
        assert math.isnan(new_out[15]) and not np.any(new_K1[1])  # (not made: nothing reads them)


def _rot(n, phi):
    """Rot(n, φ) (Rodrigues), n a unit 3-vector."""
    K = np.array([[0.0, -n[2], n[1]], [n[2], 0.0, -n[0]], [-n[1], n[0], 0.0]])
    return np.eye(3) + np.sin(phi) * K + (1.0 - np.cos(phi)) * (K @ K)


def _pass_by_quadrature(c: dict, Lbar: np.ndarray) -> tuple:
    """One pass's integrals along the frozen flow by ODE quadrature, independent of the kernel's closed forms: the
    body turns as R(s) = Rot(l̂, Ω_p s) R0 Rot(e_a, Ω_r s) (L̄ = ``Lbar``, e_a = z), each eddy mode follows
    ė_n = −e_n/τ_n − dB_b/dt (body) from y0, m_b = c_m(Σ w_n e_n − T_tail dB_b/dt), N = (R m_b) × B (case). Returns
    (∫N ds, ∫(h − s)N ds, ∫N e^{−iΩ_p s} ds, ∫(h − s)N e^{−iΩ_p s} ds)."""
    from scipy.integrate import solve_ivp

    y0, h, nm = c["y0"], c["h"], c["nm"]
    a = (c["Bre"] - 1j * c["Bim"]) * np.exp(1j * c["om"] * c["s"])[:, None]  # case phasors at the step's start
    om, lam, w = c["om"], c["lam"], c["w"]
    R0 = quat_to_matrix(y0[3:7])
    e_a = np.array([0.0, 0.0, 1.0])
    Ln = np.linalg.norm(Lbar)
    l_hat = Lbar / Ln
    Op, Or = Ln / c["Jt"], (1.0 / c["Ja"] - 1.0 / c["Jt"]) * float(Lbar @ R0 @ e_a)

    def fields(s):
        R = _rot(l_hat, Op * s) @ R0 @ _rot(e_a, Or * s)
        Bc = np.real(np.sum(a * np.exp(1j * om * s)[:, None], axis=0))
        dBc = np.real(np.sum(1j * om[:, None] * a * np.exp(1j * om * s)[:, None], axis=0))
        w_b = R.T @ (Op * l_hat) + Or * e_a  # the body's angular velocity, body frame
        dBb = -np.cross(w_b, R.T @ Bc) + R.T @ dBc
        return R, Bc, dBb

    def rhs(s, u):
        e = u[: 3 * nm].reshape(nm, 3)
        R, Bc, dBb = fields(s)
        m_b = c["c_m"] * (w @ e - c["tail"] * dBb)
        N = np.cross(R @ m_b, Bc)
        rot = np.exp(-1j * Op * s)
        i = 3 * nm
        du = np.empty_like(u)
        du[:i] = (-lam[:, None] * e - dBb).ravel()
        du[i:i + 3] = N  # ∫N
        du[i + 3:i + 6] = u[i:i + 3]  # ∫∫N = ∫(h − s)N at s = h
        du[i + 6:i + 9], du[i + 9:i + 12] = (N * rot).real, (N * rot).imag
        du[i + 12:i + 15], du[i + 15:i + 18] = u[i + 6:i + 9], u[i + 9:i + 12]
        return du

    u0 = np.concatenate([y0[7:7 + 3 * nm], np.zeros(18)])
    u = solve_ivp(rhs, (0.0, h), u0, method="DOP853", rtol=1e-13, atol=1e-30).y[:, -1]
    i = 3 * nm
    return u[i:i + 3], u[i + 3:i + 6], u[i + 6:i + 9] + 1j * u[i + 9:i + 12], u[i + 12:i + 15] + 1j * u[i + 15:i + 18]


@pytest.mark.parametrize("nm", [2, 6])
def test_a_pass_is_the_quadrature_of_the_torque_along_the_frozen_flow(nm):
    """Issue 28 (the solid sphere's 49 modes: 152 µs a step): a pass's torque integrals are now made from families of
    three terms sharing five ∫, and from MODE_SUM_MIN (4) modes on from the modes' decay terms summed over the modes
    first (68 µs). Each of out[0:3] = ∫N, out[3:6] = ∫(h − s)N, K1[0] and K1[1] (the torque seen from the precession)
    must be the quadrature of the torque along the frozen flow, for fast and slow modes (h/τ_n above and below the
    1e-2 where the closed forms switch), one and two field phasors."""
    import math

    from gyro_sim.compiled import frozen_flow as ff

    rng = np.random.default_rng(nm)
    worst = 0.0
    for P in (1, 2):
        for tau1 in (3e-3, 5.0):  # (h/τ_1 = 1 and 6e-4)
            q = rng.normal(size=4)
            c = dict(Bre=rng.normal(size=(P, 3)) * 5e-3, Bim=rng.normal(size=(P, 3)) * 5e-3,
                     om=np.array([628.0, -300.0][:P]), lam=(1.0 + np.arange(nm)) ** 2 / tau1, w=rng.normal(size=nm),
                     c_m=0.3, tail=1e-5, h=3e-3, s=0.25, Jt=5.592e-6, Ja=8.4e-6, P=P, nm=nm,
                     y0=np.concatenate([rng.normal(size=3) * 1e-3, q / np.linalg.norm(q),
                                        rng.normal(size=3 * nm) * 1e-3]))
            A, X, Z, EZ, EO, S, E_end, out, R, K1 = _work(P, nm)
            A[:] = (c["Bre"] - 1j * c["Bim"]) * np.exp(1j * c["om"] * c["s"])[:, None]
            EO[:] = np.exp(1j * c["om"] * c["h"])
            R[:] = quat_to_matrix(c["y0"][3:7])
            Lbar = c["y0"][0:3] + rng.normal(size=3) * 1e-4
            ff._flow_pass(*Lbar, math.nan, c["y0"], R, c["s"], c["h"], c["Bre"], c["Bim"], c["om"], c["Jt"], c["Ja"],
                          2, c["lam"], c["w"], c["c_m"], c["tail"], nm, A, X, Z, EZ, EO, S, E_end, out, K1, True,
                          ff.K1_BOTH)
            for got, want in zip((out[0:3], out[3:6], K1[0], K1[1]), _pass_by_quadrature(c, Lbar), strict=True):
                worst = max(worst, float(np.linalg.norm(got - want) / np.linalg.norm(want)))
    report(f"a pass's integrals against quadrature along the flow, {nm} modes (relative)", worst, 1e-9)
