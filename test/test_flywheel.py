"""Reorientation of a body by an internal flywheel ([S] Smolnikov; physics.md §4, §6 item 8; docs/flywheel.md).

Forward: in the full model (gyro_sim.run, no fields, triaxial J, wheel axis off the principal axes) the
body turns about the fixed companion axis J⁻¹a/|J⁻¹a| by −λ∫Ω_f dt, |Ω_b|/|Ω_f| = λ = J_f|J⁻¹a|.
Inverse: plan_reorientation (axis, turn, profile) reaches random targets (one near π, one at π) in the
full model; [S]'s closed forms (21), (22), (18), (12), (24), (25) agree with it; (23) as printed does
not (finding). The CLI subcommand and the scene config/flywheel_reorientation.yaml. Every test prints
what it measured.
"""
import math
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

import gyro_sim
from gyro_sim.apps import cli
from gyro_sim.physics import flywheel as fw
from gyro_sim.physics.frames import euler_angles, quat_to_matrix

J = [4.0e-6, 5.5e-6, 7.0e-6]  # kg·m², triaxial
JF = 2.0e-7  # kg·m²
A_OFF = [1.0, 2.0, -1.5]  # a wheel axis along no principal axis (normalised below)
CONFIG = Path(__file__).resolve().parents[1] / "config" / "flywheel_reorientation.yaml"


def report(name, err, tol):
    print(f"\n{name}: measured {err:.3e}, tolerance {tol:.1e}")
    assert err <= tol, f"{name}: {err:.3e} > {tol:.1e}"


def scene(axis, time, speed, duration, rate=200.0, q0=(1.0, 0.0, 0.0, 0.0), kinetic_moment=0.0, L_direction=(0, 0, 1)):
    psi, theta, phi = fw.euler_zxz(q0)
    return gyro_sim.scene_from_dict({
        "name": "flywheel_test", "rotor": {"inertia": J}, "torque_model": "none",
        "initial": {"kinetic_moment": kinetic_moment, "L_direction": list(L_direction), "psi": psi, "theta": theta,
                    "phi": phi},
        "duration": duration, "output": {"rate": rate},
        "effects": {"flywheel": {"inertia": JF, "axis": list(axis), "profile": {"time": time, "speed": speed}}}})


def random_quaternions(n, seed):
    rng = np.random.default_rng(seed)
    return [fw.qnormalize(rng.normal(size=4)) for _ in range(n)]


# --- conventions ------------------------------------------------------------------------------

def test_cayley_klein_parameters_are_S2_and_their_kinematics_S3():
    """α = w + iz, β = −y + ix: (2) with R = Rz(ψ)Rx(θ)Rz(φ) (physics.md's Euler angles with Y = I), and
    dq/dt = ½ q ⊗ (0, Ω_b) gives exactly [S] (3)."""
    rng = np.random.default_rng(0)
    e_kin = e_eul = e_frames = 0.0
    for q in random_quaternions(50, 1):
        om = rng.normal(size=3)
        wx, wy, wz = om
        dq = 0.5 * fw.qmul(q, np.r_[0.0, om])
        al, be = fw.cayley_klein(q)
        dal, dbe = complex(dq[0], dq[3]), complex(-dq[2], dq[1])
        s3a = 0.5j * wz * al + 0.5 * complex(wy, wx) * be  # [S] (3)
        s3b = -0.5j * wz * be - 0.5 * complex(wy, -wx) * al
        e_kin = max(e_kin, abs(dal - s3a), abs(dbe - s3b))
        psi, theta, phi = fw.euler_zxz(q)
        e_eul = max(e_eul, fw.attitude_error(q, fw.quat_from_euler_zxz(psi, theta, phi)))
        ref = euler_angles(quat_to_matrix(q), np.array([0.0, 0.0, 1.0]))  # frames.py, L along z3: Y = I
        e_frames = max(e_frames, float(np.max(np.abs(np.angle(np.exp(1j * (ref - [psi, theta, phi])))))))
    report("[S] (3) vs quaternion kinematics, max |Δ(α', β')|", e_kin, 1e-15)
    report("Euler z-x-z from (2) round trip, rad", e_eul, 1e-14)
    report("(2) Euler angles vs frames.euler_angles (L = z3), rad", e_frames, 1e-12)


