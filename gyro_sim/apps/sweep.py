"""Parameter sweeps: every variant of a scene run as an independent task (``gyro-sim sweep``).

A sweep is a scene, the keys it varies (a grid, random draws, or both; any scene key by its
dotted path, list items by index: ``stators.0.current``, ``controller.params.nu.1``) and the
metrics kept per run. It is given on the command line or in a sweep file (``config/sweep_*.yaml``;
format in ``docs/sweeps.md``)::

    gyro-sim sweep nutation_oblate --vary controller.period=0.004:0.02:17 \\
        --metric theta_end=final(theta_deg) --metric t_settle=time_below(theta_deg,0.1)
    gyro-sim sweep sweep_psi_rate                 # a built-in sweep file
    gyro-sim sweep sweep_psi_rate --scheduler tcp://127.0.0.1:8786

Every variant is validated like a scene file before anything runs; a variant that does not
validate, a run that raises or ends in a non-finite state is recorded (``status`` ``invalid`` /
``failed`` with the reason) and the sweep goes on. Runs are independent Dask tasks on a local
cluster (all cores by default, bound to 127.0.0.1) or on an existing scheduler (``--scheduler``);
``--workers 0`` runs them in this process without Dask. Results go to a Parquet table (one row per
variant: the varied values, the metrics, optional time series, the package version) keyed by a
hash of (scene, fixed overrides, variant values, metrics); a sweep run again skips what its file
already holds, and a hard stop loses at most the runs in flight (a journal beside the file).

A task runs several variants one after the other in the worker, so the per-task costs (scheduling
round trip, (de)serialisation, result hand-back) are paid once per task: by default (``--batch auto``)
each task is sized as it is sent to last about 0.25 s at the run time seen so far
(:mod:`gyro_sim.sweep_tasks`); ``--batch N`` gives every task N variants. It does not vectorise the
integrator: each run is the same compiled code as ``gyro_sim.run``. ``--measure`` reports runs/s
in-process, with one worker and all cores (one run per task, N per task, auto), the overhead per task
and the cost of a run inside a worker against in-process.

The core (specs, variants, metrics, serial execution, the Parquet writer aside) needs no Dask:
``dask.distributed``, ``pyarrow`` and ``tqdm`` (the ``sweep`` extra) are imported only where used.
"""
from __future__ import annotations

import argparse
import copy
import hashlib
import itertools
import json
import logging
import math
import os
import re
import socket
import sys
import time
import warnings
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

import numpy as np

from gyro_sim import __version__
from gyro_sim.scenes.scene import SceneError, apply_overrides, builtin_scenes, config_dir, scene_from_dict
from gyro_sim.scenes.scene_text import parse_scene_text, read_scene_file

__all__ = [
    "SweepError", "Axis", "RandomVar", "Metric", "Variant", "SweepSpec", "SweepResult",
    "parse_axis", "parse_random", "parse_metric", "load_sweep", "spec_from_dict", "builtin_sweeps",
    "run_chunk", "run_sweep", "read_results", "write_results", "plot_sweep", "measure", "measure_lines", "sweep_main",
    "QUANTITIES", "METRIC_FUNCTIONS", "METRIC_ALIASES",
]

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130
_FIXED_COLUMNS = ("run_id", "index", "sample", "status", "error", "wall_time_run", "worker", "gyro_sim_version")
_META_KEY = b"gyro_sim.sweep"


class SweepError(ValueError):
    """A sweep that cannot be run: bad spec, axis, distribution, metric or results file."""


# ------------------------------------------------------------------------------------------
# values and axes
# ------------------------------------------------------------------------------------------
def _split_top(text: str, sep: str) -> list[str]:
    """Split at ``sep`` outside brackets/parentheses."""
    out: list[str] = []
    cur: list[str] = []
    depth = 0
    for ch in text:
        if ch in "[(":
            depth += 1
        elif ch in "])":
            depth -= 1
        if ch == sep and depth == 0:
            out.append("".join(cur))
            cur = []
        else:
            cur.append(ch)
    out.append("".join(cur))
    return out


def _parse_value(text: Any) -> Any:
    """A value from the command line or a YAML string: int, float (``1e-3`` too), bool, ``[a, b]`` list, str."""
    if not isinstance(text, str):
        return text
    s = text.strip()
    if s.startswith("[") and s.endswith("]"):
        inner = s[1:-1].strip()
        return [] if not inner else [_parse_value(x) for x in _split_top(inner, ",")]
    for conv in (int, float):
        try:
            return conv(s)
        except ValueError:
            pass
    if s.lower() in ("true", "false"):
        return s.lower() == "true"
    if s.lower() in ("null", "none", "~"):
        return None
    return s


def _is_number(v) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def _plain(v):
    """JSON-able plain Python value (numpy scalars/arrays → float/int/list)."""
    if isinstance(v, np.ndarray):
        return _plain(v.tolist())
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.floating):
        return float(v)
    return v


@dataclass(frozen=True)
class Axis:
    """A grid axis: the dotted scene key and its values (numbers, or lists of numbers for a vector key)."""

    key: str
    values: tuple
    spec: str = ""  # how it was given (for the results' metadata)

    def __post_init__(self):
        if not self.values:
            raise SweepError(f"vary {self.key}: no values")


def _range_values(key: str, start, stop, num, spacing: str = "linear") -> list:
    start, stop = _parse_value(start), _parse_value(stop)
    try:
        num = int(_parse_value(num))
    except (TypeError, ValueError):
        raise SweepError(f"vary {key}: N = {num!r} must be a whole number ≥ 1") from None
    if num < 1:
        raise SweepError(f"vary {key}: N = {num} must be ≥ 1")
    try:
        a, b = np.asarray(start, dtype=float), np.asarray(stop, dtype=float)
    except (TypeError, ValueError):
        raise SweepError(f"vary {key}: START = {start!r}, STOP = {stop!r} must be numbers (or lists of numbers)") from None
    if a.shape != b.shape or a.ndim > 1:
        raise SweepError(f"vary {key}: START {start!r} and STOP {stop!r} must be numbers or lists of one length")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise SweepError(f"vary {key}: START and STOP must be finite")
    if spacing == "log":
        if np.any(a * b <= 0):
            raise SweepError(f"vary {key}: log spacing needs START and STOP of one sign and non-zero, got {start}, {stop}")
        vals = np.geomspace(a, b, num) if num > 1 else a[None]
    elif spacing == "linear":
        vals = np.linspace(a, b, num) if num > 1 else a[None]
    else:
        raise SweepError(f"vary {key}: spacing {spacing!r}: allowed linear, log")
    if num > 1:
        vals[-1] = b  # exact end point
    ints = (isinstance(start, int) and isinstance(stop, int) and not isinstance(start, bool)
            and np.all(vals == np.round(vals)))
    # 15 significant digits: 0.23, not linspace's 0.22999999999999998 (in tables and run ids)
    def r15(x):
        return [r15(y) for y in x] if isinstance(x, list) else float(f"{x:.15g}")

    return [int(round(v)) if ints else r15(_plain(v)) for v in vals]


def parse_axis(key: str, spec: Any) -> Axis:
    """A grid axis from ``START:STOP:N[:log]``, ``v1,v2,...`` (command line) or a YAML value:
    a list of values, ``{start, stop, num[, spacing: linear|log]}`` or ``{values: [...]}``.
    START/STOP may be lists (``[1,2]:[3,4]:5``): the axis then interpolates a vector key."""
    key = key.strip()
    if not re.fullmatch(r"[A-Za-z_][\w]*(\.[\w]+)*", key):
        raise SweepError(f"vary {key!r}: not a dotted scene key (e.g. controller.period, stators.0.current)")
    if isinstance(spec, dict):
        extra = set(spec) - {"start", "stop", "num", "spacing", "values"}
        if extra:
            raise SweepError(f"vary {key}: unknown field(s) {sorted(extra)}; allowed: start, stop, num, spacing | values")
        if "values" in spec:
            vals = spec["values"]
            if not isinstance(vals, list):
                raise SweepError(f"vary {key}: values must be a list")
            return Axis(key, tuple(_parse_value(v) for v in vals), json.dumps(spec, default=str))
        missing = [f for f in ("start", "stop", "num") if f not in spec]
        if missing:
            raise SweepError(f"vary {key}: missing {', '.join(missing)} (give start, stop, num or values)")
        vals = _range_values(key, spec["start"], spec["stop"], spec["num"], spec.get("spacing", "linear"))
        return Axis(key, tuple(vals), json.dumps(spec, default=str))
    if isinstance(spec, list):
        return Axis(key, tuple(_parse_value(v) for v in spec), json.dumps(spec, default=str))
    if isinstance(spec, (int, float)) and not isinstance(spec, bool):
        return Axis(key, (spec,), str(spec))
    if not isinstance(spec, str) or not spec.strip():
        raise SweepError(f"vary {key}: {spec!r} is not START:STOP:N[:log] or a list of values")
    text = spec.strip()
    parts = _split_top(text, ":")
    if len(parts) in (3, 4):
        spacing = parts[3].strip() if len(parts) == 4 else "linear"
        return Axis(key, tuple(_range_values(key, parts[0], parts[1], parts[2], spacing)), text)
    if len(parts) != 1:
        raise SweepError(f"vary {key}={text}: expected START:STOP:N[:log] or v1,v2,...")
    return Axis(key, tuple(_parse_value(v) for v in _split_top(text, ",")), text)


