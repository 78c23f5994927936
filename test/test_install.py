"""Installing gyro_sim (issue 31): a wheel is built out of tree (the checkout is left as it was) and carries the
built-in scenes' compiled numba kernels, so the first run after ``pip install`` compiles nothing; the same after
``colcon build`` (test_packaging.test_colcon_first_run_compiles_nothing). The whole of each pip path, in a fresh
venv with its dependencies from the index, is the slow test at the end (``--stress``).

Builds here compile the default scene's kernels alone (``GYRO_SIM_PRECOMPILE=spinup_thin_shell``: the mechanism
is the same for every scene, and the suite stays short); a plain build compiles every built-in scene's.
"""
import json
import os
import subprocess
import sys
import venv
import zipfile
from pathlib import Path

import pytest

from test_packaging import COPY_IGNORE, ROOT

import shutil

#: the first run of the scene, in a new process: compile seconds (numba's compile events, cache loads excluded)
FIRST_RUN = ("import json, gyro_sim\n"
             "from gyro_sim.compiled.compile_watch import compile_seconds\n"
             "from gyro_sim.scenes.scene import load_scene\n"
             "from gyro_sim.engine.simulate import run\n"
             "compile_seconds()\n"
             "r = run(load_scene('spinup_thin_shell'), duration=0.5)\n"
             "print(json.dumps({'compile_s': compile_seconds(), 'file': gyro_sim.__file__, 'steps': int(r.steps)}))\n")


def tree_files(root: Path) -> set:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


def build_env(**extra) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    return dict(env, GYRO_SIM_PRECOMPILE="spinup_thin_shell", PIP_DISABLE_PIP_VERSION_CHECK="1", **extra)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    """A checkout (a copy of the repo's files), its file list before, and the wheel `pip wheel` built from it."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "checkout"
    shutil.copytree(ROOT, src, ignore=COPY_IGNORE, symlinks=True)
    before = tree_files(src)
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp / "dist"), str(src)],
                       capture_output=True, text=True, env=build_env(), timeout=900)
    assert r.returncode == 0, r.stdout + r.stderr
    (whl,) = (tmp / "dist").glob("gyro_sim-*.whl")
    return src, before, whl


def test_a_wheel_build_leaves_the_checkout_as_it_was(wheel):
    src, before, _ = wheel
    after = tree_files(src)
    assert after == before, f"new: {sorted(after - before)[:10]}, gone: {sorted(before - after)[:10]}"


def test_the_wheel_carries_the_compiled_kernels_and_the_ros_files(wheel):
    names = zipfile.ZipFile(wheel[2]).namelist()
    nbi = [n for n in names if n.endswith(".nbi")]
    print(f"\n  {wheel[2].name}: {len(nbi)} numba cache indexes, {sum(n.endswith('.nbc') for n in names)} kernels")
    assert any(n.startswith("gyro_sim/compiled/__pycache__/frozen_flow.integrate_frozen") for n in nbi), nbi
    assert any(n.startswith("gyro_ctl/__pycache__/law_kernels.") for n in nbi), nbi
    assert not any("/test/" in n or n.startswith("build_support/") for n in names)
    assert any(n.endswith("share/ament_index/resource_index/packages/gyro_sim") for n in names)
    assert not any(n.endswith("entry_points.txt") and b"pytest11" in zipfile.ZipFile(wheel[2]).read(n)
                   for n in names)


def test_the_first_run_after_pip_install_compiles_nothing(wheel, tmp_path):
    """The wheel installed (pip, into a folder of its own put first on the path of this venv's Python, which has
    the dependencies): the first run of the scene loads every kernel from the wheel's cache."""
    target = tmp_path / "site"
    r = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target),
                        str(wheel[2])], capture_output=True, text=True, env=build_env(), timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    r = subprocess.run([sys.executable, "-c", FIRST_RUN], capture_output=True, text=True, timeout=300,
                       env=build_env(PYTHONPATH=str(target)), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.splitlines()[-1])
    print(f"\n  first run after pip install: {out['compile_s']:.2f} s compiling, {out['steps']} steps")
    assert Path(out["file"]).is_relative_to(target)
    assert out["compile_s"] == 0.0 and out["steps"] > 0


