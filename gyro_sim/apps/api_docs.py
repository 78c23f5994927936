"""The API reference of gyro_sim and gyro_ctl: HTML generated from the docstrings with pdoc (``gyro-sim api-docs``).

Why pdoc (docs/api.md): it is one pure-Python package (the ``docs`` extra), needs no configuration tree,
documents the packages as Python imports them (``__all__``, the lazily loaded names of ``gyro_sim``, signatures
and type hints as they are), reads the docstrings' reStructuredText roles (``:func:``, ``:class:``) and
Markdown, links the names it finds, and can render math.

What is documented is the public API, a curated list (:data:`PUBLIC`): the names ``gyro_sim`` exports, the modules
that hold them and the ones the README and docs/ tell a user to import (scenes, runs, bags, plots, the closed forms
of the physics, the control laws and their parameters, the pytest kit ``gyro_sim.testing``). The machinery behind
them (compiled kernels, steppers, the CLI, benchmarks, the ROS nodes) is left out: it changes without notice. The
landing page (``index.html``) is a short tour (:data:`TOUR`) with the list of modules.

What pdoc would show by itself and the reference should not (:func:`build` fixes each before rendering):

* a scene field's type as pydantic builds it, ``Annotated[float, BeforeValidator(func=<function _number at 0x…>),
  FieldInfo(…)]``, and ``= PydanticUndefined`` for a required field: a field is shown with its plain type
  (``float``, ``list[float]``), its default if it has one, its description (meaning and SI unit, from the
  field's docstring) and the values allowed (``≥ 1e-06, ≤ 10``);
* reStructuredText's ``text::`` before a literal block (pdoc keeps the two colons): turned into ``text:`` as
  reST renders it.

A module whose import needs an optional dependency that is not installed is left out and named in
:attr:`ApiDocs.skipped` with the extra that would bring it, instead of failing the build. Any other import error
fails it. pdoc's own warnings (a docstring it cannot convert, an annotation it cannot read) are collected in
:attr:`ApiDocs.warnings`; test/test_api_docs.py requires none.
"""
from __future__ import annotations

import contextlib
import importlib
import inspect
import re
import tempfile
import time
import typing
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional, Sequence

from gyro_sim.common.extras import extra_of, require

__all__ = ["PUBLIC", "TOUR", "ApiDocs", "build", "plain_type", "field_constraints"]

#: the public modules, in the order of the landing page → what each holds (one line)
PUBLIC: dict = {
    "gyro_sim": "the names a notebook uses: load_scene, run, Simulator, RunResult, Scene, read_bag",
    "gyro_sim.scenes.scene": "the scene file: every section and field, its meaning, unit and allowed values",
    "gyro_sim.scenes.effect_config": "the scene's effects section: unbalance, gas drag, magnetizable body, "
                                     "flywheel, damper",
    "gyro_sim.engine.simulate": "runs and their results: run, Simulator (step by step), RunResult",
    "gyro_sim.io.recording": "bags: record a run, read a bag's topics as arrays, bag_info",
    "gyro_sim.io.results": "a recorded bag as a RunResult; RunResult as pandas / xarray",
    "gyro_sim.io.plotting": "the PNG plots of a run (plot_run)",
    "gyro_sim.physics.closed_forms": "closed-form results of the papers the tests reproduce (docs/physics.md)",
    "gyro_sim.physics.conductor": "eddy-current response of the conducting rotor (transfer function, modes)",
    "gyro_sim.physics.frames": "frames and angles: the L-frame, Euler angles ψ, θ, φ",
    "gyro_sim.physics.constants": "physical constants (μ0)",
    "gyro_sim.common.extras": "the optional dependencies (pip extras) and the message for a missing one",
    "gyro_sim.testing": "the pytest kit: test your controller against the simulator (gyro_bench fixture)",
    "gyro_ctl": "control laws as pure functions of the rotor state",
    "gyro_ctl.laws": "the laws (spinup, psi_switching, reorient, ...), make_law, ControlInput",
    "gyro_ctl.config": "the scene's controller section: each law's parameters with units",
    "gyro_ctl.reorient": "reorientation of the kinetic moment along axis-parallel paths ([K] §2)",
}

#: docstring flavour: reStructuredText (``code``, :func:`x`, ``::`` blocks), converted by pdoc to Markdown
DOCFORMAT: typing.Literal["restructuredtext"] = "restructuredtext"