def _split_assignment(text: str, what: str) -> tuple[str, str]:
    if "=" not in text:
        raise SweepError(f"{what} {text!r}: expected KEY=VALUE")
    k, v = text.split("=", 1)
    return k.strip(), v.strip()


# ------------------------------------------------------------------------------------------
# random variables
# ------------------------------------------------------------------------------------------
_DISTS = {"uniform": 2, "normal": 2, "loguniform": 2, "choice": None, "randint": 2}


@dataclass(frozen=True)
class RandomVar:
    """A randomly drawn scene key: ``uniform(a,b)``, ``normal(mu,sigma)``, ``loguniform(a,b)``,
    ``randint(a,b)`` (a ≤ n ≤ b) or ``choice(v1,v2,...)``."""

    key: str
    dist: str
    args: tuple
    spec: str = ""

    def draw(self, seed: int, sample: int):
        """The value for Monte Carlo sample ``sample``: a stream of its own per (seed, sample, key), so
        adding a key or a sample never changes the other draws."""
        rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, int(sample), zlib.crc32(self.key.encode())])
        a = self.args
        if self.dist == "uniform":
            return float(rng.uniform(a[0], a[1]))
        if self.dist == "normal":
            return float(rng.normal(a[0], a[1]))
        if self.dist == "loguniform":
            return float(math.exp(rng.uniform(math.log(a[0]), math.log(a[1]))))
        if self.dist == "randint":
            return int(rng.integers(int(a[0]), int(a[1]) + 1))
        return _plain(a[int(rng.integers(len(a)))])


def parse_random(key: str, spec: Any) -> RandomVar:
    key = key.strip()
    if not re.fullmatch(r"[A-Za-z_][\w]*(\.[\w]+)*", key):
        raise SweepError(f"random {key!r}: not a dotted scene key")
    text = str(spec).strip()
    m = re.fullmatch(r"(\w+)\s*\((.*)\)", text)
    if not m or m.group(1) not in _DISTS:
        raise SweepError(f"random {key}={text}: expected one of uniform(a,b), normal(mu,sigma), loguniform(a,b), "
                         f"randint(a,b), choice(v1,v2,...)")
    dist = m.group(1)
    args = tuple(_parse_value(x) for x in _split_top(m.group(2), ",")) if m.group(2).strip() else ()
    n = _DISTS[dist]
    if n is not None:
        if len(args) != n or not all(_is_number(x) and math.isfinite(x) for x in args):
            raise SweepError(f"random {key}={text}: {dist} takes {n} finite numbers")
        lo, hi = args
        if dist in ("uniform", "loguniform", "randint") and not lo < hi:
            raise SweepError(f"random {key}={text}: needs a < b")
        if dist == "loguniform" and lo <= 0:
            raise SweepError(f"random {key}={text}: loguniform needs 0 < a < b")
        if dist == "normal" and hi <= 0:
            raise SweepError(f"random {key}={text}: normal needs sigma > 0")
    elif not args:
        raise SweepError(f"random {key}={text}: choice needs at least one value")
    return RandomVar(key, dist, args, text)


# ------------------------------------------------------------------------------------------
# metrics
# ------------------------------------------------------------------------------------------
def _q_current(res, name):
    if name not in res.stator_names:
        raise ValueError(f"no stator {name!r}; stators: {res.stator_names}")
    return res.current[:, res.stator_names.index(name)]


#: time-series quantities of a run (SI; *_deg in degrees), by name
QUANTITIES: dict[str, Callable] = {
    "t": lambda r: r.t,
    "spin": lambda r: r.spin_rate,  # rad/s, body axis 3 (|Ω| in a run without attitude: RunResult.spin_rate)
    "spin_rev_s": lambda r: r.spin_rate / (2 * math.pi),
    "omega_norm": lambda r: np.linalg.norm(r.omega_b, axis=1),
    "theta": lambda r: r.euler[:, 1],
    "theta_deg": lambda r: np.degrees(r.euler[:, 1]),
    "psi": lambda r: r.euler[:, 0],
    "phi": lambda r: r.euler[:, 2],
    "L_norm": lambda r: np.linalg.norm(r.L, axis=1),
    "L_x": lambda r: r.L[:, 0],
    "L_y": lambda r: r.L[:, 1],
    "L_z": lambda r: r.L[:, 2],
    "energy": lambda r: r.energy,
    "torque_norm": lambda r: np.linalg.norm(r.torque, axis=1),
}


def _quantity(res, name: str) -> np.ndarray:
    if name in QUANTITIES:
        return np.asarray(QUANTITIES[name](res), dtype=float)
    if name.startswith("current_"):
        return np.asarray(_q_current(res, name[len("current_"):]), dtype=float)
    raise ValueError(f"unknown quantity {name!r}; allowed: {', '.join(QUANTITIES)}, current_<stator>")


def _first_time(t, mask) -> float:
    i = int(np.argmax(mask)) if mask.size else 0
    return float(t[i]) if mask.size and mask[i] else math.inf


def _settle_below(t, y, x) -> float:
    above = np.nonzero(~(y < x))[0]
    if above.size == 0:
        return float(t[0])
    if above[-1] == y.size - 1:
        return math.inf
    return float(t[above[-1] + 1])


def _drift(y) -> float:
    y0 = y[0]
    d = float(np.max(np.abs(y - y0)))
    return d / abs(y0) if y0 != 0 else d


def _mean(t, y) -> float:
    if t[-1] > t[0]:
        integrate = np.trapezoid if hasattr(np, "trapezoid") else np.trapz
        return float(integrate(y, t) / (t[-1] - t[0]))
    return float(y[0])


#: metric functions: name → (number of quantity args, number of numeric args, f(res, scene, qs, xs))
METRIC_FUNCTIONS: dict[str, tuple] = {
    "final": (1, 0, lambda r, s, q, x: float(q[0][-1])),
    "initial": (1, 0, lambda r, s, q, x: float(q[0][0])),
    "max": (1, 0, lambda r, s, q, x: float(np.max(q[0]))),
    "min": (1, 0, lambda r, s, q, x: float(np.min(q[0]))),
    "max_abs": (1, 0, lambda r, s, q, x: float(np.max(np.abs(q[0])))),
    "mean": (1, 0, lambda r, s, q, x: _mean(r.t, q[0])),
    "drift": (1, 0, lambda r, s, q, x: _drift(q[0])),  # max |y − y(0)| / |y(0)|: conservation error
    "time_below": (1, 1, lambda r, s, q, x: _first_time(r.t, q[0] < x[0])),  # s; inf if never
    "time_above": (1, 1, lambda r, s, q, x: _first_time(r.t, q[0] > x[0])),
    "settle_below": (1, 1, lambda r, s, q, x: _settle_below(r.t, q[0], x[0])),  # from then on below x
    "wall_time": (0, 0, lambda r, s, q, x: float(r.wall_time)),
    "steps": (0, 0, lambda r, s, q, x: float(r.steps)),
}

#: bare metric names
METRIC_ALIASES = {
    "final_spin": "final(spin)",
    "final_theta_deg": "final(theta_deg)",
    "max_torque": "max(torque_norm)",
    "L_drift": "drift(L_norm)",
    "energy_drift": "drift(energy)",
    "wall_time": "wall_time()",
    "steps": "steps()",
}
DEFAULT_METRICS = ("final_spin", "final_theta_deg", "max_torque", "L_drift")

#: k(NAME[, x]): quantities of the averaged ψ-switching model of [K] §3 for the variant's scene
#: (gyro_sim.averaged.PsiSwitchingK.of_scene); they need no run.
_K_ATTRS = ("p", "s", "p_star", "V", "Lam0", "W0", "kappa", "delta", "q", "equilibria", "cycles",
            "r_minus_deg", "r_plus_deg", "sampling_factor", "time_to_deg")


def _initial_L(scene) -> float:
    ini = scene.initial
    if ini.kinetic_moment is not None:
        return float(ini.kinetic_moment)
    return abs(float(ini.spin or 0.0)) * float(scene.inertia[2])


def _k_metric(scene, name: str, xs: Sequence[float]) -> float:
    from gyro_sim.averaging.averaged import PsiSwitchingK

    ctl = scene.controller
    if ctl is None or ctl.law != "psi_switching":
        raise ValueError(f"k({name}) needs a psi_switching controller in the scene")
    m = PsiSwitchingK.of_scene(scene)
    if name in ("p", "s", "V", "Lam0", "W0", "kappa", "q"):
        return float(getattr(m, name))
    if name == "delta":
        return float(m.rotor.delta)
    if name == "p_star":
        return math.sqrt(m.p_star_sq)
    if name == "equilibria":
        return float(len(m.equilibria()))
    if name == "cycles":
        return float(m.cycles_exist())
    if name in ("r_minus_deg", "r_plus_deg"):
        want = "r-" if name == "r_minus_deg" else "r+"
        cyc = [c for c in m.limit_cycles() if c.name == want]
        return math.degrees(cyc[0].theta) if cyc else math.nan
    if name == "sampling_factor":  # mean drive of the sampled switching law: sin(Λh)/(Λh), Λ = |L0|/J
        from gyro_sim.engine.simulate import controller_period

        h = controller_period(scene)
        x = _initial_L(scene) / m.rotor.J * h
        return math.sin(x) / x if x else 1.0
    if name == "time_to_deg":
        if len(xs) != 1:
            raise ValueError("k(time_to_deg, x) takes one angle in degrees")
        return float(m.time_to_theta(scene.initial.theta, math.radians(xs[0]), L0=_initial_L(scene)))
    raise ValueError(f"k({name}): allowed {', '.join(_K_ATTRS)}")


