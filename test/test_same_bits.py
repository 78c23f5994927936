"""The per-check and per-break code in Python floats (issue 28) gives the bits of the NumPy code it replaced."""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from gyro_sim.engine.simulator import Simulator
from gyro_sim.physics.frames import attitude_split, attitude_split_one, cross_rows
from gyro_sim.scenes.scene import load_scene, merge_times
from gyro_sim.scenes.step_control import COARSE_ORDER, ESTIMATE_ORDER, ORDER, R_MEASURABLE, STIFF_ORDER, ErrorControl


def _bits(x) -> bytes:
    return np.asarray(x, dtype=float).tobytes()


# --- the error control's code before issue 28's cut (the reference the one-pass code is held to) ----------------
def _ref_denom(ctl, lengths: bool) -> float:
    """ErrorControl.denom (``lengths`` False) / denom_estimate (True) as one sum each."""
    if not sum(ctl.weights.values()) + sum(ctl.finer.values()):
        return math.inf
    acc, n = 0.0, 0
    for m, k in ctl.weights.items():
        r = k / max(ctl.shadow_steps.get(m, k), 1)
        if r >= R_MEASURABLE:
            p = ORDER.get(m, STIFF_ORDER)
            if lengths:  # (the stretches whose shadow was below SPT_MIN at COARSE_ORDER; the free stepper's at
                # ESTIMATE_ORDER)
                r = max(min(r, k / max(ctl.shadow_len.get(m, k), 1)), R_MEASURABLE)
                kc = min(ctl.coarse.get(m, 0), k)
                pe = ESTIMATE_ORDER.get(m, p)
                acc += (k - kc) / (r ** pe - 1.0) + (kc / (r ** COARSE_ORDER[m] - 1.0) if kc else 0.0)
            else:
                acc += k / (r ** p - 1.0)
            n += k
    for (m, f), k in ctl.finer.items():
        acc += k / (1.0 - f ** -ORDER.get(m, STIFF_ORDER))
        n += k
    return n / acc if acc > 0 else math.inf


def _ref_diff(ctl, main, shadow) -> tuple:
    """(| |L| − |L_s| |, |L − L_s|, direction, phase) of the pair, from the arrays."""
    L, Ls = main.y[0:3], shadow.y[0:3]
    dL = L - Ls
    dLn = abs(math.sqrt(float(L.dot(L))) - math.sqrt(float(Ls.dot(Ls))))
    dq = dp = 0.0
    if ctl.attitude:
        d, p = attitude_split_one(main.y[3:7], shadow.y[3:7], ctl.axis, L, Ls)
        dq, dp = float(d), float(p)
    return dLn, math.sqrt(float(dL.dot(dL))), dq, dp


def _ref_now(raw: tuple, den: float) -> tuple:
    """((|ΔL|, direction, phase) errors, error of |L|) of the raw differences at denominator ``den``."""
    if not math.isfinite(den):
        return (0.0, 0.0, 0.0), 0.0
    dLn, dL, dq, dp = raw
    return (dL / den, dq / den, dp / den), dLn / den


@pytest.fixture(scope="module")
def sim():
    scene = load_scene("three_stators", overrides={"duration": 1.0})
    return Simulator(scene, horizon=1.0, warn_plan=False)


def test_phasors_in_python_floats_as_numpy(sim):
    """Terms._phasors (the stators alone: Python floats) = its NumPy form, bit for bit, on random commands."""
    terms = sim.terms
    rng = np.random.default_rng(28)
    k = terms.b.size
    for _ in range(2000):
        cur = rng.uniform(0.0, 2.0, k) * (rng.random(k) < 0.6)
        rate = rng.uniform(-5e3, 5e3, k)
        phase = rng.uniform(-50.0, 50.0, k)
        t = float(rng.uniform(0.0, 10.0))
        a, b = terms._phasors(t, cur, rate, phase), terms._phasors_array(t, cur, rate, phase)
        for x, y in zip(a, b, strict=True):
            assert x.shape == y.shape and x.dtype == y.dtype and _bits(x) == _bits(y)


def test_attitude_split_one_as_the_error_control_took_it():
    """attitude_split_one from arrays and from lists of Python floats: the same bits; and within round-off of the
    vectorised attitude_split."""
    rng = np.random.default_rng(1)
    for _ in range(3000):
        q1 = rng.standard_normal(4)
        q1 /= np.linalg.norm(q1)
        q2 = q1 + rng.standard_normal(4) * 10 ** rng.uniform(-10, -1)
        q2 /= np.linalg.norm(q2)
        L1 = rng.standard_normal(3) * 10 ** rng.uniform(-6, 2)
        L2 = L1 + rng.standard_normal(3) * 1e-6 * np.abs(L1).max()
        ax = int(rng.integers(-1, 3))
        a = attitude_split_one(q1, q2, ax, L1, L2)
        b = attitude_split_one(q1.tolist(), q2.tolist(), ax, L1.tolist(), L2.tolist())
        c = attitude_split_one(list(q1), tuple(q2), ax, list(L1), tuple(L2))  # (NumPy scalars: float() of each)
        assert _bits(a) == _bits(b) == _bits(c)
        d, p = attitude_split(q1, q2, ax, L1, L2)
        assert a[0] == pytest.approx(float(d), rel=1e-6, abs=1e-12)
        assert a[1] == pytest.approx(float(p), rel=1e-6, abs=1e-12)


