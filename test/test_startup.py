"""Start-up of a process (issue 23): what ``import gyro_sim``, ``from gyro_sim.engine.simulate import run`` and a first
run import and load. Each check runs in a new interpreter (``sys.modules`` of this one holds whatever other tests
imported); none bounds a time (the benchmark's start-up part measures those: gyro_sim/apps/bench_scaling.py)."""
import json
import subprocess
import sys

import numpy as np
import pytest

#: SciPy's subpackages a run of the default scene needs none of (0.1–0.3 s of imports each, with their own)
HEAVY = ("scipy.optimize", "scipy.integrate", "scipy.constants", "scipy.special", "scipy.interpolate")


def fresh(code: str) -> dict:
    """Run ``code`` in a new interpreter; it ends by printing one JSON line (returned)."""
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout.strip().splitlines()[-1])


MODULES = "import json, sys; print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in ('scipy', 'numba', 'matplotlib', 'pydantic', 'dask', 'distributed'))))"

LOADED = """
import gc, json, sys
from numba.core.registry import CPUDispatcher
print(json.dumps({"modules": sorted(m for m in sys.modules if m.startswith('scipy.')),
                  "kernels": sorted(f"{d.py_func.__module__}.{d.py_func.__name__}" for d in gc.get_objects()
                                    if isinstance(d, CPUDispatcher) and d.overloads)}))
"""


def test_import_gyro_sim_imports_no_numerical_stack():
    mods = fresh("import gyro_sim\n" + MODULES)
    assert not mods, mods


def test_importing_run_imports_no_scipy_subpackage():
    mods = fresh("from gyro_sim.engine.simulate import run\n" + MODULES)
    assert not [m for m in mods if m.startswith(HEAVY)], mods
    assert "numba" in mods  # (the kernels are numba's: a run needs it)


@pytest.mark.parametrize("scene, stepper, unused", [
    ("spinup_thin_shell", "frozen_flow", ("gyro_sim.compiled.kernels.integrate", "gyro_sim.compiled.kernels.integrate_free")),
    ("three_stators", "lawson8", ("gyro_sim.compiled.frozen_flow.integrate_frozen", "gyro_sim.compiled.kernels.integrate_free")),
])
def test_a_run_loads_only_what_its_scene_uses(scene, stepper, unused):
    """A run imports no SciPy subpackage it does not use (its error estimate imported gyro_sim.engine.fidelity, hence
    scipy.integrate; lawson8's table imported scipy.integrate; the conductor scipy.optimize and scipy.special) and
    loads only the compiled kernels of its stepper (numba loads a kernel's cache on its first call)."""
    got = fresh(f"from gyro_sim.scenes.scene import load_scene\nfrom gyro_sim.engine.simulate import Simulator, run\n"
                f"sc = load_scene({scene!r})\nassert Simulator(sc)._method() == {stepper!r}\n"
                f"r = run(sc, duration=0.02)\nassert r.steps > 0\n" + LOADED)
    assert not [m for m in got["modules"] if m.startswith(HEAVY)], got["modules"]
    assert not set(unused) & set(got["kernels"]), got["kernels"]


def test_mu0_is_scipys():
    from scipy.constants import mu_0

    from gyro_sim.physics.constants import MU0

    assert MU0 == mu_0  # the same float: CODATA 2022 (a SciPy with other CODATA values fails here)


def test_dop853_table_is_scipys():
    """The project's DOP853 coefficients (gyro_sim/compiled/dop853_coefficients.py) are SciPy's, bit for bit."""
    d = pytest.importorskip("scipy.integrate._ivp.dop853_coefficients",
                            reason="SciPy's private module of the DOP853 table is gone (moved or renamed)")

    from gyro_sim.compiled.kernels import dop853_tableau

    A, b, c = dop853_tableau()
    s = d.N_STAGES
    assert s == 12
    for ours, theirs in ((A, d.A[:s, :s]), (b, d.B), (c, d.C[:s])):
        assert ours.dtype == np.float64 and ours.flags.c_contiguous and ours.shape == theirs.shape
        assert ours.tobytes() == np.ascontiguousarray(theirs, dtype=np.float64).tobytes()  # the same bits


