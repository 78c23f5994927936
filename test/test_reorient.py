"""Reorientation of L along axis-parallel paths in prescribed times ([K] §2, physics.md §5, §6 item 6).

The program's formulas against the averaged equations (held components still, the moved one arrives
on time) and against [K] as printed; the law against the full model (quasi-static torque, thin shell
spinning, three stators at distinct rates); refusals. Every test prints what it measured.
"""
import math
from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError
from scipy.integrate import solve_ivp

from gyro_ctl.reorient import (ReorientParams, averaged_gamma, averaged_rate, plan, reorient, scene_constants,
                               segment_program)
from gyro_sim.physics.closed_forms import quasi_static_mean_torque
from gyro_sim.scenes.scene import SceneError, parse_scene_text, scene_from_dict
from gyro_sim.engine.simulate import Runner, stator_triad

SHELL = {"kind": "thin_shell", "outer_radius": 0.025, "thickness": 0.001, "conductivity": 2.5e7}
J_OBLATE = [5.592e-6, 5.592e-6, 5.704e-6]
AXES = {"z1": [1.0, 0.0, 0.0], "z2": [0.0, 1.0, 0.0], "z3": [0.0, 0.0, 1.0]}
CONFIG = Path(__file__).resolve().parents[1] / "config" / "reorient_L.yaml"


def report(name, err, tol):
    print(f"\n{name}: measured {err:.3e}, tolerance {tol:.1e}")
    assert err <= tol, f"{name}: {err:.3e} > {tol:.1e}"


def base_scene(spin=200.0, duration=5.0, b=1e-2, torque_model="quasi_static"):
    return {"name": "reorient_test", "rotor": {"inertia": J_OBLATE, "conductor": SHELL}, "torque_model": torque_model,
            "stators": [{"name": n, "axis": a, "coil_constant": b} for n, a in AXES.items()],
            "initial": {"spin": spin, "L_direction": [0, 0, 1], "theta": 0.01}, "duration": duration,
            "output": {"rate": 100.0}}


def with_controller(d: dict, params: ReorientParams, period: float):
    """The scene with its reorient controller; if 'reorient' is not registered yet, a placeholder
    controller section gives the Runner its ticks (the law is driven by :func:`drive` either way)."""
    d = dict(d)
    d["controller"] = {"law": "reorient", "period": period, "params": params.model_dump(exclude={"law"})}
    try:
        return scene_from_dict(d)
    except SceneError:
        d["controller"] = {"law": "spinup", "period": period,
                           "params": {"stator": "z3", "target_spin": 0.0, "current": 0.0}}
        return scene_from_dict(d)


def drive(scene, law):
    """The loop of gyro_sim.run with the law given directly."""
    r = Runner(scene)
    while not r.done:
        if r.row > 0 and r.is_control_tick:
            r.apply_commands(law(r.control_input()))
        r.advance()
    return r.result()


def small_parameter(params: ReorientParams, segs, L_norm: float) -> float:
    """μ = largest mean torque c_k|ν_k| over (|L| × the slowest fast frequency, the smallest beat |ν_i| − |ν_j|)."""
    nu = sorted(params.rates.values())
    beat = min(nu[1] - nu[0], nu[2] - nu[1])
    M0 = max(float(np.max(s.c * np.abs(s.rates))) for s in segs)
    return M0 / (L_norm * beat)


def value_at(res, t):
    return res.L[int(np.argmin(np.abs(res.t - t)))]


# --- the averaged equations ---------------------------------------------------------------------------