@dataclass(frozen=True)
class Metric:
    """A metric column: ``name`` and ``func(args)`` (see METRIC_FUNCTIONS, METRIC_ALIASES, k(...))."""

    name: str
    func: str
    args: tuple = ()

    @property
    def spec(self) -> str:
        return f"{self.name}={self.func}({','.join(str(a) for a in self.args)})"

    @property
    def needs_run(self) -> bool:
        return self.func != "k"

    def evaluate(self, res, scene) -> float:
        if self.func == "k":
            return _k_metric(scene, str(self.args[0]), [float(a) for a in self.args[1:]])
        nq, nx, f = METRIC_FUNCTIONS[self.func]
        qs = [_quantity(res, str(a)) for a in self.args[:nq]]
        xs = [float(a) for a in self.args[nq:]]
        v = f(res, scene, qs, xs)
        return float(v)


def parse_metric(text: str, name: Optional[str] = None) -> Metric:
    """``[NAME=]FUNC(ARGS)`` or a bare alias (``final_spin``); ``name`` overrides NAME."""
    text = str(text).strip()
    m = re.fullmatch(r"(?:([A-Za-z_]\w*)\s*=\s*)?([A-Za-z_]\w*)\s*(?:\((.*)\))?", text)
    if not m:
        raise SweepError(f"metric {text!r}: expected NAME=FUNC(ARGS), FUNC(ARGS) or one of {', '.join(METRIC_ALIASES)}")
    given, func, argtext = m.group(1), m.group(2), m.group(3)
    name = name or given
    if name is not None and not re.fullmatch(r"[A-Za-z_]\w*", str(name)):
        raise SweepError(f"metric name {name!r}: letters, digits and _ only")
    if argtext is None:
        if func in METRIC_ALIASES:
            inner = parse_metric(METRIC_ALIASES[func])
            return Metric(name or func, inner.func, inner.args)
        raise SweepError(f"metric {text!r}: unknown metric; give FUNC(ARGS) or one of {', '.join(METRIC_ALIASES)}")
    args = tuple(_parse_value(a) for a in _split_top(argtext, ",")) if argtext.strip() else ()
    if func == "k":
        if not args or args[0] not in _K_ATTRS:
            raise SweepError(f"metric {text!r}: k(NAME[, x]) with NAME one of {', '.join(_K_ATTRS)}")
        if args[0] == "time_to_deg" and (len(args) != 2 or not _is_number(args[1])):
            raise SweepError(f"metric {text!r}: k(time_to_deg, DEGREES)")
    elif func in METRIC_FUNCTIONS:
        nq, nx, _ = METRIC_FUNCTIONS[func]
        if len(args) != nq + nx:
            raise SweepError(f"metric {text!r}: {func} takes {nq} quantit{'y' if nq == 1 else 'ies'}"
                             f"{f' and {nx} number' if nx else ''}")
        for a in args[:nq]:
            if not (a in QUANTITIES or (isinstance(a, str) and a.startswith("current_"))):
                raise SweepError(f"metric {text!r}: unknown quantity {a!r}; allowed: {', '.join(QUANTITIES)}, "
                                 f"current_<stator>")
        for a in args[nq:]:
            if not _is_number(a):
                raise SweepError(f"metric {text!r}: {a!r} is not a number")
    else:
        raise SweepError(f"metric {text!r}: unknown function {func!r}; allowed: "
                         f"{', '.join(list(METRIC_FUNCTIONS) + ['k'])}")
    if name is None:
        name = "_".join([func] + [re.sub(r"\W", "_", str(a)) for a in args]).strip("_")
    if name in _FIXED_COLUMNS or name.startswith("series"):
        raise SweepError(f"metric name {name!r} is reserved; choose another (NAME=...)")
    return Metric(name, func, args)


# ------------------------------------------------------------------------------------------
# the sweep spec
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Variant:
    index: int
    values: dict  # dotted key → value (grid and random keys)
    sample: Optional[int]
    run_id: str


@dataclass
class SweepSpec:
    """A sweep: base scene, fixed overrides (``set``), grid axes, random variables, metrics, series."""

    name: str
    scene_data: dict
    scene_ref: str  # built-in name / path / "<inline>"
    scene_where: str = ""
    set: dict = field(default_factory=dict)
    grid: list = field(default_factory=list)  # [Axis]
    random: list = field(default_factory=list)  # [RandomVar]
    samples: Optional[int] = None
    seed: int = 0
    metrics: list = field(default_factory=list)  # [Metric]
    series: list = field(default_factory=list)  # quantity names kept as time series
    series_points: int = 1000
    description: str = ""
    default_metrics: bool = False  # the metrics are DEFAULT_METRICS (a --metric replaces them)

    # --- checks ----------------------------------------------------------------------------
    def check(self) -> "SweepSpec":
        keys = [a.key for a in self.grid] + [r.key for r in self.random]
        dup = sorted({k for k in keys if keys.count(k) > 1})
        if dup:
            raise SweepError(f"key {dup[0]} is varied twice (vary/random)")
        both = sorted(set(keys) & set(self.set))
        if both:
            raise SweepError(f"key {both[0]} is both fixed (set) and varied")
        for k in keys:
            for other in keys:
                if other != k and other.startswith(k + "."):
                    raise SweepError(f"keys {k} and {other} overlap")
        if self.random and not self.samples:
            raise SweepError("random keys need a number of samples (--samples N, samples: N)")
        if self.samples and not self.random:
            raise SweepError(f"samples = {self.samples} but no random key: identical runs")
        if self.samples is not None and self.samples < 0:
            raise SweepError(f"samples = {self.samples} must be ≥ 0")
        if not self.metrics:
            self.metrics = [parse_metric(m) for m in DEFAULT_METRICS]
            self.default_metrics = True
        names = [m.name for m in self.metrics]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise SweepError(f"metric name {dup[0]} is used twice")
        clash = sorted(set(names) & set(keys))
        if clash:
            raise SweepError(f"metric name {clash[0]} is also a varied key")
        for q in self.series:
            if q not in QUANTITIES and not q.startswith("current_"):
                raise SweepError(f"series {q!r}: unknown quantity; allowed: {', '.join(QUANTITIES)}, current_<stator>")
        if self.series_points < 2:
            raise SweepError("series_points must be ≥ 2")
        return self

    # --- variants --------------------------------------------------------------------------
    @property
    def scene_canonical(self) -> str:
        return json.dumps(self.scene_data, sort_keys=True, default=str)

    def run_id(self, values: dict) -> str:
        """Hash of (scene content, fixed overrides, variant values, metrics, series): the resume key."""
        key = {"scene": self.scene_canonical, "set": self.set, "values": values,
               "metrics": [m.spec for m in self.metrics], "series": list(self.series),
               "series_points": self.series_points if self.series else 0}
        return hashlib.sha256(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()[:24]

    def variants(self) -> list:
        grid = list(itertools.product(*[a.values for a in self.grid])) if self.grid else [()]
        samples = list(range(self.samples)) if self.random else [None]
        out: list = []
        for combo in grid:
            for s in samples:
                values = {a.key: _plain(v) for a, v in zip(self.grid, combo)}
                for rv in self.random:
                    values[rv.key] = rv.draw(self.seed, s)
                out.append(Variant(len(out), values, s, self.run_id(values)))
        return out

    def scene_for(self, values: dict):
        """The validated scene of a variant (raises SceneError with the key, value and what is allowed)."""
        return _scene_for(self.scene_data, self.set, values, self.scene_where, self.name)

    def payload(self) -> dict:
        """What a worker needs (plain data, pickles small)."""
        return {"scene": self.scene_data, "where": self.scene_where, "name": self.name, "set": self.set,
                "metrics": [m.spec for m in self.metrics], "series": list(self.series),
                "series_points": self.series_points}

    def meta(self) -> dict:
        return {"name": self.name, "description": self.description, "scene_ref": self.scene_ref,
                "scene": self.scene_data, "set": self.set,
                "vary": {a.key: a.spec for a in self.grid}, "grid": [a.key for a in self.grid],
                "random": {r.key: r.spec for r in self.random}, "samples": self.samples, "seed": self.seed,
                "metrics": {m.name: m.spec.split("=", 1)[1] for m in self.metrics}, "series": list(self.series),
                "gyro_sim_version": __version__}


def _scene_for(data: dict, fixed: dict, values: dict, where: str, name: str):
    label = ", ".join(f"{k}={_fmt(v)}" for k, v in values.items())
    w = f"{where} [{label}]" if label else where
    try:
        d = apply_overrides(data, {**fixed, **values})
    except (KeyError, IndexError, TypeError, ValueError, AttributeError) as e:
        bad = ", ".join(f"{k}" for k in {**fixed, **values})
        raise SceneError(f"invalid scene {w}: cannot set {bad}: {type(e).__name__}: {e}") from None
    return scene_from_dict(d, where=w, default_name=name)


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, list):
        return "[" + ",".join(_fmt(x) for x in v) + "]"
    return str(v)


# --- loading ---------------------------------------------------------------------------------
def builtin_sweeps() -> dict:
    """Built-in sweep files: ``config/sweep_*.yaml`` by stem."""
    d = config_dir()
    return {p.stem: p for p in sorted(d.glob("sweep_*.yaml"))} if d.is_dir() else {}