def test_companion_axis_formulas_S24_S12_S25_S30_and_the_23_misprint():
    """(24) both ways, (12) = (25), λ = J_f|J⁻¹a| = J_f/|J e| ((8), (30)); (23) as printed flips k2's sign."""
    e24 = e_inv = e25 = e30 = e23_k1 = 0.0
    e23_k2_printed = math.inf
    for q in random_quaternions(40, 2):
        a = q[1:] / np.linalg.norm(q[1:])
        mu, nu = fw.axis_angles(a)
        A, B, C = J
        ms, ns = fw.companion_angles(J, mu, nu)
        # (24): tg μ* = (B/A) tg μ, cos ν* = ctg ν/(C R), sin ν* = (cos²μ/B² + sin²μ/A²)^½/R
        R = math.sqrt((math.cos(nu) / math.sin(nu)) ** 2 / C ** 2 + math.cos(mu) ** 2 / B ** 2 + math.sin(mu) ** 2 / A ** 2)
        e24 = max(e24, abs(math.tan(ms) - B / A * math.tan(mu)) / (1 + abs(math.tan(ms))),
                  abs(math.cos(ns) - math.cos(nu) / math.sin(nu) / (C * R)),
                  abs(math.sin(ns) - math.sqrt(math.cos(mu) ** 2 / B ** 2 + math.sin(mu) ** 2 / A ** 2) / R))
        mu2, nu2 = fw.wheel_angles_from_companion(J, ms, ns)
        e_inv = max(e_inv, float(np.linalg.norm(fw.axis_from_angles(mu2, nu2) - a)))
        k1, k2 = fw.ck_coefficients(J, mu, nu)
        e25 = max(e25, abs(k1 - np.exp(-1j * ms) / math.tan(0.5 * ns)) / abs(k1),
                  abs(k2 + math.tan(0.5 * ns) * np.exp(-1j * ms)) / abs(k2))
        lam = fw.turn_ratio(J, JF, a)
        e30 = max(e30, abs(lam - JF / fw.reduced_inertia(J, fw.companion_axis(J, a))) / lam)
        p1, p2 = fw.ck_coefficients_23_printed(J, mu, nu)
        e23_k1 = max(e23_k1, abs(p1 - k1) / abs(k1))
        e23_k2_printed = min(e23_k2_printed, abs(p2 - k2) / abs(k2))
        assert abs(p2 + k2) / abs(k2) < 1e-12  # printed (23) gives −k2
    report("(24) companion angles from the wheel angles", e24, 1e-12)
    report("(24) inverted: wheel axis from the companion angles", e_inv, 1e-12)
    report("(12) vs (25), relative", e25, 1e-12)
    report("(8) λ = J_f|J⁻¹a| vs (30) J_f/|J e|, relative", e30, 1e-14)
    report("(23) as printed, k1, relative", e23_k1, 1e-12)
    print(f"(23) as printed, k2: smallest relative difference from (12) {e23_k2_printed:.3f} "
          "(= 2: the printed factor (1 - ctg ν/(CR)) must be (ctg ν/(CR) - 1))")
    assert e23_k2_printed > 1.9


# --- forward problem in the full model --------------------------------------------------------