def test_a_failed_kernel_compile_does_not_fail_the_build(tmp_path, monkeypatch):
    """A build where the kernels cannot compile (here: the Python outside the venv, without numba) says so and goes
    on: the kernels then compile on first use."""
    sys.path.insert(0, str(ROOT / "build_support"))
    try:
        import precompile_kernels
    finally:
        sys.path.pop(0)
    bare = sys._base_executable
    if subprocess.run([bare, "-c", "import numba"], capture_output=True).returncode == 0:
        pytest.skip(f"{bare} has numba")
    monkeypatch.setattr(precompile_kernels.sys, "executable", bare)
    said = []
    assert not precompile_kernels.precompile(str(ROOT), say=said.append)
    assert "they compile on first use" in said[-1], said


@pytest.mark.slow
@pytest.mark.parametrize("extra", ["", "[ros]"])
def test_pip_install_into_a_fresh_venv_then_run(tmp_path, extra):
    """`pip install .` / `pip install '.[ros]'` into a new venv (dependencies from the index), then the default
    scene's first run (with --ros for the ros extra) compiles nothing."""
    src = tmp_path / "checkout"
    shutil.copytree(ROOT, src, ignore=COPY_IGNORE, symlinks=True)
    venv.create(tmp_path / "venv", with_pip=True)
    py = tmp_path / "venv/bin/python"
    r = subprocess.run([py, "-m", "pip", "install", "-q", f"{src}{extra}"], capture_output=True, text=True,
                       env=build_env(), timeout=1800)
    assert r.returncode == 0, r.stdout + r.stderr
    argv = [tmp_path / "venv/bin/gyro-sim", "run", "spinup_thin_shell", "--duration", "1", "--out", tmp_path]
    r = subprocess.run(argv + (["--ros"] if extra else []), capture_output=True, text=True, env=build_env(),
                       timeout=600, cwd=tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "compiling" not in r.stdout + r.stderr, r.stdout + r.stderr


def lower_bounds() -> list:
    """``name==version`` of each dependency's lower bound (pyproject.toml)."""
    from packaging.requirements import Requirement

    from test_packaging import pyproject

    out = []
    for r in map(Requirement, pyproject()["project"]["dependencies"]):
        low = [s.version for s in r.specifier if s.operator == ">="]
        assert low, f"{r}: no lower bound"
        out.append(f"{r.name}=={low[0]}")
    return out


def test_the_kernel_build_asks_for_the_package_s_own_bounds():
    sys.path.insert(0, str(ROOT / "build_support"))
    try:
        import out_of_tree
    finally:
        sys.path.pop(0)
    from test_packaging import pyproject

    deps = set(pyproject()["project"]["dependencies"])
    assert set(out_of_tree.KERNEL_REQUIRES) <= deps, set(out_of_tree.KERNEL_REQUIRES) - deps


@pytest.mark.slow
def test_lower_bounds(tmp_path):
    """The dependencies at their lower bounds (pyproject.toml), together in a fresh venv: the physics, recording and
    results tests pass with them (this source tree on PYTHONPATH)."""
    venv.create(tmp_path / "venv", with_pip=True)
    py = tmp_path / "venv/bin/python"
    r = subprocess.run([py, "-m", "pip", "install", "-q", *lower_bounds(), "pytest", "hypothesis", "mpmath",
                        "mcap-ros2-support"], capture_output=True, text=True, env=build_env(), timeout=1800)
    assert r.returncode == 0, r.stdout + r.stderr
    tests = [str(ROOT / "test" / t) for t in ("test_closed_forms.py", "test_frozen_flow.py", "test_recording.py",
                                               "test_results.py", "test_scene.py")]
    r = subprocess.run([py, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-k", "not ros", *tests],
                       capture_output=True, text=True, timeout=1800, cwd=tmp_path,
                       env=build_env(PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(tmp_path / "numba")))
    print("\n  " + r.stdout.strip().splitlines()[-1])
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