def _load_scene_ref(ref, base: Optional[Path]) -> tuple:
    """(data, where, name, ref text) of a scene given by built-in name, path or inline mapping."""
    if isinstance(ref, dict):
        data = copy.deepcopy(ref)
        return data, f"{base / '(inline scene)' if base else '(inline scene)'}", data.get("name", "scene"), "<inline>"
    if not isinstance(ref, (str, Path)):
        raise SweepError(f"scene = {ref!r}: a built-in scene name, a path or an inline mapping")
    p = Path(ref)
    cands = [base / p] if base is not None and not p.is_absolute() else []
    cands.append(p)
    for c in cands:
        if c.is_file():
            p = c
            break
    else:
        scenes = builtin_scenes()
        key = p.stem if p.suffix in (".yaml", ".yml") else str(ref)
        if key in scenes and p.parent == Path("."):
            p = scenes[key]
        else:
            raise SweepError(f"scene {str(ref)!r}: no such file and no built-in scene of that name; "
                             f"built-in scenes: {', '.join(scenes) or 'none found'}")
    try:
        data = parse_scene_text(read_scene_file(p), str(p))
    except SceneError as e:
        raise SweepError(str(e)) from None
    if not isinstance(data, dict):
        raise SweepError(f"invalid scene {p}: the top level must be a mapping")
    return data, str(p), data.get("name", p.stem), str(ref)


_SWEEP_KEYS = {"name", "description", "scene", "set", "vary", "random", "samples", "seed", "metrics", "series",
               "series_points"}


def spec_from_dict(d: dict, where: str = "", base: Optional[Path] = None) -> SweepSpec:
    """A sweep from a parsed sweep file (see the module docstring and docs/sweeps.md)."""
    if not isinstance(d, dict):
        raise SweepError(f"invalid sweep {where}: the top level must be a mapping")
    extra = set(d) - _SWEEP_KEYS
    if extra:
        raise SweepError(f"invalid sweep {where}: unknown key(s) {sorted(extra)}; allowed: {', '.join(sorted(_SWEEP_KEYS))}")
    if "scene" not in d:
        raise SweepError(f"invalid sweep {where}: scene: required key is missing")
    data, swhere, sname, ref = _load_scene_ref(d["scene"], base)
    name = d.get("name") or (Path(where).stem if where else sname)

    def mapping(key):
        v = d.get(key) or {}
        if not isinstance(v, dict):
            raise SweepError(f"invalid sweep {where}: {key} must be a mapping of dotted keys")
        return v

    try:
        grid = [parse_axis(k, v) for k, v in mapping("vary").items()]
        rnd = [parse_random(k, v) for k, v in mapping("random").items()]
        mets = d.get("metrics") or []
        if isinstance(mets, dict):
            metrics = [parse_metric(v, name=k) for k, v in mets.items()]
        elif isinstance(mets, list):
            metrics = [parse_metric(v) for v in mets]
        else:
            raise SweepError("metrics must be a list or a mapping NAME: FUNC(ARGS)")
        series = d.get("series") or []
        if isinstance(series, str):
            series = [s.strip() for s in series.split(",") if s.strip()]
        spec = SweepSpec(name=str(name), scene_data=data, scene_ref=ref, scene_where=swhere,
                         set={k: _parse_value(v) for k, v in mapping("set").items()}, grid=grid, random=rnd,
                         samples=d.get("samples"), seed=int(d.get("seed", 0) or 0), metrics=metrics,
                         series=list(series), series_points=int(d.get("series_points", 1000)),
                         description=str(d.get("description", "") or ""))
        return spec.check()
    except SweepError as e:
        raise SweepError(f"invalid sweep {where}: {e}" if where else str(e)) from None


def load_sweep(source: str | Path) -> SweepSpec:
    """A sweep file (path or built-in name ``sweep_*``) or a scene (path or built-in name) swept over nothing."""
    p = Path(source)
    if not p.is_file():
        sw = builtin_sweeps()
        key = p.stem if p.suffix in (".yaml", ".yml") else str(source)
        if key in sw and p.parent == Path("."):
            p = sw[key]
        else:
            data, where, name, ref = _load_scene_ref(str(source), None)
            return SweepSpec(name=str(name), scene_data=data, scene_ref=ref, scene_where=where).check()
    try:
        d = parse_scene_text(read_scene_file(p, kind="sweep"), str(p), kind="sweep")
    except SceneError as e:
        raise SweepError(str(e)) from None
    if isinstance(d, dict) and "rotor" in d:  # a scene file
        data, where, name, ref = _load_scene_ref(str(p), None)
        return SweepSpec(name=str(name), scene_data=data, scene_ref=ref, scene_where=where).check()
    return spec_from_dict(d, where=str(p), base=p.parent)


# ------------------------------------------------------------------------------------------
# one task: run a chunk of variants (in a Dask worker or in this process)
# ------------------------------------------------------------------------------------------
def _run_scene(scene):
    """The integrator (``gyro_sim.run``); one place so tests can stand in for it."""
    from gyro_sim.engine.simulate import run

    return run(scene)


def _worker_label() -> str:
    try:
        from distributed import get_worker

        return f"{get_worker().address}/pid{os.getpid()}"
    except Exception:  # not in a Dask worker (or no distributed)
        return f"{socket.gethostname()}/pid{os.getpid()}"


def _decimate(y: np.ndarray, n: int) -> list:
    if y.size <= n:
        return [float(v) for v in y]
    idx = np.unique(np.linspace(0, y.size - 1, n).round().astype(int))
    return [float(v) for v in y[idx]]


def run_chunk(payload: dict, items: Sequence[tuple]) -> list:
    """Run the variants ``items`` = [(run_id, values), ...] of a sweep ``payload`` (SweepSpec.payload)
    one after the other; returns one row per item: run_id, status ('ok' | 'invalid' | 'failed'),
    error, metrics {name: float}, series {quantity: [..]}, wall_time_run (s), cpu_time_run (s of this
    thread's CPU), worker. Never raises for a bad variant or a failed run: the reason goes in ``error``."""
    metrics = [parse_metric(m) for m in payload["metrics"]]
    series = payload.get("series") or []
    npts = int(payload.get("series_points", 1000))
    label = _worker_label()
    rows = []
    for run_id, values in items:
        w0, c0 = time.perf_counter(), time.thread_time()
        row = {"run_id": run_id, "status": "ok", "error": None, "metrics": {}, "series": {}, "worker": label}
        try:
            scene = _scene_for(payload["scene"], payload.get("set") or {}, values, payload.get("where", ""),
                               payload.get("name", "scene"))
        except SceneError as e:
            row.update(status="invalid", error=str(e), wall_time_run=time.perf_counter() - w0,
                       cpu_time_run=time.thread_time() - c0)
            rows.append(row)
            continue
        try:
            res = _run_scene(scene) if any(m.needs_run for m in metrics) or series else None
            if res is not None:
                # (q is NaN by design in a run without attitude: output.attitude false, isotropic rotor)
                finite = np.isfinite(res.L).all(axis=1) & (np.isfinite(res.q).all(axis=1) | (not res.attitude))
                if not finite.all():
                    i = int(np.argmin(finite))
                    raise FloatingPointError(f"non-finite state (L or attitude) at t = {res.t[i]:.6g} s")
            vals = {}
            for m in metrics:
                try:
                    vals[m.name] = m.evaluate(res, scene)
                except Exception as e:  # noqa: BLE001 - reported, never raised
                    raise RuntimeError(f"metric {m.name}: {type(e).__name__}: {e}") from None
            row["metrics"] = vals
            if series and res is not None:
                row["series"] = {"t": _decimate(res.t, npts), **{q: _decimate(_quantity(res, q), npts) for q in series}}
        except Exception as e:  # noqa: BLE001 - a failed run is a result
            msg = str(e) if isinstance(e, (FloatingPointError, RuntimeError)) and str(e) else f"{type(e).__name__}: {e}"
            row.update(status="failed", error=msg, metrics={}, series={})
        row["wall_time_run"] = time.perf_counter() - w0
        row["cpu_time_run"] = time.thread_time() - c0  # (this thread's CPU s: measure() compares it, not stored)
        rows.append(row)
    return rows


def _noop(x):
    return x


# ------------------------------------------------------------------------------------------
# results: Parquet table (+ journal)
# ------------------------------------------------------------------------------------------
def _journal_path(out: Path) -> Path:
    return out.with_name(out.name + ".journal.jsonl")


def _flat_row(spec: SweepSpec, v: Variant, r: dict) -> dict:
    row = {"run_id": v.run_id, "index": v.index, "sample": v.sample, "status": r["status"], "error": r.get("error"),
           "wall_time_run": float(r.get("wall_time_run") or 0.0), "worker": r.get("worker", ""),
           "gyro_sim_version": r.get("gyro_sim_version", __version__)}
    row.update(v.values)
    for m in spec.metrics:
        row[m.name] = float(r.get("metrics", {}).get(m.name, math.nan)) if r["status"] == "ok" else math.nan
    if spec.series:
        ser = r.get("series") or {}
        for q in ["t"] + list(spec.series):
            row[f"series.{q}"] = ser.get(q)
    return row


def _row_from_flat(spec: SweepSpec, flat: dict) -> dict:
    r = {"run_id": flat["run_id"], "status": flat["status"], "error": flat.get("error"),
         "wall_time_run": flat.get("wall_time_run"), "worker": flat.get("worker"),
         "gyro_sim_version": flat.get("gyro_sim_version"),
         "metrics": {m.name: flat.get(m.name, math.nan) for m in spec.metrics}, "series": {}}
    if spec.series:
        r["series"] = {q: flat.get(f"series.{q}") for q in ["t"] + list(spec.series)}
    return r