def test_denominators_in_one_pass():
    """ErrorControl._denoms = (denom, denom_estimate) as each was summed alone (_ref_denom), bit for bit, over random
    stretches."""
    rng = np.random.default_rng(2)
    methods = list(ORDER)
    for _ in range(500):
        ctl = ErrorControl.__new__(ErrorControl)
        ctl.weights, ctl.shadow_steps, ctl.shadow_len, ctl.finer, ctl.coarse = {}, {}, {}, {}, {}
        for m in rng.choice(methods, size=int(rng.integers(0, 4)), replace=False).tolist():
            k = int(rng.integers(0, 5000))
            ctl.weights[m] = k
            ctl.shadow_steps[m] = int(rng.integers(0, k + 2))
            ctl.shadow_len[m] = ctl.shadow_steps[m] + float(rng.uniform(0.0, k / 2 + 1))
            if m in COARSE_ORDER and rng.integers(0, 2):
                ctl.coarse[m] = int(rng.integers(0, k + 1))
        for _ in range(int(rng.integers(0, 3))):
            ctl.finer[(str(rng.choice(methods)), float(rng.uniform(4.0, 40.0)))] = float(rng.uniform(0.0, 100.0))
        a, b = ctl._denoms()
        assert _bits(a) == _bits(_ref_denom(ctl, False)) and _bits(b) == _bits(_ref_denom(ctl, True))
        assert _bits(a) == _bits(ctl.denom) and _bits(b) == _bits(ctl.denom_estimate)


def test_measure_as_diff_and_now(sim):
    """ErrorControl.measure written out = its parts as they were (_ref_diff, then _ref_now at each denominator), bit
    for bit."""
    sh = sim.follower()
    sh.y = sim.y.copy()
    rng = np.random.default_rng(3)
    ctl = ErrorControl(sim.step_plan, True, 1.0, adapt=False, axis=2)
    ctl.note_method("lawson8", 400, 110)
    ctl.note_method("etdrk4", 300, 150, finer=0.5)
    for _ in range(300):
        sh.y[0:7] = sim.y[0:7] + rng.standard_normal(7) * 10 ** rng.uniform(-14, -4)
        ref = copy.deepcopy(ctl)
        got = ctl.measure(sim, sh)
        # the parts, as measure took them before issue 28
        ref.L_max = max(ref.L_max, float(np.linalg.norm(sim.y[0:3])))
        raw = _ref_diff(ref, sim, sh)
        (dL, dq, dp), dLn = _ref_now(raw, _ref_denom(ref, False))
        ref.dL = max(ref.dL, ref.banked[0] + dL)
        ref.e_q = max(ref.e_q, ref.banked[1] + dq)
        ref.e_p = max(ref.e_p, ref.banked[2] + dp)
        now, _ = _ref_now(raw, _ref_denom(ref, True))
        ref.est = tuple(max(e, b + n) for e, b, n in zip(ref.est, ref.banked_est, now, strict=True))
        assert _bits(got) == _bits((dL, dq, dp, ref.e_L, ref.e_q, ref.e_p))
        assert _bits(ctl.est) == _bits(ref.est) and _bits(ctl.dLn) == _bits(dLn)
        assert math.isfinite(got[0])


def test_cross_rows_as_numpy():
    """cross_rows (the stators' e1 × e2 a control law is handed, in scalar code) = np.cross, bit for bit."""
    rng = np.random.default_rng(4)
    for k in (0, 1, 3, 7):
        for _ in range(200):
            a = rng.standard_normal((k, 3)) * 10 ** rng.uniform(-8, 8)
            b = rng.standard_normal((k, 3)) * 10 ** rng.uniform(-8, 8)
            got, want = cross_rows(a, b), np.cross(a, b).reshape(-1, 3)
            assert got.shape == want.shape == (k, 3) and _bits(got) == _bits(want)


def test_merge_times_as_union1d():
    """merge_times (sort and mask: sorted_union) = the np.unique / np.union1d form it replaced, bit for bit."""
    rng = np.random.default_rng(5)

    def ref(times, exact):
        if not exact.size:
            return np.unique(times)
        j = np.searchsorted(exact, times)
        lo, hi = np.clip(j - 1, 0, exact.size - 1), np.clip(j, 0, exact.size - 1)
        near = (np.minimum(np.abs(exact[lo] - times), np.abs(exact[hi] - times))
                <= 1e-9 * np.maximum(1.0, np.abs(times)))
        return np.union1d(exact, times[~near])

    for _ in range(500):
        T = float(rng.uniform(0.1, 100.0))
        times = np.sort(np.concatenate([np.arange(int(rng.integers(0, 60))) * T / 50, rng.uniform(0, T, 5)]))
        exact = np.arange(int(rng.integers(0, 40))) * float(rng.choice([T / 50, T / 37, 0.02]))
        exact = exact + rng.choice([0.0, 1e-12, 1e-6], exact.size) * (rng.random(exact.size) < 0.3)
        exact = np.unique(exact)
        got, want = merge_times(times, exact), ref(times, exact)
        assert got.shape == want.shape and _bits(got) == _bits(want)
