"""A sweep's definition (:mod:`gyro_sim.apps.sweep`): :class:`Variant`, :class:`SweepSpec`, the built-in sweep files
and their loading (:func:`spec_from_dict`, :func:`load_sweep`).
"""
from __future__ import annotations

import copy
import hashlib
import itertools
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

from gyro_sim import __version__
from gyro_sim.apps.sweep_axes import SweepError, _is_number, _parse_value, _plain, parse_axis, parse_random
from gyro_sim.apps.sweep_metrics import DEFAULT_METRICS, QUANTITIES, parse_metric
from gyro_sim.scenes.scene import SceneError, apply_overrides, builtin_scenes, config_dir, scene_from_dict
from gyro_sim.scenes.scene_text import parse_scene_text, read_scene_file


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
    # the theory's values drawn on the plot: {label, x or y, metric (with y)}, a value a number or [-]k(NAME)
    marks: list = field(default_factory=list)
    mark_values: list = field(default_factory=list)  # the marks with their values (check())

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
        self.mark_values = [self._mark(m, names) for m in self.marks]
        return self

    def _mark(self, mark, metric_names) -> dict:
        """A mark of the plot with its value: {label, x: value} (a line across every panel at that value of the
        first grid key) or {label, y: value, metric: NAME} (across that metric's panel); a value is a number or
        ``k(NAME)`` / ``-k(NAME)`` of the base scene (sweep_metrics._k_metric)."""
        if not isinstance(mark, dict) or not isinstance(mark.get("label"), str) or \
                len({"x", "y"} & set(mark)) != 1 or set(mark) - {"label", "x", "y", "metric"}:
            raise SweepError(f"marks: {mark!r}: expected {{label: TEXT, x: VALUE}} or {{label: TEXT, y: VALUE, "
                             f"metric: NAME}}")
        axis = "x" if "x" in mark else "y"
        if axis == "y" and mark.get("metric") not in metric_names:
            raise SweepError(f"marks: {mark['label']!r}: metric = {mark.get('metric')!r}; allowed: "
                             f"{', '.join(metric_names)}")
        value = mark[axis]
        if not _is_number(value):
            text = str(value).strip()
            sign = -1.0 if text.startswith("-") else 1.0
            m = parse_metric(text.lstrip("-"))
            if m.func != "k":
                raise SweepError(f"marks: {mark['label']!r}: {axis} = {value!r}: a number or [-]k(NAME)")
            try:
                value = sign * m.evaluate(None, self.scene_for({}))
            except (ValueError, SceneError) as e:
                raise SweepError(f"marks: {mark['label']!r}: {axis} = {text}: {e}") from None
        return {"label": mark["label"], axis: float(value), **({"metric": mark["metric"]} if axis == "y" else {})}

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
                "marks": list(self.mark_values), "gyro_sim_version": __version__}


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
               "series_points", "marks"}


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
                         description=str(d.get("description", "") or ""), marks=list(d.get("marks") or []))
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
