"""Fault injection (gyro_sim.engine.faults): reproducible from a seed, statistics as asked, nothing when off."""
import math

import numpy as np
import pytest

from gyro_sim.engine.faults import FaultConfig, Faults

CMD = (["z1", "z2", "z3"], [0.3, 0.0, 0.5], None, 0)


def run_commands(cfg, n=20000):
    f = Faults(cfg)
    return f, [f.command((CMD[0], CMD[1], CMD[2], k)) for k in range(n)]


def test_off_by_default_changes_nothing():
    cfg = FaultConfig()
    assert not cfg.active
    f, out = run_commands(cfg, 100)
    assert [c[3] for c in out] == list(range(100)) and all(c[1] == CMD[1] for c in out)
    L, q, w = f.state(np.array([1.0, 2, 3]), np.array([1.0, 0, 0, 0]), np.array([4.0, 5, 6]), 0)
    assert np.array_equal(L, [1, 2, 3]) and np.array_equal(q, [1, 0, 0, 0]) and np.array_equal(w, [4, 5, 6])


def test_same_seed_same_faults_and_another_seed_others():
    cfg = FaultConfig(seed=7, command_drop=0.2, command_corrupt=0.1, command_delay=2, noise_omega=0.5)
    a = run_commands(cfg, 500)[1]
    b = run_commands(cfg, 500)[1]
    c = run_commands(FaultConfig(seed=8, command_drop=0.2, command_corrupt=0.1, command_delay=2), 500)[1]
    assert a == b and a != c


def test_drop_and_corrupt_fractions_within_binomial_bounds():
    n, p_drop, p_cor = 20000, 0.25, 0.1
    f, out = run_commands(FaultConfig(seed=1, command_drop=p_drop, command_corrupt=p_cor), n)
    dropped = sum(c is None for c in out)
    corrupted = sum(c is not None and c[1] != CMD[1] for c in out)
    sd_d = math.sqrt(n * p_drop * (1 - p_drop))
    kept = n - dropped
    sd_c = math.sqrt(kept * p_cor * (1 - p_cor))
    print(f"\n  dropped {dropped} of {n} (expected {n * p_drop:.0f} ± {sd_d:.0f}); corrupted {corrupted} of {kept} "
          f"kept (expected {kept * p_cor:.0f} ± {sd_c:.0f}); bound 5σ")
    assert abs(dropped - n * p_drop) < 5 * sd_d and abs(corrupted - kept * p_cor) < 5 * sd_c
    scaled = np.array([c[1][0] / CMD[1][0] for c in out if c is not None and c[1] != CMD[1]])
    assert scaled.min() >= 0 and scaled.max() < 2 and abs(scaled.mean() - 1) < 5 * (2 / math.sqrt(12)) / math.sqrt(len(scaled))


def test_delay_shifts_by_whole_ticks_and_quantum_rounds():
    f, out = run_commands(FaultConfig(command_delay=3), 10)
    assert out[:3] == [None] * 3 and [c[3] for c in out[3:]] == list(range(7))
    f, out = run_commands(FaultConfig(current_quantum=0.2), 3)
    assert out[0][1] == [0.2, 0.0, 0.4] or np.allclose(out[0][1], [0.2, 0.0, 0.4])
    assert np.allclose(np.array(out[0][1]) / 0.2, np.round(np.array(out[0][1]) / 0.2))


def test_sensor_noise_and_bias_statistics():
    cfg = FaultConfig(seed=3, noise_omega=0.05, noise_L=1e-4, noise_attitude=0.01, bias_omega=(0.0, 0.0, 0.2))
    f = Faults(cfg)
    n = 4000
    L0, q0, w0 = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.0, 0.0, 100.0])
    s = [f.state(L0, q0, w0, k * 1_000_000) for k in range(n)]
    again = f.state(L0, q0, w0, 5 * 1_000_000)  # a state published again: the same noise
    assert all(np.array_equal(a, b) for a, b in zip(again, s[5]))
    dw = np.array([x[2] for x in s]) - w0
    dL = np.array([x[0] for x in s]) - L0
    ang = np.array([2 * math.acos(min(1.0, abs(x[1][0]))) for x in s])
    # chi-square bounds: the sample std of n normals is within σ(1 ± 5/sqrt(2n))
    tol = 5 / math.sqrt(2 * n)
    print(f"\n  Ω noise std {dw[:, :2].std():.4f} (0.05), bias {dw[:, 2].mean():.4f} (0.2), L std {dL.std():.2e} "
          f"(1e-4), attitude error rms {math.sqrt((ang ** 2).mean() / 3):.4f} rad per axis (0.01)")
    assert abs(dw[:, :2].std() / 0.05 - 1) < tol and abs(dL.std() / 1e-4 - 1) < tol
    assert abs(dw[:, 2].mean() - 0.2) < 5 * 0.05 / math.sqrt(n)
    assert abs(math.sqrt((ang ** 2).mean() / 3) / 0.01 - 1) < 2 * tol
    assert np.allclose([np.linalg.norm(x[1]) for x in s], 1.0, atol=1e-15)
    cov_q, cov_w = f.covariances()
    assert cov_q[0] == cov_q[4] == cov_q[8] == 1e-4 and cov_w[0] == pytest.approx(0.0025)


@pytest.mark.parametrize("bad", [dict(command_drop=1.5), dict(command_delay=-1), dict(command_delay=1.5),
                                 dict(noise_omega=-1.0), dict(bias_omega=(0.0, 1.0))])
def test_bad_settings_are_refused_with_the_name(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        FaultConfig(**bad)