#: the landing page's tour (Markdown; links to the module pages)
TOUR = """\
# gyro_sim API reference

gyro_sim simulates the rotor of an electrodynamically controlled gyroscope: a conducting rotor spun and steered by
the rotating magnetic fields of three stators. Everything is in SI units (m, kg, s, A, T, S/m, rad); vectors are
in the case frame unless a name says otherwise (the frames are in docs/physics.md of the repository).

## A tour

1. **Load a scene and run it.** A scene (a YAML file or a built-in name) says everything about a run:

    ```python
    import gyro_sim
    scene = gyro_sim.load_scene("spinup_thin_shell")   # gyro_sim.builtin_scenes() lists the names
    result = gyro_sim.run(scene, duration=2.0)           # a RunResult: time series as NumPy arrays
    print(result.summary())
    result.t, result.L, result.euler[:, 1]               # s, N·m·s (case frame), θ in rad
    ```

   [`gyro_sim`](gyro_sim.html) holds these names; [`run`](gyro_sim/engine/simulate.html#run) and
   [`RunResult`](gyro_sim/engine/simulate.html#RunResult) are documented in
   [`gyro_sim.engine.simulate`](gyro_sim/engine/simulate.html).
2. **Change a scene.** Every section and field of the scene file, with its meaning, unit and allowed values, is
   in [`gyro_sim.scenes.scene`](gyro_sim/scenes/scene.html) (start at `Scene`); the effects (unbalance, gas drag,
   magnetizable body, flywheel, damper) in [`gyro_sim.scenes.effect_config`](gyro_sim/scenes/effect_config.html).
   A scene is validated when it is loaded: a wrong value is refused with one line naming the key.
3. **Step it yourself.** [`Simulator`](gyro_sim/engine/simulate.html#Simulator) advances a scene by a time and
   takes stator commands in between (`Simulator.advance`, `Simulator.set_stator`).
4. **Control it.** A law of [`gyro_ctl.laws`](gyro_ctl/laws.html) is a pure function of the state
   ([`ControlInput`](gyro_ctl/laws.html#ControlInput)) that returns stator commands; its parameters are the
   scene's `controller` section ([`gyro_ctl.config`](gyro_ctl/config.html)). The same function runs inside
   `gyro_sim.run` and in the ROS controller node.
5. **Record, read and plot.** [`gyro_sim.io.recording`](gyro_sim/io/recording.html) writes and reads bags,
   [`gyro_sim.io.results`](gyro_sim/io/results.html) turns a bag back into a RunResult (and a RunResult into
   pandas or xarray), [`gyro_sim.io.plotting`](gyro_sim/io/plotting.html) draws the PNG plots.
6. **Check the physics.** [`gyro_sim.physics.closed_forms`](gyro_sim/physics/closed_forms.html) and
   [`gyro_sim.physics.conductor`](gyro_sim/physics/conductor.html) hold the closed-form results of the papers
   that the tests reproduce.
7. **Test your own controller** in your pytest suite with the `gyro_bench` fixture of
   [`gyro_sim.testing`](gyro_sim/testing.html).

## Modules
"""


@dataclass
class ApiDocs:
    """What :func:`build` wrote: ``out`` (open ``out/index.html``), the modules documented, those left out
    (module → (extra, the missing module)) and pdoc's warnings (one string each)."""

    out: Path
    modules: list = field(default_factory=list)
    skipped: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)


def _importable(names: Sequence[str]) -> tuple:
    """(modules that import, {module: (extra, missing module)} for those needing a missing optional dependency).

    The names of a module's ``__all__`` are looked up, so that those a module loads lazily are in its namespace.

    Other import errors propagate: they are bugs, not a missing extra."""
    ok, skipped = [], {}
    for name in names:
        try:
            module = importlib.import_module(name)
            for public in getattr(module, "__all__", ()):  # load the names a module provides on first use
                getattr(module, public, None)  # (PEP 562: gyro_sim.run, gyro_sim.Scene...), as pdoc reads __dict__
        except ModuleNotFoundError as exc:
            top = (exc.name or "").split(".")[0]
            extra = extra_of(top)
            if extra is None:
                raise
            skipped[name] = (extra, top)
        else:
            ok.append(name)
    return ok, skipped


# --- clean types and defaults of pydantic fields ----------------------------------------------------------------
def plain_type(tp):
    """``tp`` without ``Annotated[...]`` metadata at any depth (``list[Annotated[float, ...]]`` → ``list[float]``):
    the type a reader writes, not pydantic's validators and field infos."""
    origin = typing.get_origin(tp)
    if origin is typing.Annotated:
        return plain_type(typing.get_args(tp)[0])
    args = typing.get_args(tp)
    if origin is None or not args:
        return tp
    new = tuple(plain_type(a) for a in args)
    if new == args:
        return tp
    if origin is typing.Union:
        return typing.Union[new]
    if origin is typing.Literal:
        return tp
    try:
        return origin[new]  # list[...], dict[...], tuple[...]
    except TypeError:
        return typing.__dict__.get(getattr(tp, "_name", "") or "", tp)[new]