def test_averaged_equation_is_K13_summed_over_the_stators():
    """dL_k/dt = c_k ν_k − ½(C + c_k) γ L_k/J is Σ_k [K] (1.3) at Ω = ⟨Ω⟩ = γ L/J; ⟨Ω⟩ checked by averaging
    the body's angular velocity over ψ and φ at fixed θ (triaxial rotor)."""
    rng = np.random.default_rng(3)
    Jb = np.array([4.0e-6, 5.0e-6, 6.5e-6])
    worst_t = worst_w = 0.0
    for _ in range(20):
        L = rng.normal(size=3) * 1e-3
        theta = rng.uniform(0.05, 3.0)
        k_e, b = 0.02, np.array([1e-2, 2e-2, 1.5e-2])
        I = rng.uniform(0.1, 1.0, 3)
        nu = rng.uniform(-900, 900, 3)
        J, gamma = averaged_gamma(Jb, theta)
        Om = gamma * L / J
        total = sum(quasi_static_mean_torque(k_e, b[k] * I[k], nu[k], AXES[f"z{k + 1}"], stator_triad(AXES[f"z{k + 1}"])[0],
                                             Om) for k in range(3))
        c = k_e * (b * I) ** 2
        worst_t = max(worst_t, np.linalg.norm(averaged_rate(L, c, nu, J, gamma) - total) / np.linalg.norm(total))
        # ⟨Ω⟩ over the fast angles: Ω = R J⁻¹ Rᵀ L with R = Y Rz(ψ) Rx(θ) Rz(φ)
        y3 = L / np.linalg.norm(L)
        y1 = np.cross([0.3, 0.5, 0.8], y3)
        y1 /= np.linalg.norm(y1)
        Y = np.column_stack([y1, np.cross(y3, y1), y3])
        n = 64
        acc = np.zeros(3)
        for psi in np.arange(n) * 2 * math.pi / n:
            for phi in np.arange(n) * 2 * math.pi / n:
                R = Y @ _rz(psi) @ _rx(theta) @ _rz(phi)
                acc += R @ ((R.T @ L) / Jb)
        worst_w = max(worst_w, np.linalg.norm(acc / n**2 - Om) / np.linalg.norm(Om))
    report("Σ [K] (1.3) vs the SI averaged equation, relative", worst_t, 1e-13)
    report("<Ω> over ψ, φ vs γ L/J, relative", worst_w, 1e-12)


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def _random_cases(n, seed):
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        L = rng.normal(size=3) * 1e-3
        p = int(rng.integers(3))
        target = L[p] + rng.normal() * 4e-4
        rates = rng.uniform(300, 1200, 3)
        theta = rng.uniform(0, math.pi)
        T = rng.uniform(0.5, 5.0)
        kw = dict(inertia=J_OBLATE, theta=theta, k_e=0.02045, coil_constants=[1e-2, 1.2e-2, 0.8e-2], rates=rates)
        try:
            seg = segment_program(L, p, target, T, **kw)
        except ValueError:
            continue
        out.append((L, p, target, T, kw, seg))
    return out


def test_program_holds_the_other_components_and_arrives_in_time():
    """[K] §2: with the program's c_k, l_q′ = l_r′ = 0 and the averaged equations carry L_p to its target in T_p."""
    worst_hold = worst_end = worst_q = 0.0
    for L, p, target, T, kw, seg in _random_cases(40, 7):
        J, gamma = averaged_gamma(kw["inertia"], kw["theta"])
        rhs = averaged_rate(L, seg.c, seg.rates, J, gamma)
        scale = float(np.max(seg.c * np.abs(seg.rates)))
        q, r = (p + 1) % 3, (p + 2) % 3
        worst_hold = max(worst_hold, abs(rhs[q]) / scale, abs(rhs[r]) / scale)
        sol = solve_ivp(lambda t, y, seg=seg, J=J, gamma=gamma: averaged_rate(y, seg.c, seg.rates, J, gamma), (0, T), L,
                        rtol=1e-12, atol=1e-18)
        end = sol.y[:, -1]
        worst_end = max(worst_end, abs(end[p] - target) / abs(target - L[p]))
        worst_q = max(worst_q, abs(end[q] - L[q]) / np.linalg.norm(L), abs(end[r] - L[r]) / np.linalg.norm(L))
        assert np.all(seg.c >= 0) and np.all(np.isfinite(seg.currents))
    report("held components: |dL_q/dt|, |dL_r/dt| / largest c_k|ν_k|", worst_hold, 1e-13)
    report("averaged model: |L_p(T_p) − target| / |move|", worst_end, 1e-9)
    report("averaged model: held components' change / |L|", worst_q, 1e-10)