def write_results(path: Path, rows: list, meta: dict) -> None:
    """Write the flat rows as a Parquet table (atomically) with the sweep's metadata in the schema."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    cols: dict = {}
    keys: list = []
    for r in rows:
        for k in r:
            if k not in cols:
                cols[k] = None
                keys.append(k)
    arrays = {}
    for k in keys:
        vals = [r.get(k) for r in rows]
        if k in ("index", "sample"):
            arrays[k] = pa.array(vals, type=pa.int64())
        elif k in ("run_id", "status", "error", "worker", "gyro_sim_version"):
            arrays[k] = pa.array(vals, type=pa.string())
        else:
            nonnull = [v for v in vals if v is not None]
            if all(isinstance(v, bool) for v in nonnull) and nonnull:
                arrays[k] = pa.array(vals, type=pa.bool_())
            elif all(_is_number(v) for v in nonnull):
                arrays[k] = pa.array([None if v is None else float(v) for v in vals], type=pa.float64())
            elif all(isinstance(v, list) and all(_is_number(x) for x in v) for v in nonnull):
                arrays[k] = pa.array([None if v is None else [float(x) for x in v] for v in vals],
                                     type=pa.list_(pa.float64()))
            else:
                arrays[k] = pa.array([None if v is None else (v if isinstance(v, str) else json.dumps(v)) for v in vals],
                                     type=pa.string())
    table = pa.table(arrays) if arrays else pa.table({"run_id": pa.array([], pa.string())})
    table = table.replace_schema_metadata({_META_KEY: json.dumps(meta, default=str).encode()})
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    pq.write_table(table, tmp)
    os.replace(tmp, path)


def read_results(path: str | Path) -> tuple:
    """(rows as dicts, sweep metadata dict) of a results file written by :func:`run_sweep`."""
    import pyarrow.parquet as pq

    path = Path(path)
    try:
        table = pq.read_table(path)
    except Exception as e:  # noqa: BLE001
        raise SweepError(f"cannot read results {path}: {e}") from None
    md = table.schema.metadata or {}
    meta = json.loads(md[_META_KEY]) if _META_KEY in md else {}
    return table.to_pylist(), meta


def _read_journal(path: Path) -> list:
    rows = []
    if path.is_file():
        with open(path, encoding="utf-8") as f:
            for line in f:
                try:
                    rows.append(json.loads(line))
                except json.JSONDecodeError:  # a line cut by a hard stop
                    continue
    return rows


# ------------------------------------------------------------------------------------------
# the driver
# ------------------------------------------------------------------------------------------
@dataclass
class SweepResult:
    spec: SweepSpec
    rows: list  # flat rows (table columns), by variant index
    n_total: int = 0
    n_run: int = 0  # run now
    n_skipped: int = 0  # already in the results file
    n_invalid: int = 0
    n_failed: int = 0  # failed runs (all, this time or before)
    wall: float = 0.0  # s, executing the runs (cluster start excluded)
    startup: float = 0.0  # s, starting / connecting to the cluster
    workers: int = 0
    tasks: int = 0  # tasks sent (runs in this process: one per run)
    mode: str = ""
    interrupted: bool = False
    out: Optional[Path] = None

    @property
    def runs_per_second(self) -> float:
        return self.n_run / self.wall if self.wall > 0 else math.nan


class _Progress:
    """Runs done / failed and the time left (tqdm on stderr)."""

    def __init__(self, total: int, initial: int, name: str, enabled: bool):
        self.failed = 0
        self.bar = None
        if enabled and total > initial:
            try:
                from tqdm import tqdm
            except ImportError:  # pragma: no cover - the sweep extra brings it
                return
            self.bar = tqdm(total=total, initial=initial, desc=f"sweep {name}", unit="run", file=sys.stderr,
                            mininterval=0.2 if sys.stderr.isatty() else 5.0, dynamic_ncols=True, leave=True)

    def update(self, failed: bool) -> None:
        if failed:
            self.failed += 1
        if self.bar is not None:
            self.bar.set_postfix_str(f"failed={self.failed}", refresh=False)
            self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _dask_client(workers: Optional[int], scheduler: Optional[str]):
    """(client, cluster or None, n_workers, mode)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise SweepError("running on Dask needs the sweep extra: pip install 'gyro_sim[sweep]' "
                         "(or --workers 0 to run in this process)") from None
    logging.getLogger("distributed").setLevel(logging.ERROR)
    if scheduler:
        kw = {"scheduler_file": scheduler} if Path(scheduler).is_file() else {"address": scheduler}
        try:
            client = Client(timeout="20s", **kw)
        except Exception as e:  # noqa: BLE001
            raise SweepError(f"cannot connect to the Dask scheduler {scheduler}: {e}") from None
        n = len(client.scheduler_info().get("workers", {}))
        if n == 0:
            try:
                client.wait_for_workers(1, timeout=20)
            except Exception:  # noqa: BLE001
                client.close()
                raise SweepError(f"the Dask scheduler {scheduler} has no workers") from None
            n = len(client.scheduler_info().get("workers", {}))
        return client, None, n, f"scheduler {client.scheduler.address}"
    import dask

    from gyro_sim.apps.sweep_tasks import WORKER_CONFIG

    n = int(workers) if workers else (os.cpu_count() or 1)
    with warnings.catch_warnings(), dask.config.set(WORKER_CONFIG):  # (the nannies pass it to their workers)
        # the scheduler's health endpoint moves off 8787 if that is taken
        warnings.filterwarnings("ignore", message=r"Port \d+ is already in use")
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, silence_logs=logging.ERROR)
    client = Client(cluster)
    return client, cluster, n, f"local cluster ({n} worker process{'es' if n != 1 else ''})"


def _batch_arg(text) -> Any:
    """``--batch``: ``"auto"`` or a whole number ≥ 1 (SweepError otherwise)."""
    if str(text).strip().lower() == "auto":
        return "auto"
    try:
        n = int(text)
    except (TypeError, ValueError):
        n = 0
    if n < 1:
        raise SweepError(f"--batch {text}: must be a whole number ≥ 1 or auto")
    return n


def _execute(payload: dict, items: list, client, batch, on_rows: Callable, worker_addrs=None):
    """Run ``items`` ([(run_id, values)]) on the client (in this process if None, one variant after the other):
    ``batch`` variants per task, or tasks sized as they are sent (``"auto"``, :func:`gyro_sim.sweep_tasks.
    run_adaptive`; returns its sizer)."""
    if client is None:
        for it in items:
            on_rows(run_chunk(payload, [it]))
        return None
    from gyro_sim.apps.sweep_tasks import run_adaptive, run_fixed

    pl = client.scatter([payload], broadcast=True, hash=False)[0]  # once per worker, not once per task
    if batch == "auto":
        return run_adaptive(client, run_chunk, pl, items, on_rows, worker_addrs=worker_addrs)
    run_fixed(client, run_chunk, pl, items, int(batch), on_rows, worker_addrs=worker_addrs)
    return None


def run_sweep(spec: SweepSpec, out: Optional[str | Path] = None, workers: Optional[int] = None,
              scheduler: Optional[str] = None, batch="auto", resume: bool = True, retry_failed: bool = False,
              progress: bool = True) -> SweepResult:
    """Run every variant of ``spec``: validated first, then as Dask tasks (``workers`` = 0: in this
    process), skipping the runs ``out`` already holds. Writes ``out`` (Parquet) if given. ``batch``: variants
    per task, or ``"auto"``: each task sized as it is sent (:mod:`gyro_sim.sweep_tasks`); the results do not
    depend on it."""
    t_start = time.perf_counter()
    from gyro_sim.common.extras import MissingExtra

    try:  # (before any run: without pyarrow the results could not be written after the last one)
        _require_extras(out is not None, workers == 0 and not scheduler, "run_sweep")
    except MissingExtra as e:
        raise SweepError(str(e)) from None
    variants = spec.variants()
    by_id = {v.run_id: v for v in variants}
    out = Path(out) if out is not None else None
    done: dict = {}
    if out is not None and resume:
        if out.is_file():
            old, _ = read_results(out)
            for flat in old:
                if flat.get("run_id") in by_id and flat.get("status") != "invalid":
                    done[flat["run_id"]] = _row_from_flat(spec, flat)
        for r in _read_journal(_journal_path(out)):
            if r.get("run_id") in by_id:
                done[r["run_id"]] = r
        if retry_failed:
            done = {k: r for k, r in done.items() if r["status"] == "ok"}
    elif out is not None:
        _journal_path(out).unlink(missing_ok=True)
    results: dict = dict(done)
    # --- validate every variant before anything runs
    todo = []
    n_invalid = 0
    for v in variants:
        if v.run_id in done:
            continue
        try:
            spec.scene_for(v.values)
        except SceneError as e:
            results[v.run_id] = {"run_id": v.run_id, "status": "invalid", "error": str(e), "metrics": {}, "series": {},
                                 "wall_time_run": 0.0, "worker": ""}
            n_invalid += 1
            continue
        todo.append(v)
    res = SweepResult(spec, [], n_total=len(variants), n_skipped=len(done), n_invalid=n_invalid, out=out)
    bar = _Progress(len(variants), len(variants) - len(todo), spec.name, progress)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
    journal = open(_journal_path(out), "a", encoding="utf-8") if out is not None and todo else None

    def on_rows(rows):
        for r in rows:
            r["gyro_sim_version"] = __version__
            results[r["run_id"]] = r
            if journal is not None:
                journal.write(json.dumps(r) + "\n")
                journal.flush()
            res.n_run += 1
            bar.update(r["status"] != "ok")

    client = cluster = None
    try:
        if todo:
            payload = spec.payload()
            items = [(v.run_id, v.values) for v in todo]
            if workers == 0 and not scheduler:
                res.mode, res.workers = "in-process", 1
                res.startup = 0.0
            else:
                t0 = time.perf_counter()
                client, cluster, res.workers, res.mode = _dask_client(workers, scheduler)
                res.startup = time.perf_counter() - t0
            t0 = time.perf_counter()
            sizer = _execute(payload, items, client, batch, on_rows)
            res.wall = time.perf_counter() - t0
            res.tasks = (len(sizer.sizes) if sizer is not None else
                         len(items) if client is None else math.ceil(len(items) / int(batch)))
    except KeyboardInterrupt:
        res.interrupted = True
        res.wall = time.perf_counter() - t_start
    finally:
        bar.close()
        if journal is not None:
            journal.close()
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    res.rows = [_flat_row(spec, v, results[v.run_id]) for v in variants if v.run_id in results]
    res.n_failed = sum(1 for r in res.rows if r["status"] == "failed")
    res.n_invalid = sum(1 for r in res.rows if r["status"] == "invalid")
    if out is not None:
        meta = dict(spec.meta(), complete=not res.interrupted and len(res.rows) == len(variants),
                    created=time.strftime("%Y-%m-%dT%H:%M:%S%z"))
        write_results(out, res.rows, meta)
        _journal_path(out).unlink(missing_ok=True)
    return res