_BOUNDS = (("gt", ">"), ("ge", "≥"), ("lt", "<"), ("le", "≤"), ("min_length", "length ≥ {}"),
           ("max_length", "length ≤ {}"))


def _bounds(metadata) -> list:
    out = []
    for m in metadata:
        for attr, sym in _BOUNDS:
            v = getattr(m, attr, None)
            if v is not None:
                out.append(sym.format(v) if "{}" in sym else f"{sym} {v:g}" if isinstance(v, float) else f"{sym} {v}")
    return out


def field_constraints(info) -> str:
    """The values a pydantic field allows, in words (``≥ 1e-06, ≤ 10``; ``length 3; each item ≥ 1e-15, ≤ 1e+06``),
    or ''.

    Bounds on the field itself and, for a list, on its items."""
    own = _bounds(info.metadata)
    items = []
    ann = info.annotation
    while typing.get_origin(ann) is typing.Union:  # Optional[...]: look inside
        ann = next((a for a in typing.get_args(ann) if a is not type(None)), ann)
        if typing.get_origin(ann) is typing.Annotated:
            own += _bounds(typing.get_args(ann)[1:])
            ann = typing.get_args(ann)[0]
    if typing.get_origin(ann) is list:
        inner = typing.get_args(ann)[0] if typing.get_args(ann) else None
        if typing.get_origin(inner) is typing.Annotated:
            items = _bounds(typing.get_args(inner)[1:])
    for n in range(1, 10):
        if f"length ≥ {n}" in own and f"length ≤ {n}" in own:
            own = [b for b in own if not b.startswith("length")] + [f"length {n}"]
    text = ", ".join(own)
    if items:
        text = f"{text}; each item {', '.join(items)}" if text else f"each item {', '.join(items)}"
    return text


def _append(docstring: str, line: str) -> str:
    return (docstring.rstrip() + "\n\n" if docstring else "") + line


def _clean_model(cls_doc) -> None:
    """A pydantic model's fields as a reader wants them (see the module docstring); nested classes too."""
    import pdoc.doc
    from pydantic import BaseModel

    obj = cls_doc.obj
    fields = obj.model_fields if isinstance(obj, type) and issubclass(obj, BaseModel) else {}
    if fields:
        # (a model without a docstring: pdoc shows BaseModel's)
        if cls_doc.docstring.strip() == (inspect.getdoc(BaseModel) or "").strip():
            cls_doc.docstring = ""
        cls_doc.bases = [("pydantic", "BaseModel", "pydantic.BaseModel")]  # (not the private _Strict)
    for member in cls_doc.members.values():
        if isinstance(member, pdoc.doc.Class):
            _clean_model(member)
        if not isinstance(member, pdoc.doc.Variable) or member.name not in fields:
            continue
        info = fields[member.name]
        member.annotation = plain_type(info.annotation)
        extra = []
        if info.is_required():
            member.default_value = pdoc.doc.empty  # (pydantic's PydanticUndefined)
            extra.append("required")
        elif info.default_factory is not None:
            member.default_value = pdoc.doc.empty
            extra.append(f"default: {getattr(info.default_factory, '__name__', 'computed')}()")
        allowed = field_constraints(info)
        if allowed:
            extra.append(f"allowed: {allowed}")
        if extra:
            member.docstring = _append(member.docstring, f"({'; '.join(extra)})")


def _clean(module_doc) -> None:
    """The module's pydantic models (:func:`_clean_model`) and its type aliases (``Vec3 = Annotated[...]``: shown as
    the plain type and the values allowed)."""
    import pdoc.doc
    from pydantic.fields import FieldInfo

    for member in module_doc.members.values():
        if isinstance(member, pdoc.doc.Class):
            _clean_model(member)
        elif isinstance(member, pdoc.doc.Variable) and typing.get_origin(member.default_value) is typing.Annotated:
            alias = member.default_value
            allowed = field_constraints(FieldInfo.from_annotation(typing.cast(type, alias)))
            member.default_value = plain_type(alias)
            if allowed:
                member.docstring = _append(member.docstring, f"(allowed: {allowed})")


# --- reST literal blocks --------------------------------------------------------------------------------------
_LITERAL = re.compile(r"(?m)(\S?)(\s*)::[ \t]*$")


def rest_literal_markers(text: str) -> str:
    """reST's ``text::`` before a literal block as reST renders it: ``text:`` (``text ::`` and a line of ``::``
    alone: nothing). pdoc's reST reader leaves the two colons in."""
    return _LITERAL.sub(lambda m: m.group(1) + ("" if m.group(2) or not m.group(1) else ":"), text)