def test_program_equals_K_section_2_as_printed():
    """The SI program is [K] §2 in non-dimensional form with c_k = μ m_k J Ω0 (any Ω0, μ)."""
    worst = 0.0
    for L, p, target, T, kw, seg in _random_cases(20, 11):
        J, gamma = averaged_gamma(kw["inertia"], kw["theta"])
        Om0, mu = 173.0, 3.1e-3
        l, nu_t = L / (J * Om0), seg.rates / Om0
        q, r = (p + 1) % 3, (p + 2) % 3
        lp1, lp2, lq, lr = l[p], target / (J * Om0), l[q], l[r]
        Delta = 4 * (nu_t[q] - gamma * lq) * (nu_t[r] - gamma * lr) - gamma**2 * lq * lr
        lam = gamma * (2 * gamma**2 * lq * lr - 3 * gamma * (nu_t[q] * lr + nu_t[r] * lq) + 4 * nu_t[q] * nu_t[r]) / Delta
        m = np.empty(3)
        m[p] = math.log((nu_t[p] - lam * lp1) / (nu_t[p] - lam * lp2)) / (mu * lam * T * Om0)
        m[q] = gamma * m[p] * lq * (2 * nu_t[r] - gamma * lr) / Delta
        m[r] = gamma * m[p] * lr * (2 * nu_t[q] - gamma * lq) / Delta
        c = mu * m * J * Om0
        worst = max(worst, float(np.max(np.abs(c - seg.c))) / float(np.max(seg.c)), abs(lam - seg.lam) / abs(lam))
    report("SI program vs [K] §2 printed (non-dimensional), relative", worst, 1e-9)


# --- refusals -----------------------------------------------------------------------------------------

def _params(**kw):
    d = dict(waypoints=[{"axis": "z1", "target": 2.9e-4, "duration": 2.0}], rates={"z1": 440.0, "z2": 540.0, "z3": 660.0},
             coil_constants={"z1": 1e-2, "z2": 1e-2, "z3": 1e-2}, inertia=J_OBLATE, k_e=0.020453, current_limit=1.0)
    d.update(kw)
    return ReorientParams(**d)


def test_target_beyond_the_asymptote_is_refused():
    L0 = [0.0, 0.0, 5.704e-6 * 200.0]
    seg = plan(_params(), L0)[0]
    asym = seg.asymptote
    print(f"\nasymptote of the z1 move: {asym:.6e} N·m·s (λ = {seg.lam:.6f})")
    for target in (1.2 * asym, asym):  # beyond it, and the asymptote itself (reached only as t → ∞)
        with pytest.raises(ValueError) as e:
            plan(_params(waypoints=[{"axis": "z1", "target": target, "duration": 2.0}], current_limit=100.0), L0)
        msg = str(e.value)
        print(msg)
        assert "waypoint 1" in msg and "axis z1" in msg and f"{target:.4g}" in msg
        assert "reachable limit" in msg and f"{asym:.4g}" in msg
    # just inside: accepted (with a current to match)
    plan(_params(waypoints=[{"axis": "z1", "target": 0.9 * asym, "duration": 2.0}], current_limit=100.0), L0)
    # the law refuses the same program at its first tick
    x = _input(0.0, L0)
    with pytest.raises(ValueError, match="reachable limit"):
        reorient(x, _params(waypoints=[{"axis": "z1", "target": 1.2 * asym, "duration": 2.0}], current_limit=100.0))
    # a later waypoint is checked from the start too (here the second one)
    with pytest.raises(ValueError, match="waypoint 2"):
        reorient(x, _params(waypoints=[{"axis": "z2", "target": 1e-4, "duration": 2.0},
                                       {"axis": "z1", "target": 1.2 * asym, "duration": 2.0}], current_limit=100.0))


def test_currents_above_the_limit_are_refused():
    L0 = [0.0, 0.0, 5.704e-6 * 200.0]
    seg = plan(_params(current_limit=100.0), L0)[0]
    need = float(seg.currents.max())
    with pytest.raises(ValueError) as e:
        plan(_params(current_limit=0.5 * need), L0)
    msg = str(e.value)
    print(f"\n{msg}")
    assert "waypoint 1" in msg and "current_limit" in msg and "shortest duration" in msg
    t_min = 2.0 * 4.0  # I ∝ 1/√T: half the current needs four times the time
    assert f"{t_min:.4g}" in msg
    plan(_params(current_limit=0.5 * need, waypoints=[{"axis": "z1", "target": 2.9e-4, "duration": 1.001 * t_min}]), L0)


def test_params_are_validated():
    with pytest.raises(ValidationError, match="not a stator"):
        _params(waypoints=[{"axis": "z4", "target": 1e-4, "duration": 1.0}])
    with pytest.raises(ValidationError, match="must differ"):
        _params(rates={"z1": 440.0, "z2": 440.0, "z3": 660.0})
    with pytest.raises(ValidationError, match="coil_constants"):
        _params(coil_constants={"z1": 1e-2, "z2": 1e-2})
    with pytest.raises(ValidationError):
        _params(gain=1.0)
    with pytest.raises(ValidationError):
        _params(waypoints=[{"axis": "z1", "target": 1e-4, "duration": 0.0}])
    assert _params().stators_used() == ["z1", "z2", "z3"]


