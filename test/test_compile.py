"""Compilation of the numba kernels: only what a scene uses, once, cached wherever the cache lives, announced.

No timing is asserted (the machine is shared): what is checked is which kernels compile, how many times, and
what the user is told.
"""
import json
import os
import re
import subprocess
import sys



SIGNATURES = """
import inspect, json, gyro_sim
from gyro_sim.compiled import frozen_flow
from gyro_sim.compiled import kernels
gyro_sim.run(gyro_sim.load_scene("spinup_thin_shell"), duration=0.2)
gyro_sim.run(gyro_sim.load_scene("spinup_thin_shell"), duration=0.2, attitude=True)
case = lambda f: list(inspect.signature(f.py_func).parameters).index("case")  # (the steppers' pos, max_steps follow)
print(json.dumps({f.__name__: [str(s[case(f)]) for s in f.signatures]
                  for f in (kernels.record_sample, frozen_flow.integrate_frozen)}))
"""


def test_default_scene_compiles_each_kernel_once_and_no_case_frame_code():
    """The default scene (frozen-flow steps with the attitude) uses one signature of each kernel (the sample at
    t = 0 and the stepper's samples share record_sample), and the case-frame step of attitude-free runs is
    pruned (case = None), not compiled: before, record_sample compiled twice and frozen_flow_step_case compiled
    unused. In a process of its own: the suite's other tests compile other signatures."""
    out = subprocess.run([sys.executable, "-c", SIGNATURES], capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr
    sigs = json.loads(out.stdout.splitlines()[-1])
    print(f"\n  the case argument of each signature compiled: {sigs}")
    assert sigs == {"record_sample": ["none"], "integrate_frozen": ["none"]}


def _run_cli(args, cache_dir):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir))
    return subprocess.run([sys.executable, "-m", "gyro_sim.apps.cli", *args], env=env, capture_output=True, text=True,
                          timeout=900)


def test_first_run_announces_its_compile_and_a_second_process_loads_the_cache(tmp_path):
    """With an empty cache (here numba's NUMBA_CACHE_DIR, as for a read-only install) the first run prints one
    line saying it compiles, and its summary gives the compile time apart from the run's wall time (the real-time
    factor leaves it out); a second process finds the cache and compiles nothing."""
    cache = tmp_path / "numba_cache"
    args = ["run", "spinup_thin_shell", "--duration", "1", "--out", str(tmp_path), "--quiet"]
    first = _run_cli(args, cache)
    assert first.returncode == 0, first.stderr
    notices = [line for line in first.stderr.splitlines() if "compiling the numba kernels" in line]
    m = re.search(r"wall time\s+([\d.]+) s  \(\+ ([\d.]+) s compiling", first.stdout)
    assert len(notices) == 1 and m, (first.stdout, first.stderr)
    second = _run_cli(args, cache)
    assert second.returncode == 0, second.stderr
    print(f"\n  first run: {m.group(0)}; second process: "
          f"{[x for x in second.stdout.splitlines() if x.startswith('wall time')]}")
    assert "compiling" not in second.stderr and "compiling" not in second.stdout
    assert any(p.suffix == ".nbc" for p in cache.rglob("*"))


READ_ONLY = """
import sys
import numba.core.caching as caching


def read_only(self):
    raise PermissionError("the package directory is read-only (a system or colcon install)")


caching.InTreeCacheLocator.ensure_cache_path = read_only  # as root every directory is writable: simulate it
from gyro_sim.apps.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_read_only_install_falls_back_to_the_user_cache_and_warmup_compiles_once(tmp_path):
    """Where the package's own directory cannot take the cache (a read-only site-packages or colcon install),
    numba uses the user's cache (~/.cache/numba): `gyro-sim warmup` compiles there and says so, the next warmup
    reports a warm cache, a run then compiles nothing, never a compile every launch; an unknown scene is one
    error line. (Simulated: this suite runs as root, for whom no directory is read-only. One cold compile serves
    the warmup and the read-only checks: each costs 20-40 s on a loaded machine.)"""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(HOME=str(tmp_path), XDG_CACHE_HOME=str(tmp_path / "xdg"))

    def cli(*args):
        return subprocess.run([sys.executable, "-c", READ_ONLY, *args], env=env, capture_output=True, text=True,
                              timeout=900)

    first = cli("warmup", "free_rotor")
    assert first.returncode == 0 and "warmup: free_rotor: compiled in" in first.stdout, first.stdout + first.stderr
    second = cli("warmup", "free_rotor")
    assert second.returncode == 0 and "already compiled" in second.stdout, second.stdout + second.stderr
    run = cli("run", "free_rotor", "--duration", "0.2", "--out", str(tmp_path), "--quiet")
    assert run.returncode == 0, run.stderr
    assert "compiling" not in run.stderr and "compiling" not in run.stdout, run.stderr
    cached = [p for p in tmp_path.rglob("*.nbi")]
    print(f"\n  read-only install: {len(cached)} kernel index files in {sorted({str(p.parent) for p in cached})[:1]}")
    assert cached and all(str(tmp_path / "xdg") in str(p) or str(tmp_path) in str(p) for p in cached)
    bad = cli("warmup", "no_such_scene")
    assert bad.returncode == 2 and bad.stderr.startswith("error:") and len(bad.stderr.splitlines()) == 1


NO_NEW_KERNEL = """
import sys, numba, gyro_sim
from gyro_sim.engine.warmup import currents_off, warm
from gyro_sim.scenes.scene import load_scene

def loaded():
    # every numba kernel of gyro_sim's modules with the signatures this process has compiled or loaded
    return {(m, k): len(v.overloads) for m, mod in list(sys.modules.items()) if m.startswith("gyro_sim")
            for k, v in vars(mod).items() if isinstance(v, numba.core.registry.CPUDispatcher)}

warm(["nutation_oblate"], say=lambda text: None)
before = loaded()
currents_off(load_scene("nutation_oblate"), 0.3)  # (what the node does at t = 0.3 s of a run: not only 0.05)
after = loaded()
print(sorted(k[1] for k in after if after[k] > before.get(k, 0)))
"""


def test_warmup_covers_the_currents_off_path():
    """After ``gyro-sim warmup`` a lost controller's zeroing (or the watchdog's) loads no new kernel mid-run: the
    torque-free integrator it switches to is among what warmup runs (before: integrate_free compiled mid-run, 42 to
    58 s under load, issue 30). In a process of its own (the suite's other tests load other kernels)."""
    out = subprocess.run([sys.executable, "-c", NO_NEW_KERNEL], capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr
    new = json.loads(out.stdout.splitlines()[-1].replace("'", '"'))
    print(f"\n  kernels first loaded by the zeroed run after warmup: {new}")
    assert new == []