@contextlib.contextmanager
def _rest_literals():
    import pdoc.docstrings

    rst = pdoc.docstrings.rst
    pdoc.docstrings.rst = lambda contents, source_file: rst(rest_literal_markers(contents), source_file)
    pdoc.docstrings.convert.cache_clear()
    try:
        yield
    finally:
        pdoc.docstrings.rst = rst
        pdoc.docstrings.convert.cache_clear()


# --- the landing page --------------------------------------------------------------------------------------------
_INDEX = """\
{% extends "default/index.html.jinja2" %}
{% block title %}gyro_sim API reference{% endblock %}
{% block nav %}
    <h2>Public API</h2>
    <ul>
        {% for submodule in all_modules %}
            <li><a href="{{ submodule.replace(".","/") }}.html">{{ submodule }}</a></li>
        {% endfor %}
    </ul>
{% endblock %}
{% block content %}
    <header class="pdoc">
        {% if search %}
            <input type="search" placeholder="Search the gyro_sim API..." aria-label="search box">
        {% endif %}
    </header>
    <main class="pdoc">TOUR_HTML</main>
    {% if search %}
        {% include "search.html.jinja2" %}
    {% endif %}
{% endblock %}
"""


def _tour_html(names: Sequence[str]) -> str:
    from pdoc.render_helpers import to_html

    rows = "\n".join(f"- [`{n}`]({n.replace('.', '/')}.html): {PUBLIC.get(n, '')}" for n in names)
    return str(to_html(TOUR + "\n" + rows + "\n"))


def _say(progress: Optional[Callable[[str], None]], line: str) -> None:
    if progress is not None:
        progress(line)


def build(out: Path | str, modules: Sequence[str] = tuple(PUBLIC),
          progress: Optional[Callable[[str], None]] = None) -> ApiDocs:
    """Write the HTML reference of ``modules`` (default: the public API, :data:`PUBLIC`) to ``out`` (made if
    needed): a page per module, ``index.html`` (the tour) and the search index. ``progress`` gets one line per
    step (a module imported and rendered, the index, the totals). Raises
    :class:`gyro_sim.common.extras.MissingExtra` without pdoc."""
    require("docs", "the API reference (gyro-sim api-docs)")
    import pdoc
    import pdoc.doc
    import pdoc.render

    start = time.perf_counter()
    out = Path(out)
    pdoc_dir = str(Path(pdoc.__file__).parent)
    with warnings.catch_warnings(record=True) as caught, tempfile.TemporaryDirectory() as templates, \
            _rest_literals():
        warnings.simplefilter("always")
        _say(progress, f"importing {len(modules)} modules")
        names, skipped = _importable(list(modules))
        (Path(templates) / "index.html.jinja2").write_text(_INDEX.replace("TOUR_HTML", _tour_html(names)),
                                                           encoding="utf-8")
        pdoc.render.configure(docformat=DOCFORMAT, math=False, show_source=True,
                              template_directory=Path(templates),
                              footer_text="gyro_sim API reference (gyro-sim api-docs)")
        docs = {}
        for name in names:
            doc = pdoc.doc.Module(importlib.import_module(name))
            doc.modulename = name  # (gyro_sim.testing is the module gyro_sim.apps.testing: documented by its name)
            _clean(doc)
            docs[name] = doc
        for name, doc in docs.items():  # a package lists its public descendants only (not apps, compiled, ...)
            doc.submodules = [d for n, d in docs.items() if n.startswith(name + ".")]
        pages = {}
        for i, (name, doc) in enumerate(docs.items(), 1):
            pages[name] = pdoc.render.html_module(doc, docs)
            _say(progress, f"[{i}/{len(docs)}] {name}")
        index = pdoc.render.html_index(docs)
        search = pdoc.render.search_index(docs)
        _say(progress, "index and search index")
    for name, html in pages.items():
        page = out / f"{name.replace('.', '/')}.html"
        page.parent.mkdir(parents=True, exist_ok=True)
        page.write_text(html, encoding="utf-8")
    (out / "index.html").write_text(index, encoding="utf-8")
    if search:
        (out / "search.js").write_text(search, encoding="utf-8")
    size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    _say(progress, f"wrote {len(pages) + 1} pages, {size / 1e6:.1f} MB, in {time.perf_counter() - start:.1f} s")
    # (a package's page lists its submodules: pdoc tries those left out again and says it could not import them)
    expected = tuple(f"Couldn't import {name}:" for name in skipped)
    said = [str(w.message) for w in caught
            if str(w.filename).startswith(pdoc_dir) and not (expected and str(w.message).startswith(expected))]
    return ApiDocs(out=out, modules=names, skipped=skipped, warnings=said)