def test_forward_body_turns_about_the_fixed_companion_axis_full_model():
    """[S] (8), (9), (29) in gyro_sim.run: L = 0, a wheel axis off the principal axes, a speed profile that
    changes sign. The axis stays fixed, the turn is −λ∫Ω_f dt (opposite to the wheel), ω/Ω_f = λ."""
    a = np.asarray(A_OFF) / np.linalg.norm(A_OFF)
    q0 = fw.quat_from_euler_zxz(0.3, 1.1, -0.7)
    time, speed = [0.0, 0.5, 1.2, 2.0, 2.6], [0.0, 3000.0, -1000.0, 2000.0, 0.0]
    r = gyro_sim.run(scene(a, time, speed, 3.0, q0=q0))
    e = fw.companion_axis(J, a)
    lam = fw.turn_ratio(J, JF, a)
    tau, W = r.effects["flywheel_angle"], r.effects["flywheel_speed"]
    print(f"\nλ = {lam:.6g}, companion axis e = {e} vs wheel axis a = {a} ({math.degrees(math.acos(e @ a)):.2f} deg apart); "
          f"wheel turn {tau[-1]:.6g} rad, body turn {lam * tau[-1]:.6g} rad; {r.steps} steps, {r.wall_time:.2f} s wall")
    assert abs(tau[-1] - fw.profile_angle(time, speed)) < 1e-9
    assert math.degrees(math.acos(e @ a)) > 5.0  # the companion axis is not the wheel axis
    turn, off = fw.turn_about_axis(q0, r.q, e)
    report("turn about e + λ∫Ω_f dt, max over the run, rad", float(np.max(np.abs(turn + lam * tau))), 1e-9)
    report("rotation off the companion axis, max, rad", float(np.max(off)), 1e-9)
    e_case = np.einsum("nij,j->ni", quat_to_matrix(r.q), e)
    report("drift of the companion axis in the case frame", float(np.max(np.linalg.norm(e_case - e_case[0], axis=1))), 1e-12)
    m = np.abs(W) > 1.0
    om = r.omega_b[m]
    report("| |Ω_b|/|Ω_f| − λ | / λ", float(np.max(np.abs(np.linalg.norm(om, axis=1) / np.abs(W[m]) - lam))) / lam, 1e-12)
    report("Ω_b direction vs −sign(Ω_f) e", float(np.max(np.linalg.norm(om / (-lam * W[m][:, None]) - e, axis=1))), 1e-12)
    # sign convention: the body turns opposite to the wheel about the wheel axis
    assert np.all(np.sign(om @ a) == -np.sign(W[m]))
    # only ∫Ω_f matters ([S] (5)): final attitude = forward_attitude(q0, τ_end)
    report("final attitude vs q0 ⊗ exp(−½λτ e), rad", fw.attitude_error(r.q[-1], fw.forward_attitude(q0, J, JF, a, tau[-1])), 1e-9)
    # first integrals (19), (20): the cosines of the rotation axis with the fixed axes
    mu, nu = fw.axis_angles(a)
    A, B, C = J
    i19, i20 = [], []
    for q in r.q:
        psi, th, ph = fw.euler_zxz(q)
        i19.append((math.cos(nu) / math.sin(nu) / C * math.sin(th)
                    - math.cos(th) * (math.cos(ph) * math.cos(mu) / B + math.sin(ph) * math.sin(mu) / A)
                    - 1j * (math.sin(ph) * math.cos(mu) / B - math.cos(ph) * math.sin(mu) / A)) * np.exp(1j * psi))
        i20.append(math.cos(th) + math.tan(nu) * math.sin(th) * (C / B * math.cos(ph) * math.cos(mu)
                                                                 + C / A * math.sin(ph) * math.sin(mu)))
    report("[S] (19) variation over the run (× J3, dimensionless)", float(np.max(np.abs(np.array(i19) - i19[0]))) * C, 1e-9)
    report("[S] (20) variation over the run", float(np.max(np.abs(np.array(i20) - i20[0]))), 1e-9)


