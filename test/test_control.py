"""Control laws in the core: exact switching instants, no chattering near θ = 0, limits and modes."""
import math

import numpy as np
import pytest

import gyro_sim
from gyro_ctl.laws import make_law, make_switching
from gyro_sim.engine.simulate import Runner

PREC = 2 * math.pi / 204.0  # precession period of nutation_oblate, s (|L|/J1 ≈ 204 rad/s)


def nutation(**over):
    return gyro_sim.load_scene("nutation_oblate", overrides=over)


def time_below(r, deg):
    th = np.degrees(r.theta)
    i = int(np.argmax(th < deg))
    assert th[i] < deg, f"θ never fell below {deg}°: end {th[-1]:.3f}°"
    return float(r.t[i])


def test_event_located_switching_is_the_limit_of_fine_sampling():
    """ψ-switching with exact switching instants agrees with ever finer sampled control (θ after 0.1 s)."""
    base = {"duration": 0.1, "torque_model": "quasi_static"}
    th_ev = gyro_sim.run(nutation(**base, **{"controller.sampling": "events", "controller.period": 0.005})).theta[-1]
    errs = []
    for per in (1e-4, 2e-5):
        th = gyro_sim.run(nutation(**base, **{"controller.period": per})).theta[-1]
        errs.append(abs(th - th_ev) / th_ev)
        print(f"  sampled every {per * 1e3:g} ms: θ(0.1 s) = {math.degrees(th):.5f}° vs exact switching "
              f"{math.degrees(th_ev):.5f}°")
    print(f"\nrelative differences {['%.1e' % e for e in errs]}")
    assert errs[-1] < 5e-3 and errs[-1] < errs[0]


def test_switches_happen_where_the_switching_function_vanishes():
    s = nutation(**{"duration": 0.2, "controller.sampling": "events", "controller.period": 0.005})
    law, sw = make_law(s.controller), make_switching(s.controller)
    seen = []

    def spy(x):
        seen.append((x.t, np.min(np.abs(sw(x)))))
        return law(x)

    r = Runner(s)
    while not r.done:
        if r.row > 0 and r.is_control_tick:
            r.apply_commands(spy(r.control_input()))
        r.advance_located(spy, sw) if r.row > 0 else r.advance()
    off_tick = [v for t, v in seen if abs(t / 0.005 - round(t / 0.005)) > 1e-6]
    print(f"\n{len(off_tick)} switches between ticks; largest |u_n·e⊥| at a switch {max(off_tick):.1e}")
    assert len(off_tick) >= 2 * 0.2 / PREC  # two per precession period and stator, at least
    assert max(off_tick) < 1e-6


def test_no_chattering_near_theta_zero():
    """From θ0 = 1°: at most 2 field reversals per control stator per precession period, none in the dead band."""
    s = nutation(**{"duration": 0.4, "initial.theta": math.radians(1.0), "controller.sampling": "events",
                    "controller.period": 0.005, "output.rate": 1000.0})
    r = gyro_sim.run(s)
    flips = {}
    for name in ("z1", "z2"):
        rates = [(t, rate[names.index(name)]) for t, names, cur, rate in r.commands
                 if name in names and cur[names.index(name)] > 0]  # reversals of a field that is on
        t = np.array([a for a, _ in rates])
        sg = np.sign([b for _, b in rates])
        flips[name] = t[1:][np.diff(sg) != 0]
    t_in = time_below(r, math.degrees(s.controller.params.dead_band))
    for name, tf in flips.items():
        per_period = len(tf[tf < t_in]) / max(t_in / PREC, 1e-9)
        after = np.sum(tf > t_in + 1e-3)
        print(f"  {name}: {len(tf)} reversals, {per_period:.2f} per precession period before the dead band "
              f"(reached at {t_in:.3f} s), {after} after")
        assert per_period <= 2.5 and after == 0


def test_theta_to_pi_with_negative_nu():
    s = nutation(**{"duration": 3.0, "controller.params.nu": [-3000.0, -5000.0], "controller.sampling": "events",
                    "controller.params.control_current": 0.7, "controller.period": 0.005, "output.rate": 200.0})
    r = gyro_sim.run(s)
    th = np.degrees(r.theta)
    i = int(np.argmax(th > 179.9))
    print(f"\nθ: {th[0]:.1f}° → {th[-1]:.3f}°, above 179.9° from t = {r.t[i]:.3f} s")
    assert th[i] > 179.9 and th[-1] > 179.9


def test_limits_clip_every_command():
    s = nutation(**{"duration": 0.05, "controller.current_limit": 0.2, "controller.rate_limit": 1000.0})
    r = gyro_sim.run(s)
    cur = np.array([c for _, _, cs, _ in r.commands for c in cs if c is not None])
    rates = np.array([v for _, _, _, rs in r.commands for v in rs if v is not None])
    assert cur.max() == pytest.approx(0.2) and np.abs(rates).max() == pytest.approx(1000.0)
    assert np.max(r.current) <= 0.2


@pytest.mark.parametrize("law,params,check", [
    ("off", {}, lambda r: np.all(r.current[1:] == 0.0)),
    ("hold", {}, lambda r: np.all(r.current == r.current[0]) and r.commands == []),
    ("manual", {"commands": {"z3": {"current": 0.7, "rate": -50.0}}},
     lambda r: np.all(r.current[1:, 2] == 0.7) and np.all(r.field_rate[1:, 2] == -50.0)),
])
def test_off_hold_manual(law, params, check):
    d = {"duration": 0.05, "controller": {"law": law, "period": 0.01, "params": params},
         "stators.2.current": 0.3}
    s = gyro_sim.load_scene("nutation_oblate", overrides=d)
    assert check(gyro_sim.run(s))