def _input(t, L, axes=None):
    from gyro_ctl.laws import ControlInput

    ax = np.array(list(AXES.values()) if axes is None else axes)
    return ControlInput(t=t, L=np.asarray(L, float), q=np.array([1.0, 0, 0, 0]), omega_b=np.zeros(3),
                        stator_names=tuple(AXES), stator_axes=ax)


def test_law_schedule_and_stator_geometry():
    p = _params(start=0.5)
    L0 = [0.0, 0.0, 5.704e-6 * 200.0]
    assert all(c[0] == 0.0 for c in reorient(_input(0.2, L0), p).values())  # before start: off
    assert all(c[0] == 0.0 for c in reorient(_input(2.5, L0), p).values())  # after the last waypoint: off
    on = reorient(_input(0.5, L0), p)
    seg = plan(p, L0)[0]
    for k, n in enumerate(p.stator_names):  # at the waypoint's start the law is the open-loop program
        assert on[n][0] == pytest.approx(seg.currents[k], rel=1e-12) and on[n][1] == seg.rates[k]
    with pytest.raises(ValueError, match="orthonormal"):
        reorient(_input(1.0, L0, axes=[[1, 0, 0], [0.6, 0.8, 0], [0, 0, 1]]), p)


# --- the full model ---------------------------------------------------------------------------------

SPIN = 200.0
L3 = J_OBLATE[2] * SPIN


def _two_moves(scene_d, T=2.0, start=0.25, limit=2.0):
    s0 = scene_from_dict(scene_d)
    return ReorientParams(waypoints=[{"axis": "z1", "target": 0.25 * L3, "duration": T},
                                     {"axis": "z2", "target": -0.2 * L3, "duration": T}],
                          rates={"z1": 2.2 * SPIN, "z2": 2.7 * SPIN, "z3": 3.3 * SPIN}, current_limit=limit,
                          start=start, **scene_constants(s0))


def _check_run(res, p, segs, label, k_tol=3.0):
    """Errors at each waypoint's end (and along the path) against μ|L|; returns the largest end error / |L|."""
    mu = small_parameter(p, segs, L3)
    print(f"\n{label}: μ = {mu:.2e}")
    nominal = np.array([0.0, 0.0, L3])
    worst_end = 0.0
    J, gamma = averaged_gamma(p.inertia, 0.0)
    for i, ((t0, t1), w, seg) in enumerate(zip(p.schedule(), p.waypoints, segs)):
        k = p.stator_names.index(w.axis)
        start = nominal.copy()
        nominal[k] = w.target
        err = value_at(res, t1) - nominal
        print(f"  waypoint {i + 1} ({w.axis} → {w.target:.4e} N·m·s in {w.duration} s): error at t = {t1} s "
              f"{np.array2string(err, precision=3)} N·m·s = {np.linalg.norm(err) / L3:.2e} |L| = "
              f"{np.linalg.norm(err) / (mu * L3):.2f} μ|L|")
        worst_end = max(worst_end, float(np.linalg.norm(err)))
        # along the path: held components stay, the moved one follows the exponential of the program
        sel = (res.t >= t0) & (res.t <= t1)
        a = seg.c[k] * seg.lam / J
        Linf = J * seg.rates[k] / seg.lam
        path = Linf + (start[k] - Linf) * np.exp(-a * (res.t[sel] - t0))
        dev_path = float(np.max(np.abs(res.L[sel, k] - path)))
        dev_held = float(np.max(np.abs(np.delete(res.L[sel] - start, k, axis=1))))
        print(f"    along the path: |L_p − program| ≤ {dev_path / L3:.2e} |L|, held components moved ≤ "
              f"{dev_held / L3:.2e} |L|")
        assert dev_path <= 2 * k_tol * mu * L3 and dev_held <= 2 * k_tol * mu * L3
    report(f"{label}: largest end error / (μ|L|)", worst_end / (mu * L3), k_tol)
    after = res.L[res.t >= p.schedule()[-1][1]]
    assert np.max(np.abs(after - after[0])) <= 1e-12 * L3  # fields off: L stays put
    return worst_end / L3