def test_gyrostat_kernel_with_nonzero_kinetic_moment():
    """The compiled gyrostat for L ≠ 0: J Ω̇ + Ω × (J Ω + h) + ḣ = 0, h = J_f Ω_f a (Euler's gyrostat
    equation, Ω̇ by a 5-point difference of the output); ½ Ω·J Ω constant while Ω_f is constant."""
    a = np.asarray(A_OFF) / np.linalg.norm(A_OFF)
    time, speed = [0.0, 0.5, 1.5, 2.0], [0.0, 300.0, 300.0, 0.0]
    dt = 1e-3
    r = gyro_sim.run(scene(a, time, speed, 2.0, rate=1.0 / dt, kinetic_moment=2.5e-4, L_direction=(0.3, -0.2, 1.0)))
    Jv = np.asarray(J)
    Om, W = r.omega_b, r.effects["flywheel_speed"]
    acc = np.array([fw_acc(t, time, speed) for t in r.t])
    report("|L(t) − L(0)| (no torque), N·m·s", float(np.max(np.abs(r.L - r.L[0]))), 0.0)
    res = []
    for k in range(2, len(r.t) - 2):
        if min(abs(r.t[k] - tk) for tk in time) < 2.5 * dt:
            continue  # Ω̇ jumps at the knots
        dOm = (Om[k - 2] - 8 * Om[k - 1] + 8 * Om[k + 1] - Om[k + 2]) / (12 * dt)
        h = JF * W[k] * a
        lhs = Jv * dOm + np.cross(Om[k], Jv * Om[k] + h) + JF * acc[k] * a
        res.append(np.linalg.norm(lhs) / np.linalg.norm(Jv * dOm))
    report("Euler gyrostat equation residual / |J Ω̇|", float(np.max(res)), 1e-6)
    seg = (r.t > 0.5 + 1e-9) & (r.t < 1.5 - 1e-9)
    E_locked = 0.5 * np.einsum("ni,i,ni->n", Om, Jv, Om)  # (RunResult.energy is the gyrostat's: the wheel's too)
    E = E_locked[seg]
    report("½ Ω·J Ω on the constant-speed segment, relative variation", float(np.ptp(E) / E.mean()), 1e-10)
    assert float(np.ptp(E_locked) / E_locked.mean()) > 1e-3  # …and it does change while the wheel accelerates


def fw_acc(t, time, speed):
    """dΩ_f/dt (rad/s²) of a piecewise-linear profile at t (right derivative)."""
    for i in range(len(time) - 1):
        if time[i] <= t < time[i + 1]:
            return (speed[i + 1] - speed[i]) / (time[i + 1] - time[i])
    return 0.0


# --- inverse problem -------------------------------------------------------------------------

def test_smolnikov_closed_forms_21_22_18_agree_with_the_plan():
    """[S] (21), (22) (wheel angles from the Euler angles of the two attitudes, as printed) and (18) with
    (12) (wheel turn) against plan_reorientation's vector solution (Euler's theorem + (24) inverted)."""
    e_axis = e_tau = e_att = 0.0
    qs = random_quaternions(40, 5)
    for q0, q1 in zip(qs[0::2], qs[1::2]):
        plan = fw.plan_reorientation(J, JF, q1, q0, duration=1.0)
        E0, E1 = fw.euler_zxz(q0), fw.euler_zxz(q1)
        mu, nu = fw.smolnikov_wheel_angles(J, E0, E1)
        tau = fw.smolnikov_wheel_turn(J, JF, mu, nu, E0, E1)
        lam = fw.turn_ratio(J, JF, fw.axis_from_angles(mu, nu))
        e_att = max(e_att, fw.attitude_error(fw.forward_attitude(q0, J, JF, fw.axis_from_angles(mu, nu), tau), q1))
        if lam * tau > math.pi:  # (21) fixes μ modulo π: the opposite axis turns the short way
            mu, nu, tau = mu + math.pi, math.pi - nu, (2 * math.pi - lam * tau) / lam
        e_axis = max(e_axis, float(np.linalg.norm(fw.axis_from_angles(mu, nu) - plan.axis)))
        e_tau = max(e_tau, abs(tau - plan.wheel_turn) / plan.wheel_turn)
    report("(21)-(22) wheel axis vs plan", e_axis, 1e-9)
    report("(18) wheel turn vs plan, relative", e_tau, 1e-9)
    report("(21)-(22)-(18) reach the target (closed form, rad)", e_att, 1e-12)


