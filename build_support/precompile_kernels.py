"""Compile the numba kernels into a built tree, at build time (setup.py's build_py and develop steps).

numba caches a compiled kernel next to its module (``__pycache__/*.nbi|nbc``), keyed by the module's content
(numba >= 0.60: a hash, not the file's time), the kernel's signature, the Python and numba versions and the CPU.
Compiling the built-in scenes' kernels in the tree that is installed (the wheel's, colcon's) therefore ships
them: the first run after ``pip install .`` or ``colcon build`` loads them from that cache instead of compiling
(about 12 s of CPU for the default scene, minutes for every scene on a busy machine). A machine with another
CPU or numba version compiles on first use, as without this step.

``GYRO_SIM_PRECOMPILE``: unset or ``all``, every built-in scene; ``0`` / ``none``, nothing (a quick build; the
kernels then compile on first use, or with ``gyro-sim warmup``); else a comma-separated list of scene names.
A failed compile never fails the build: it says why and the kernels compile on first use.
"""
import os
import subprocess
import sys
import time

__all__ = ["precompile", "scenes_asked"]

#: run with the built tree first on sys.path; the built-in scenes are read from the source's config/ (a build
#: folder has none: colcon's, for one)
_SCRIPT = (
    "import sys\n"
    "from pathlib import Path\n"
    "from gyro_sim.scenes import scene\n"
    "from gyro_sim.engine.warmup import warm\n"
    "scene.config_dir = lambda: Path(sys.argv[2])\n"
    "names = sys.argv[1].split(',') if sys.argv[1] else None\n"
    "warm(names, say=lambda s: print(s, flush=True))\n"
)
#: the source tree's built-in scenes
CONFIG = os.path.join(os.path.dirname(os.path.dirname(os.path.realpath(__file__))), "config")


def scenes_asked(env=os.environ):
    """The scenes ``GYRO_SIM_PRECOMPILE`` asks for: None (none), '' (every built-in scene) or 'a,b'."""
    v = env.get("GYRO_SIM_PRECOMPILE", "all").strip()
    if v.lower() in ("0", "none", "no", "false", "off"):
        return None
    return "" if v.lower() in ("", "1", "all", "yes", "true", "on") else v


def _say(line):
    print(line, file=sys.stderr, flush=True)


def precompile(root, say=_say):
    """Run the built-in scenes' kernels once with ``root`` first on sys.path, so numba writes their cache into
    ``root``'s packages. Returns True where it ran to the end."""
    names = scenes_asked()
    if names is None:
        say("gyro_sim: GYRO_SIM_PRECOMPILE=0: the numba kernels are not compiled at build time")
        return False
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "NUMBA_DISABLE_JIT")}
    env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in [os.environ.get("PYTHONPATH")] if p])
    say(f"gyro_sim: compiling the numba kernels of the built-in scenes into {root} (about a minute on 2 cores)")
    t0 = time.perf_counter()
    try:
        r = subprocess.run([sys.executable, "-c", _SCRIPT, names, CONFIG], env=env, cwd=root,
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    except OSError as e:
        say(f"gyro_sim: warning: the kernels were not compiled at build time ({e}); they compile on first use")
        return False
    for line in r.stdout.splitlines():
        say(f"  {line}")
    if r.returncode != 0:
        say("gyro_sim: warning: the kernels were not compiled at build time (above); they compile on first use")
        return False
    say(f"gyro_sim: kernels compiled in {time.perf_counter() - t0:.0f} s")
    return True