# ------------------------------------------------------------------------------------------
# plots
# ------------------------------------------------------------------------------------------
def _xval(v):
    if isinstance(v, list):
        return float(v[0]) if v else math.nan
    return float(v) if _is_number(v) else math.nan


def plot_sweep(rows: list, meta: dict, path: str | Path | None = None, metrics: Optional[Sequence[str]] = None):
    """One figure, a panel per metric: a metric against the one grid key (runs as points, the median over
    Monte Carlo samples as a line), a 2-D map over the first two grid keys (mean over the rest), or
    histograms for a random-only sweep. Runs that never reached a level (inf) are ▲ at the top; failed
    or invalid variants are red × (1-D or 2-D cells).

    Args:
        rows: the result rows (:func:`read_results`); meta: the sweep's metadata (grid, random, metrics).
        path: if given, the figure is also written there as PNG (atomically; parent folders are made).
        metrics: the metric names to draw (default: every metric of ``meta``, at most 8).

    Returns:
        The ``matplotlib.figure.Figure`` (Agg canvas, no pyplot state; the backend is left as it is)."""
    import matplotlib
    import matplotlib.transforms

    from gyro_sim.io.plotting import new_figure, save_png
    names = list(metrics or list(meta.get("metrics", {})))[:8]
    grid = list(meta.get("grid", []))
    rnd = list(meta.get("random", {}))
    n = max(1, len(names))
    ncol = 1 if n == 1 else 2
    nrow = math.ceil(n / ncol)
    fig = new_figure((6.4 * ncol, 4.0 * nrow), layout="tight")
    axes = fig.subplots(nrow, ncol, squeeze=False)
    title = f"sweep {meta.get('name', '')}: {len(rows)} runs"
    nf = sum(1 for r in rows if r["status"] != "ok")
    if nf:
        title += f", {nf} failed"
    fig.suptitle(title)
    ok = [r for r in rows if r["status"] == "ok"]
    bad = [r for r in rows if r["status"] != "ok"]
    for i, name in enumerate(names):
        ax = axes[i // ncol][i % ncol]
        expr = meta.get("metrics", {}).get(name, "")
        ax.set_title(f"{name} = {expr}" if expr else name, fontsize=9)
        if not grid:
            vals = np.array([r.get(name, math.nan) for r in ok], dtype=float)
            fin = vals[np.isfinite(vals)]
            if fin.size:
                ax.hist(fin, bins=max(5, min(40, int(math.sqrt(fin.size)) * 2)), color="C0", alpha=0.8)
            ninf = int(np.sum(np.isinf(vals)))
            ax.set_xlabel(name + (f"   ({ninf} never / inf)" if ninf else ""))
            ax.set_ylabel("runs")
            if rnd:
                ax.text(0.99, 0.97, f"{len(ok)} samples of {', '.join(rnd)}", transform=ax.transAxes, ha="right",
                        va="top", fontsize=8)
        elif len(grid) == 1:
            key = grid[0]
            xs = np.array([_xval(r.get(key)) for r in ok])
            ys = np.array([r.get(name, math.nan) for r in ok], dtype=float)
            fin = np.isfinite(ys)
            ax.plot(xs[fin], ys[fin], "o" if rnd else "o-", ms=4, alpha=0.6 if rnd else 1.0, color="C0", label="runs")
            if rnd and fin.any():
                ux = np.unique(xs[~np.isnan(ys)])
                med = np.array([np.median(ys[(xs == u) & ~np.isnan(ys)]) for u in ux])
                ax.plot(ux, np.where(np.isfinite(med), med, np.nan), "-", color="C1", label="median over samples")
            if np.any(np.isinf(ys)):
                tr = matplotlib.transforms.blended_transform_factory(ax.transData, ax.transAxes)
                ax.plot(xs[np.isinf(ys)], np.full(int(np.sum(np.isinf(ys))), 0.97), "^", color="C3", transform=tr,
                        label="never (inf)")
            if bad:
                tr = matplotlib.transforms.blended_transform_factory(ax.transData, ax.transAxes)
                bx = np.array([_xval(r.get(key)) for r in bad])
                ax.plot(bx, np.full(bx.size, 0.03), "x", color="red", transform=tr, label="failed / invalid")
            vec = any(isinstance(r.get(key), list) for r in rows)
            ax.set_xlabel(key + ("[0]" if vec else ""))
            ax.set_ylabel(name)
            ax.grid(alpha=0.3)
            if rnd or bad or np.any(np.isinf(ys)):
                ax.legend(fontsize=7)
        else:
            kx, ky = grid[0], grid[1]
            xv = sorted({_xval(r.get(kx)) for r in rows})
            yv = sorted({_xval(r.get(ky)) for r in rows})
            Z = np.full((len(yv), len(xv)), math.nan)
            S = np.zeros_like(Z)
            C = np.zeros_like(Z)
            INF = np.zeros_like(Z)
            for r in ok:
                v = float(r.get(name, math.nan))
                a, b = yv.index(_xval(r.get(ky))), xv.index(_xval(r.get(kx)))
                if math.isfinite(v):
                    S[a, b] += v
                    C[a, b] += 1
                elif math.isinf(v):
                    INF[a, b] += 1
            with np.errstate(invalid="ignore", divide="ignore"):
                Z = np.where(C > 0, S / np.maximum(C, 1), math.nan)
            cmap = matplotlib.colormaps["viridis"]  # the registry: no pyplot
            cmap = cmap.with_extremes(bad="0.85") if hasattr(cmap, "with_extremes") else cmap
            im = ax.imshow(np.ma.masked_invalid(Z), origin="lower", aspect="auto", cmap=cmap, interpolation="nearest")
            fig.colorbar(im, ax=ax, label=name)
            for a in range(len(yv)):
                for b in range(len(xv)):
                    if C[a, b] == 0 and INF[a, b] > 0:
                        ax.text(b, a, "∞", ha="center", va="center", fontsize=8, color="C3")
            for r in bad:
                ax.plot(xv.index(_xval(r.get(kx))), yv.index(_xval(r.get(ky))), "x", color="red")
            step_x, step_y = max(1, len(xv) // 8), max(1, len(yv) // 8)
            ax.set_xticks(range(0, len(xv), step_x), [f"{v:.3g}" for v in xv[::step_x]], fontsize=7)
            ax.set_yticks(range(0, len(yv), step_y), [f"{v:.3g}" for v in yv[::step_y]], fontsize=7)
            ax.set_xlabel(kx)
            ax.set_ylabel(ky)
    for j in range(len(names), nrow * ncol):
        axes[j // ncol][j % ncol].set_visible(False)
    if path is not None:
        save_png(fig, path, dpi=110)
    return fig


# ------------------------------------------------------------------------------------------
# measuring the execution (runs/s, scaling, overhead per task, batched path)
# ------------------------------------------------------------------------------------------
#: the Dask configurations :func:`measure` can time: label → (workers: "one" | "all", variants per task or "auto")
MEASURE_CONFIGS = {"one_worker": ("one", 1), "all_workers": ("all", 1), "batched": ("all", None),
                   "one_worker_auto": ("one", "auto"), "all_workers_auto": ("all", "auto")}


def _timed_rows(payload: dict, items: list, client, batch, worker_addrs=None) -> tuple:
    """(wall s, rows, tasks) of one pass over ``items``."""
    rows: list = []
    t0 = time.perf_counter()
    sizer = _execute(payload, items, client, batch, rows.extend, worker_addrs=worker_addrs)
    wall = time.perf_counter() - t0
    tasks = len(items) if client is None else (len(sizer.sizes) if sizer is not None
                                               else math.ceil(len(items) / int(batch)))
    return wall, rows, tasks


def _pass_figures(n: int, wall: float, rows: list, tasks: int, workers: int) -> dict:
    """runs/s, the mean cost of a run (wall and this thread's CPU, s) and the overhead per task of one pass."""
    run_sum = sum(r["wall_time_run"] for r in rows)
    o = {"wall": wall, "runs_per_s": n / wall, "tasks": tasks, "run_sum": run_sum,
         "cpu_sum": sum(r.get("cpu_time_run", 0.0) for r in rows), "failed": sum(1 for r in rows if r["status"] != "ok"),
         "workers": workers}
    o["run_wall"], o["run_cpu"] = o["run_sum"] / n, o["cpu_sum"] / n
    o["overhead_per_task"] = (workers * wall - run_sum) / tasks
    return o


def measure(spec: SweepSpec, workers: Optional[int] = None, batch: Optional[int] = None,
            noop_tasks: int = 400, scheduler: Optional[str] = None, stream=None,
            configs: Sequence[str] = tuple(MEASURE_CONFIGS), repeats: int = 1,
            each_round: Optional[Callable] = None) -> dict:
    """Time the sweep's runs in this process and on Dask, and the bare task overhead; returns (and prints) the
    figures.

    In this process one after the other (no Dask), before the cluster starts and again after it is closed
    (``serial``: their mean; a drifting load shows as their difference); then each of ``configs``
    (:data:`MEASURE_CONFIGS`): 1 worker or all workers, one task per run, ``batch`` runs per task (``batched``;
    default: an even split, 4 tasks per worker) or tasks sized as they are sent (``*_auto``, the default of
    ``run_sweep``). Workers are warmed first (simulator imported, kernels loaded); cluster start is reported
    apart. For each: runs/s, the speed-up over this process, the mean cost of a run inside the worker (wall and
    CPU of its thread, ``run_wall``, ``run_cpu``) against in-process, and the overhead per task = (workers × wall −
    Σ run time in the workers) / tasks; then the round trip of ``noop_tasks`` empty tasks (0: skipped). ``repeats``:
    passes of each, the configurations taking turns, the fastest kept (the one a busy machine disturbed least);
    ``each_round()``, if given, is called after each round's passes (the cluster idle) and its returns are kept in
    ``out["rounds"]`` (e.g. another measurement that should meet the same load)."""
    stream = stream or sys.stdout
    items = []
    for v in spec.variants():
        try:
            spec.scene_for(v.values)
            items.append((v.run_id, v.values))
        except SceneError:
            pass
    if not items:
        raise SweepError("no valid variant to measure")
    unknown = [c for c in configs if c not in MEASURE_CONFIGS]
    if unknown:
        raise SweepError(f"measure: unknown configuration(s) {unknown}; allowed: {', '.join(MEASURE_CONFIGS)}")
    n = len(items)
    payload = spec.payload()
    out: dict = {"runs": n, "repeats": max(1, int(repeats))}
    run_chunk(payload, items[:1])  # warm-up: imports, compiled kernels, first-call costs
    rounds = max(1, int(repeats))

    def one_pass(client, bb, ws=None, workers_=1):
        return _pass_figures(n, *_timed_rows(payload, items, client, bb, worker_addrs=ws), workers=workers_)

    def fastest(passes):
        return max(passes, key=lambda o: o["runs_per_s"])

    before = fastest([one_pass(None, 1) for _ in range(rounds)])
    t0 = time.perf_counter()
    client, cluster, nw, mode = _dask_client(workers, scheduler)
    out["mode"], out["workers"] = mode, nw
    b = batch or max(1, math.ceil(n / (4 * nw)))
    out["batch"] = b
    try:
        client.run(run_chunk, payload, items[:1])  # the same warm-up in every worker
        out["startup"] = time.perf_counter() - t0
        addrs = sorted(client.scheduler_info()["workers"])
        passes: dict = {label: [] for label in configs}
        out["rounds"] = []
        for _ in range(rounds):  # (the configurations in turn: a load that changes meets them all)
            for label in configs:
                which, bb = MEASURE_CONFIGS[label]
                ws = addrs[:1] if which == "one" else None
                passes[label].append(one_pass(client, bb or b, ws, 1 if ws else nw))
            if each_round is not None:
                out["rounds"].append(each_round())
        for label in configs:
            out[label] = fastest(passes[label])
        if noop_tasks:
            t0 = time.perf_counter()
            futs = client.map(_noop, range(noop_tasks), pure=False)
            client.gather(futs)
            out["noop_per_task"] = (time.perf_counter() - t0) / noop_tasks
            del futs
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    after = fastest([one_pass(None, 1) for _ in range(rounds)])
    out["serial_before"], out["serial_after"] = before, after
    out["serial"] = serial = {k: (before[k] + after[k]) / 2 for k in ("wall", "run_wall", "run_cpu")}
    serial["runs_per_s"] = n / serial["wall"]
    out["serial_wall"], out["serial_run_sum"] = serial["wall"], serial["run_wall"] * n
    out["serial_runs_per_s"] = serial["runs_per_s"]
    for label in configs:
        o = out[label]
        o["speedup"] = o["runs_per_s"] / serial["runs_per_s"]  # over this process
        o["run_wall_ratio"] = o["run_wall"] / serial["run_wall"]  # a run's cost in a worker / in-process
        o["run_cpu_ratio"] = o["run_cpu"] / serial["run_cpu"] if serial["run_cpu"] > 0 else math.nan
    if "one_worker" in out and "all_workers" in out:
        out["scaling_efficiency"] = out["all_workers"]["runs_per_s"] / (nw * out["one_worker"]["runs_per_s"])
    if "all_workers" in out and "batched" in out:
        out["batched_speedup"] = out["batched"]["runs_per_s"] / out["all_workers"]["runs_per_s"]
    stream.write("\n".join(measure_lines(out, spec.name)) + "\n")
    return out


def measure_lines(out: dict, name: str = "") -> list:
    """The printed report of :func:`measure`."""
    n, nw, serial = out["runs"], out["workers"], out["serial"]
    titles = {"one_worker": "Dask, 1 worker, 1 run per task", "all_workers": f"Dask, {nw} workers, 1 run per task",
              "batched": f"Dask, {nw} workers, {out['batch']} runs per task",
              "one_worker_auto": "Dask, 1 worker, auto batch", "all_workers_auto": f"Dask, {nw} workers, auto batch"}
    lines = [
        f"measured on {os.cpu_count()} cores, {out['mode']}: {n} runs of sweep {name} "
        f"(mean run {serial['run_wall'] * 1e3:.2f} ms in-process)"
        + (f"; the fastest of {out['repeats']} passes each" if out.get("repeats", 1) > 1 else ""),
        f"  cluster start + connect + warm-up {out['startup']:9.2f} s (not in the figures below)",
        f"  {'in-process, serial (no Dask)':<34s}{serial['runs_per_s']:9.2f} runs/s  {serial['wall']:7.2f} s  "
        f"(before the cluster {out['serial_before']['runs_per_s']:.2f}, after {out['serial_after']['runs_per_s']:.2f}); "
        f"a run {serial['run_wall'] * 1e3:.2f} ms wall, {serial['run_cpu'] * 1e3:.2f} ms CPU",
    ]
    for label, title in titles.items():
        if label not in out:
            continue
        o = out[label]
        extra = ""
        if label == "all_workers" and "scaling_efficiency" in out:
            extra = f"  efficiency {out['scaling_efficiency']:.2f}"
        if label == "batched" and "batched_speedup" in out:
            extra = f"  batched speed-up {out['batched_speedup']:.2f}x"
        lines.append(f"  {title:<34s}{o['runs_per_s']:9.2f} runs/s  {o['wall']:7.2f} s  {o['tasks']:5d} tasks  "
                     f"x{o['speedup']:.2f} of in-process  a run {o['run_wall'] * 1e3:.2f} ms wall "
                     f"({o['run_wall_ratio']:.2f}x), {o['run_cpu'] * 1e3:.2f} ms CPU ({o['run_cpu_ratio']:.2f}x)  "
                     f"overhead {o['overhead_per_task'] * 1e3:.2f} ms/task{extra}")
    if "noop_per_task" in out:
        lines.append(f"  empty task round trip             {out['noop_per_task'] * 1e3:9.2f} ms/task")
    lines.append("  (a run's cost: mean over the runs, inside the worker, against in-process; "
                 "overhead per task = (workers x wall - run time in the workers) / tasks)")
    return lines


# ------------------------------------------------------------------------------------------
# command line
# ------------------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="gyro-sim sweep",
        description="Run every variant of a scene (grid and/or Monte Carlo) on Dask; results as Parquet + PNG. "
                    "SOURCE is a sweep file (config/sweep_*.yaml by name, or a path), a scene (built-in name or "
                    "path), or a results .parquet file (summarise and plot it).",
        epilog="Examples: gyro-sim sweep sweep_psi_rate;  gyro-sim sweep nutation_oblate --vary "
               "controller.period=0.004:0.02:17 --metric 't=time_below(theta_deg,0.1)' --set duration=3;  "
               "gyro-sim sweep free_rotor --random initial.theta=uniform(0,0.5) --samples 100 --workers 2.")
    p.add_argument("source", metavar="SOURCE")
    p.add_argument("--vary", metavar="KEY=START:STOP:N", action="append", default=[],
                   help="grid axis: START:STOP:N (N values, ends included), START:STOP:N:log, or v1,v2,...; "
                        "START/STOP may be lists [a,b] for a vector key (repeatable)")
    p.add_argument("--random", metavar="KEY=DIST", action="append", default=[],
                   help="Monte Carlo key: uniform(a,b), normal(mu,sigma), loguniform(a,b), randint(a,b), "
                        "choice(v1,...) (repeatable; with --samples)")
    p.add_argument("--samples", metavar="N", type=int, default=None, help="random draws (per grid point)")
    p.add_argument("--seed", metavar="S", type=int, default=None, help="seed of the random draws (default 0)")
    p.add_argument("--set", metavar="KEY=VALUE", action="append", default=[],
                   help="fixed override of every variant, e.g. duration=1.0 (repeatable)")
    p.add_argument("--metric", metavar="[NAME=]FUNC(ARGS)", action="append", default=[],
                   help="metric column (repeatable; adds to the sweep file's): final(Q), max(Q), min(Q), mean(Q), "
                        "max_abs(Q), drift(Q), time_below(Q,x), time_above(Q,x), settle_below(Q,x), wall_time(), "
                        "steps(), k(NAME[,x]); aliases " + ", ".join(METRIC_ALIASES))
    p.add_argument("--series", metavar="Q[,Q...]", default=None,
                   help="keep these time series per run (e.g. theta_deg,spin); 'none' to drop the file's")
    p.add_argument("--workers", metavar="N", type=int, default=None,
                   help="local Dask worker processes (default: all cores); 0 = run in this process without Dask")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="an existing Dask scheduler (tcp://host:port or a scheduler file) instead of a local cluster")
    p.add_argument("--batch", metavar="N|auto", default="auto",
                   help="variants per task; auto (default): each task sized to last about 0.25 s at the run time "
                        "seen so far, the tasks shrinking towards the end so the workers finish together")
    p.add_argument("--out", metavar="FILE", type=Path, default=None,
                   help="results table (default runs/sweep_<name>.parquet; the plot goes beside it as .png)")
    p.add_argument("--no-resume", action="store_true", help="run everything again (default: skip what FILE holds)")
    p.add_argument("--retry-failed", action="store_true", help="run the failed variants again when resuming")
    p.add_argument("--no-plot", action="store_true", help="no PNG")
    p.add_argument("--dry-run", action="store_true", help="list and validate the variants; run nothing")
    p.add_argument("--measure", action="store_true",
                   help="time the runs in this process, with 1 worker and all cores (1 run per task, N per task, "
                        "auto), the overhead per task and a run's cost in a worker (no results file)")
    p.add_argument("--quiet", action="store_true", help="no progress bar, no table")
    return p


def _apply_cli(spec: SweepSpec, args) -> SweepSpec:
    try:
        grid = {a.key: a for a in spec.grid}
        for text in args.vary:
            k, v = _split_assignment(text, "--vary")
            grid[k] = parse_axis(k, v)
        rnd = {r.key: r for r in spec.random}
        for text in args.random:
            k, v = _split_assignment(text, "--random")
            rnd[k] = parse_random(k, v)
        fixed = dict(spec.set)
        for text in args.set:
            k, v = _split_assignment(text, "--set")
            fixed[k] = _parse_value(v)
        mets = {} if spec.default_metrics else {m.name: m for m in spec.metrics}
        for text in args.metric:
            m = parse_metric(text)
            mets[m.name] = m
        spec.grid, spec.random, spec.set = list(grid.values()), list(rnd.values()), fixed
        if args.metric:
            spec.metrics, spec.default_metrics = list(mets.values()), False
        if args.samples is not None:
            spec.samples = args.samples
        if args.seed is not None:
            spec.seed = args.seed
        if args.series is not None:
            spec.series = [] if args.series.strip().lower() == "none" else [
                s.strip() for s in args.series.split(",") if s.strip()]
        return spec.check()
    except SweepError:
        raise


def _print_table(rows: list, spec_meta: dict, stream, limit: int = 60) -> None:
    keys = list(spec_meta.get("grid", [])) + list(spec_meta.get("random", {}))
    names = list(spec_meta.get("metrics", {}))
    head = ["#"] + keys + names + ["status"]
    lines = [head]
    for r in rows[:limit]:
        cells = [str(r["index"])] + [_fmt(r.get(k)) for k in keys]
        cells += [_fmt(r.get(n)) if r["status"] == "ok" else "-" for n in names]
        cells.append(r["status"])
        lines.append(cells)
    widths = [max(len(line[i]) for line in lines) for i in range(len(head))]
    for line in lines:
        stream.write("  " + "  ".join(c.rjust(w) for c, w in zip(line, widths)) + "\n")
    if len(rows) > limit:
        stream.write(f"  ... {len(rows) - limit} more rows in the results file\n")
    bad = [r for r in rows if r["status"] != "ok"]
    for r in bad[:10]:
        stream.write(f"  #{r['index']} {r['status']}: {r.get('error')}\n")
    if len(bad) > 10:
        stream.write(f"  ... {len(bad) - 10} more failed or invalid variants\n")


def _write(stream, text: str) -> None:
    from gyro_sim.apps.console import _write as write  # one encoding-safe writer for every command

    write(stream, text)


def _require_extras(parquet: bool, in_process: bool, what: str = "gyro-sim sweep") -> None:
    """Raise :class:`gyro_sim.extras.MissingExtra` (one line naming the ``sweep`` extra) if what a sweep will
    use is not installed: pyarrow where results are read or written (``parquet``), Dask unless it runs
    ``in_process`` (``--workers 0``). Checked before any variant runs (a missing pyarrow would otherwise end
    the sweep after its last run); tqdm is optional (no progress bar without it)."""
    from gyro_sim.common.extras import missing, require

    modules = ("pyarrow",) * parquet + ("dask", "distributed") * (not in_process)
    dask_gone = not in_process and {"dask", "distributed"} & set(missing("sweep", modules))
    require("sweep", what, modules, hint="; or --workers 0 to run in this process" if dask_gone else "")


def _check_command_extras(args) -> None:
    """What ``gyro-sim sweep`` with these arguments needs of the ``sweep`` extra (see :func:`_require_extras`)."""
    if args.source.endswith(".parquet"):
        _require_extras(True, True)
    elif args.measure:
        _require_extras(False, False, "gyro-sim sweep --measure")
    elif not args.dry_run:
        _require_extras(True, args.workers == 0 and not args.scheduler)


def sweep_main(argv: Optional[Sequence[str]] = None) -> int:
    """``gyro-sim sweep``: returns the exit status (0 done, 1 every run failed, 2 bad sweep/usage, 130 interrupted)."""
    from gyro_sim.common.extras import MissingExtra

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        _check_command_extras(args)
    except MissingExtra as e:
        _write(sys.stderr, f"error: {e}\n")
        return EXIT_USAGE
    try:
        if args.source.endswith(".parquet"):
            rows, meta = read_results(args.source)
            if not args.quiet:
                _print_table(rows, meta, sys.stdout)
            if not args.no_plot and rows:
                png = Path(args.source).with_suffix(".png")
                plot_sweep(rows, meta, png)
                _write(sys.stdout, f"plot: {png}\n")
            return EXIT_OK
        spec = load_sweep(args.source)
        spec = _apply_cli(spec, args)
        args.batch = _batch_arg(args.batch)
        if args.workers is not None and args.workers < 0:
            raise SweepError(f"--workers {args.workers}: must be ≥ 0")
        variants = spec.variants()
        if args.dry_run:
            n_bad = 0
            for v in variants:
                try:
                    spec.scene_for(v.values)
                    status = "ok"
                except SceneError as e:
                    status, n_bad = f"invalid: {e}", n_bad + 1
                _write(sys.stdout, f"  #{v.index} {v.run_id} " + " ".join(f"{k}={_fmt(x)}" for k, x in v.values.items())
                       + f"  {status}\n")
            _write(sys.stdout, f"sweep {spec.name}: {len(variants)} variants, {n_bad} invalid; metrics: "
                               + ", ".join(m.spec for m in spec.metrics) + "\n")
            return EXIT_OK
        if args.measure:
            measure(spec, workers=args.workers or None, batch=args.batch if args.batch != "auto" else None,
                    scheduler=args.scheduler)
            return EXIT_OK
        out = args.out or Path("runs") / f"sweep_{spec.name}.parquet".replace("sweep_sweep_", "sweep_")
        res = run_sweep(spec, out=out, workers=args.workers, scheduler=args.scheduler, batch=args.batch,
                        resume=not args.no_resume, retry_failed=args.retry_failed, progress=not args.quiet)
    except (SweepError, SceneError) as e:
        _write(sys.stderr, f"error: {e}\n")
        return EXIT_USAGE
    meta = dict(spec.meta())
    if not args.quiet:
        _print_table(res.rows, meta, sys.stdout)
    rate = f", {res.runs_per_second:.2f} runs/s" if res.n_run and res.wall > 0 else ""
    _write(sys.stdout,
           f"sweep {spec.name}: {res.n_total} variants ({res.n_run} run now, {res.n_skipped} from {res.out}), "
           f"{res.n_failed} failed, {res.n_invalid} invalid; {res.wall:.2f} s{rate}"
           + (f" on {res.mode}" if res.mode else "")
           + (f" in {res.tasks} tasks" if res.workers and res.mode != "in-process" and res.tasks else "") + "\n")
    _write(sys.stdout, f"results: {res.out}\n")
    if not args.no_plot and res.rows:
        png = res.out.with_suffix(".png")
        plot_sweep(res.rows, meta, png)
        _write(sys.stdout, f"plot: {png}\n")
    if res.interrupted:
        _write(sys.stderr, f"interrupted: {len(res.rows)} of {res.n_total} done; run the same command again to resume\n")
        return EXIT_INTERRUPTED
    if res.rows and all(r["status"] != "ok" for r in res.rows):
        return EXIT_FAILED
    return EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(sweep_main())
