"""The metrics of a sweep (:mod:`gyro_sim.apps.sweep`): quantities of a run, metric functions and aliases,
:class:`Metric` and :func:`parse_metric`.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Callable, Optional, Sequence

import numpy as np

from gyro_sim.apps.sweep_axes import _FIXED_COLUMNS, SweepError, _is_number, _parse_value, _split_top


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
            "r_minus_deg", "r_plus_deg", "sampling_factor", "time_to_deg", "h_star")


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
    if name == "h_star":  # s: the control period where the sampled drive changes sign, Λh = π (docs/sweeps.md)
        return math.pi * m.rotor.J / _initial_L(scene)
    if name == "time_to_deg":
        if len(xs) != 1:
            raise ValueError("k(time_to_deg, x) takes one angle in degrees")
        return float(m.time_to_theta(scene.initial.theta, math.radians(xs[0]), L0=_initial_L(scene)))
    raise ValueError(f"k({name}): allowed {', '.join(_K_ATTRS)}")


#: units of the quantities (plot labels; "1": a ratio)
QUANTITY_UNITS = {"t": "s", "spin": "rad/s", "spin_rev_s": "rev/s", "omega_norm": "rad/s", "theta": "rad",
                  "theta_deg": "deg", "psi": "rad", "phi": "rad", "L_norm": "N·m·s", "L_x": "N·m·s", "L_y": "N·m·s",
                  "L_z": "N·m·s", "energy": "J", "torque_norm": "N·m"}
#: units of the k(NAME) quantities ("1": a ratio, "": a count)
K_UNITS = {"p": "1", "s": "1", "p_star": "1", "V": "1/s", "Lam0": "rad/s", "W0": "rad/s", "kappa": "1",
           "delta": "1", "q": "1", "equilibria": "", "cycles": "", "r_minus_deg": "deg", "r_plus_deg": "deg",
           "sampling_factor": "1", "time_to_deg": "s", "h_star": "s"}


def metric_unit(text: str) -> str:
    """The unit of a metric given as ``FUNC(ARGS)`` (or an alias): "s", "deg", "1" (a ratio), "" (a count or
    unknown)."""
    try:
        m = parse_metric(text)
    except SweepError:
        return ""
    if m.func == "k":
        return K_UNITS.get(str(m.args[0]), "")
    if m.func in ("time_below", "time_above", "settle_below", "wall_time"):
        return "s"
    if m.func == "drift":
        return "1"
    if m.func == "steps" or not m.args:
        return ""
    q = str(m.args[0])
    return QUANTITY_UNITS.get(q, "A" if q.startswith("current_") else "")


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
