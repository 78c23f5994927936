"""The values and axes of a sweep (:mod:`gyro_sim.apps.sweep`): :class:`SweepError`, values from the command line
or YAML, grid axes (:func:`parse_axis`) and random variables (:func:`parse_random`).
"""
from __future__ import annotations

import json
import math
import re
import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

_FIXED_COLUMNS = ("run_id", "index", "sample", "seed", "status", "error", "wall_time_run", "worker", "gyro_sim_version")


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