def test_full_model_moves_L_along_z1_then_z2_closed_loop():
    """The law (re-planned at every 10 ms tick) drives the full model: L along z1, then z2, others held."""
    d = base_scene(spin=SPIN, duration=4.5)
    p = _two_moves(d)
    segs = plan(p, [0.0, 0.0, L3], theta=0.01)
    res = drive(with_controller(d, p, 0.01), lambda x: reorient(x, p))
    assert res.current.max() <= p.current_limit
    _check_run(res, p, segs, "closed loop (law), spin 200 rad/s")


def test_full_model_open_loop_program_of_K():
    """[K] §2 as an open-loop program (constant currents per waypoint, planned from the initial state)."""
    d = base_scene(spin=SPIN, duration=4.5)
    p = _two_moves(d)
    segs = plan(p, [0.0, 0.0, L3], theta=0.01)
    sched = p.schedule()

    def program(x):
        for (t0, t1), s in zip(sched, segs):
            if t0 - 1e-9 <= x.t < t1 - 1e-9:
                return s.commands()
        return {n: (0.0, p.rates[n]) for n in p.stator_names}

    res = drive(with_controller(d, p, 0.01), program)
    _check_run(res, p, segs, "open loop (program), spin 200 rad/s")


def test_error_shrinks_with_mu():
    """Faster spin and fields (same program in units of L3): μ halves twice; the end error follows (O(μ))."""
    errs = []
    for spin in (200.0, 800.0):
        d = base_scene(spin=spin, duration=4.5)
        L3s = J_OBLATE[2] * spin
        s0 = scene_from_dict(d)
        p = ReorientParams(waypoints=[{"axis": "z1", "target": 0.25 * L3s, "duration": 2.0},
                                      {"axis": "z2", "target": -0.2 * L3s, "duration": 2.0}],
                           rates={"z1": 2.2 * spin, "z2": 2.7 * spin, "z3": 3.3 * spin}, current_limit=5.0,
                           start=0.25, **scene_constants(s0))
        segs = plan(p, [0.0, 0.0, L3s], theta=0.01)
        mu = small_parameter(p, segs, L3s)
        res = drive(with_controller(d, p, 0.01), lambda x, p=p: reorient(x, p))
        target = np.array([0.25 * L3s, -0.2 * L3s, L3s])
        err = float(np.linalg.norm(res.L[-1] - target)) / L3s
        print(f"\nspin {spin} rad/s: μ = {mu:.2e}, final error {err:.2e} |L| = {err / mu:.2f} μ|L|")
        assert err <= 3 * mu
        errs.append((mu, err))
    assert errs[1][0] < 0.3 * errs[0][0] and errs[1][1] < 0.5 * errs[0][1]


# --- the built-in scene --------------------------------------------------------------------------------

def test_config_scene_reorient_L():
    """config/reorient_L.yaml: its params validate, repeat the scene's constants, plan, and run to the targets."""
    data = parse_scene_text(CONFIG.read_text())
    ctl = data["controller"]
    assert ctl["law"] == "reorient"
    p = ReorientParams(**ctl["params"])
    bare = {k: v for k, v in data.items() if k != "controller"}
    consts = scene_constants(scene_from_dict(bare))
    assert p.inertia == consts["inertia"] and p.coil_constants == consts["coil_constants"]
    assert p.k_e == pytest.approx(consts["k_e"], rel=1e-12)
    L0 = np.array(data["initial"]["L_direction"], float) * data["rotor"]["inertia"][2] * data["initial"]["spin"]
    segs = plan(p, L0, theta=data["initial"]["theta"])
    try:
        from gyro_ctl.laws import LAWS
        registered = "reorient" in LAWS
    except ImportError:
        registered = False
    if registered:
        import gyro_sim

        res = gyro_sim.run(gyro_sim.load_scene(str(CONFIG)))
    else:
        res = drive(with_controller(bare, p, ctl["period"]), lambda x: reorient(x, p))
    nominal = L0.copy()
    mu = small_parameter(p, segs, float(np.linalg.norm(L0)))
    print(f"\nreorient_L ({'registered law' if registered else 'law driven directly'}): μ = {mu:.2e}")
    for (_t0, t1), w in zip(p.schedule(), p.waypoints):
        nominal[p.stator_names.index(w.axis)] = w.target
        err = float(np.linalg.norm(value_at(res, t1) - nominal))
        print(f"  waypoint {w.axis} → {w.target:.3e}: error {err:.2e} N·m·s = {err / (mu * np.linalg.norm(L0)):.2f} μ|L|")
        assert err <= 3 * mu * np.linalg.norm(L0)
