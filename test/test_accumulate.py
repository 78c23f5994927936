"""The error estimate's sums over the output samples (ErrorEstimator.accumulate) and the samples' check
(Runner._check_samples) take many samples a call on arrays: the same bits as sample by sample, however the samples
come in chunks (a run whose samples are breaks, as the ROS node's, gets the same estimate)."""
from __future__ import annotations

import numpy as np
import pytest

import gyro_sim
from gyro_sim.engine import shadow
from gyro_sim.engine.runner import Runner


@pytest.mark.parametrize("name", ["spinup_thin_shell", "spinup_solid_sphere"])  # (no modes' sums; the modes' sums)
def test_one_chunk_on_arrays_equals_sample_by_sample(name):
    scene = gyro_sim.load_scene(name, overrides={"duration": 0.2})
    rng = np.random.default_rng(7)
    n = 200
    t = np.sort(rng.uniform(0.0, 0.2, n))
    L_rows = rng.normal(size=(n, 3)) * 0.3
    Ln = np.sqrt(L_rows[:, 0] ** 2 + L_rows[:, 1] ** 2 + L_rows[:, 2] ** 2)
    N_rows = rng.normal(size=(n, 3)) * 1e-3
    a, b = Runner(scene, None).estimator, Runner(scene, None).estimator
    assert n > shadow.VECTOR_SAMPLES
    a.accumulate(t, Ln, N_rows, L_rows)  # (on arrays)
    for k in range(n):  # (one sample a call: the scalar code)
        b.accumulate(t[k:k + 1], Ln[k:k + 1].tolist(), N_rows[k:k + 1], L_rows[k:k + 1])
    got = [(e._turned, e._impulse, e._spin_dev, e._last_t, e.control.L_max) for e in (a, b)]
    print(f"\n  {name}: turned, impulse, spin deviation, last t, largest |L|: {got[0]}")
    assert got[0] == got[1] and got[0][0] > 0
    assert np.array_equal(a._L_seen, b._L_seen)
    if name == "spinup_solid_sphere":
        assert got[0][1] > 0 and got[0][2] > 0


def test_running_sum_adds_in_order():
    terms = np.array([1e16, 1.0, -1e16, 1.0])
    want = 0.0
    for v in terms.tolist():
        want += v
    assert shadow._running_sum(0.0, terms) == want == 1.0  # (the order matters: 1e16 + 1.0 rounds to 1e16)