def test_planned_reorientations_reach_random_targets_in_the_full_model():
    """plan_reorientation → plan_scene → gyro_sim.run for random initial/target attitudes, a turn of
    π − 1e-6 and an exact half turn: the final attitude error is printed and bounded."""
    rng = np.random.default_rng(7)
    qs = random_quaternions(10, 11)
    cases = list(zip(qs[0::2], qs[1::2]))
    q0 = qs[0]
    e = rng.normal(size=3)
    e /= np.linalg.norm(e)
    cases.append((q0, fw.qmul(q0, fw.rotation_quaternion(e, math.pi - 1e-6))))
    cases.append((q0, fw.qmul(q0, np.r_[0.0, e])))  # exactly π
    worst = 0.0
    for i, (qi, qt) in enumerate(cases):
        plan = fw.plan_reorientation(J, JF, qt, qi, peak_speed=400.0, ramp=0.1)
        sc = gyro_sim.scene_from_dict(fw.plan_scene(plan, hold=0.2))
        r = gyro_sim.run(sc)
        err = fw.attitude_error(r.q[-1], qt)
        tau_err = abs(r.effects["flywheel_angle"][-1] - plan.wheel_turn)
        print(f"\n  target {i}: body turn {math.degrees(plan.body_turn):8.3f} deg, wheel turn {plan.wheel_turn:9.4f} rad, "
              f"profile end {plan.end_time:.3f} s, attitude error {err:.2e} rad, |∫Ω_f − τ| {tau_err:.1e} rad")
        assert abs(np.linalg.norm(r.L[-1])) == 0.0
        worst = max(worst, err)
    assert cases and abs(fw.plan_reorientation(J, JF, cases[-1][1], cases[-1][0], duration=1.0).body_turn - math.pi) < 1e-12
    report("planned reorientation, worst final attitude error in the full model, rad", worst, 1e-9)


def test_trapezoid_profile():
    cases = [dict(peak_speed=50.0, ramp=0.2), dict(duration=2.0), dict(duration=2.0, ramp=0.5),
             dict(peak_speed=20.0, duration=3.0), dict(peak_speed=500.0, ramp=1.0)]
    for kw in cases:
        for ang in (40.0, -40.0):
            t, w = fw.trapezoid_profile(ang, **kw, start=0.25)
            assert t[0] == 0.25 and w[0] == 0.0 and w[-1] == 0.0 and np.all(np.diff(t) > 0)
            assert abs(fw.profile_angle(t, w) - ang) < 1e-12 * 40
            assert np.all(np.sign(w[1:-1]) == np.sign(ang))
    t, w = fw.trapezoid_profile(40.0, peak_speed=500.0, ramp=1.0)  # too short for a plateau: triangle, same acceleration
    assert len(t) == 3 and abs(w[1] / t[1] - 500.0) < 1e-9 and w[1] < 500.0
    t, w = fw.trapezoid_profile(40.0, peak_speed=20.0, duration=3.0)
    assert max(w) == 20.0 and abs(t[-1] - 3.0) < 1e-12
    for kw in (dict(peak_speed=1.0), dict(peak_speed=1.0, ramp=1.0, duration=3.0), dict(duration=1.0, ramp=0.6),
               dict(peak_speed=10.0, duration=2.0), dict(peak_speed=100.0, duration=1.0), dict(duration=-1.0)):
        with pytest.raises(ValueError):
            fw.trapezoid_profile(40.0, **kw)
    with pytest.raises(ValueError, match="nothing to turn"):
        fw.plan_reorientation(J, JF, [1, 0, 0, 0], duration=1.0)


# --- CLI and the scene ------------------------------------------------------------------------