@pytest.mark.parametrize("law,params,reason", [
    ("spinup", {"stator": "z9", "target_spin": 1.0, "current": 1.0}, "stator = 'z9': stator 'z9'"),
    ("psi_switching", {"control_stators": ["z1", "z9"], "nu": 1.0, "control_current": 1.0, "spin_current": 1.0,
                       "spin_rate": 1.0}, "control_stators = ['z1', 'z9']: stator 'z9'"),
    ("psi_switching", {"spin_stator": "z7", "nu": 1.0, "control_current": 1.0, "spin_current": 1.0,
                       "spin_rate": 1.0}, "spin_stator = 'z7': stator 'z7'"),
    ("manual", {"commands": {"z3": {"current": 1.0, "rate": 1.0}, "z8": {"current": 1.0, "rate": 1.0}}},
     "commands = ['z3', 'z8']: stator 'z8'"),
])
def test_unknown_stators_names_the_parameter_value_and_allowed(law, params, reason):
    """The one check of a law's stator names against a scene's (scene files and the controller node use it)."""
    from gyro_ctl.config import ControllerConfig, unknown_stators

    cfg = ControllerConfig(law=law, params=params)
    assert unknown_stators(cfg, ["z1", "z2", "z3"]) == f"{reason} is not defined; allowed: ['z1', 'z2', 'z3']"
    assert unknown_stators(cfg, ["z1", "z2", "z3", "z7", "z8", "z9"]) == ""
    assert unknown_stators(ControllerConfig(law="off", params={}), []) == ""


def test_bad_controller_section_is_refused():
    with pytest.raises(gyro_sim.SceneError,
                       match=r"controller.params.spin_stator = 'z9': stator 'z9' is not defined; allowed: \['z1', 'z2', 'z3'\]"):
        gyro_sim.load_scene("nutation_oblate", overrides={"controller.params.spin_stator": "z9"})
    with pytest.raises(gyro_sim.SceneError, match=r"one rate per control stator"):
        gyro_sim.load_scene("nutation_oblate", overrides={"controller.params.nu": [1.0, 2.0, 3.0]})
    with pytest.raises(gyro_sim.SceneError, match=r"share one sign"):
        gyro_sim.load_scene("nutation_oblate", overrides={"controller.params.nu": [1.0, -2.0]})


def test_lowest_control_rate_for_psi_switching():
    """Sampled ψ-switching (as over ROS in lockstep, which gives the same numbers) needs ≈ 4 ticks per
    precession period: at 8 ms (3.9 ticks) θ still settles below 0.1°, at 15.5 ms (2 ticks) it does not."""
    out = {}
    for per in (0.008, 0.0155):
        r = gyro_sim.run(nutation(**{"controller.period": per, "duration": 2.0, "output.rate": 500.0}))
        out[per] = math.degrees(r.theta[-1])
        print(f"  period {per * 1e3:g} ms = {PREC / per:.1f} ticks per precession period: θ(2 s) = {out[per]:.3f}°")
    assert out[0.008] < 0.1 and out[0.0155] > 1.0


def test_event_switching_is_the_same_with_and_without_a_sample_callback():
    """In-process runs look for switching zeros between output samples whether or not a caller takes the
    samples (a controller period longer than the output period: 20 ms against 1 ms)."""
    sc = gyro_sim.load_scene("nutation_oblate", overrides={"initial.theta": math.radians(1.0), "controller.period": 0.02,
                                                           "output.rate": 1000.0, "controller.sampling": "events"})
    a = gyro_sim.run(sc, duration=0.3)
    b = gyro_sim.run(sc, duration=0.3, on_samples=lambda rows: None)
    print(f"\n  {len(a.commands)} commands without, {len(b.commands)} with a callback")
    assert len(a.commands) == len(b.commands) and np.array_equal(a.L, b.L) and np.array_equal(a.q, b.q)


def test_a_command_in_force_is_not_applied_again(monkeypatch):
    """A law that repeats its command at every tick (the lockstep spin-up): the run and its shadow are left alone
    (the same field, rates, step plan), and the command is still logged; a changed value, a rate of the other zero
    sign or a value that is no float goes through set_stators (its checks) as before."""
    from gyro_sim.engine.simulator import Simulator

    r = Runner(gyro_sim.load_scene("spinup_thin_shell"), 0.1, attitude=True)
    r.advance()  # (t = 0, the scene's commands)
    calls = []
    real = Simulator.set_stators
    monkeypatch.setattr(Simulator, "set_stators", lambda self, c: (calls.append(dict(c)), real(self, c)))
    cur, rate = float(r.sim.current[2]), float(r.sim.rate[2])
    n_log = len(r.command_log)
    r.apply_commands({"z3": (cur, rate)})
    r.apply_commands({"z3": (cur, None)})
    assert calls == [] and len(r.command_log) == n_log + 2
    r.apply_commands({"z3": (cur * 0.5, rate)})
    assert len(calls) == 1
    r.apply_commands({"z1": (0.0, -0.0)})  # (z1's rate is +0.0: the sign is the command's)
    r.apply_commands({"z3": (int(cur) if cur == int(cur) else cur, rate)})
    assert len(calls) == 2 + (cur == int(cur))
    assert math.copysign(1.0, float(r.sim.rate[0])) == -1.0
    with pytest.raises(ValueError, match="current"):
        r.apply_commands({"z3": (math.nan, rate)})