def test_cli_flywheel_plan_writes_a_scene_that_reaches_the_target(tmp_path, capsys):
    qt = fw.qnormalize([0.2, -0.7, 0.4, 0.55])
    out = tmp_path / "planned.yaml"
    code = cli.main(["flywheel-plan", "--inertia", *map(str, J), "--wheel-inertia", str(JF), "--target-quaternion",
                     *(repr(float(x)) for x in qt), "--initial-euler", "0.1", "0.2", "0.3", "--peak-speed", "300", "--ramp", "0.1",
                     "--write-scene", str(out)])
    text = capsys.readouterr().out
    with capsys.disabled():
        print("\n" + text)
    assert code == 0 and "wheel axis a" in text and "wheel turn" in text and out.is_file()
    r = gyro_sim.run(gyro_sim.load_scene(out))
    q0 = fw.quat_from_euler_zxz(0.1, 0.2, 0.3)
    with capsys.disabled():
        report("CLI-planned scene: final attitude error, rad", fw.attitude_error(r.q[-1], qt), 1e-9)
        report("CLI-planned scene: initial attitude, rad", fw.attitude_error(r.q[0], q0), 1e-12)
    # bad input: one error line, status 2
    for argv in (["--target-quaternion", "1", "0", "0", "0"],                      # nothing to turn
                 ["--target-quaternion", "0", "1", "0", "0", "--wheel-inertia", "-1"],
                 ["--target-quaternion", "0", "1", "0", "0", "--peak-speed", "1", "--ramp", "1", "--duration", "9"],
                 ["--target-quaternion", "0", "1", "0", "0", "--write-scene", str(out)]):  # exists
        base = ["flywheel-plan", "--inertia", *map(str, J), "--wheel-inertia", str(JF)]
        code = cli.main(base + argv)
        err = capsys.readouterr().err
        with capsys.disabled():
            print(f"  {' '.join(argv)} -> {code}: {err.strip()}")
        assert code == 2 and err.startswith("error: ") and err.count("\n") == 1


def test_scene_flywheel_reorientation_reaches_its_stated_target(tmp_path, capsys):
    """config/flywheel_reorientation.yaml: the target in its description is reached; the file's wheel axis
    and profile are those the plan of its header gives."""
    sc = gyro_sim.load_scene("flywheel_reorientation")
    m = re.search(r"q = \(([^)]*)\)", sc.description)
    qt = np.array([float(x) for x in m.group(1).split(",")])
    plan = fw.plan_reorientation(sc.rotor.inertia, sc.effects.flywheel.inertia, qt, peak_speed=60.0, ramp=0.2)
    assert np.allclose(plan.axis, sc.effects.flywheel.axis, rtol=0, atol=1e-12)
    assert np.allclose(plan.time, sc.effects.flywheel.profile.time, rtol=0, atol=1e-12)
    assert np.allclose(plan.speed, sc.effects.flywheel.profile.speed, rtol=0, atol=1e-12)
    header = CONFIG.read_text()
    assert "0.0354943" in header and "59.0066" in header and f"{plan.lam:.6g}" == "0.0354943"
    r = gyro_sim.run(sc)
    err = fw.attitude_error(r.q[-1], qt)
    print(f"\nflywheel_reorientation: {r.steps} steps, {r.wall_time:.3f} s wall; body axes in the case frame at the end:\n"
          f"{np.round(quat_to_matrix(r.q[-1]), 12)}")
    report("flywheel_reorientation: final attitude error vs the stated target, rad", err, 1e-9)
    assert cli.main(["run", "flywheel_reorientation", "--out", str(tmp_path), "--quiet"]) == 0
    assert (tmp_path / "flywheel_reorientation.png").is_file()
    out = capsys.readouterr().out
    with capsys.disabled():
        print(out)
    assert yaml.safe_load(CONFIG.read_text())["effects"]["flywheel"]["inertia"] == 2.0e-7
