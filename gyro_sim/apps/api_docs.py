"""The API reference of gyro_sim and gyro_ctl: HTML generated from the docstrings with pdoc (``gyro-sim api-docs``).

Why pdoc (docs/api.md): it is one pure-Python package (the ``docs`` extra), needs no configuration tree,
documents the packages as Python imports them (``__all__``, the lazily loaded names of ``gyro_sim``, signatures
and type hints as they are), reads the docstrings' reStructuredText roles (``:func:``, ``:class:``) and
Markdown, links the names it finds, and can render math. Sphinx or mkdocs(-trings) would need a
configuration tree (``conf.py`` / ``mkdocs.yml``, stub pages) and more dependencies for the same pages.

Every public module is documented: the packages' modules and subpackages whose names have no leading
underscore. pdoc imports each; a module whose import needs an optional dependency that is not installed
(``gyro_sim.ros.*`` and ``gyro_ctl.ros.*`` need rclpy, the ``ros`` extra) is left out and named in
:attr:`ApiDocs.skipped` with the extra that would bring it, instead of failing the build. Any other import
error fails it. pdoc's own warnings (a docstring it cannot convert, an annotation it cannot read) are
collected in :attr:`ApiDocs.warnings`; test/test_api_docs.py requires none.
"""
from __future__ import annotations

import importlib
import pkgutil
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

from gyro_sim.common.extras import extra_of, require

__all__ = ["PACKAGES", "ApiDocs", "build", "public_modules"]

#: the packages documented
PACKAGES = ("gyro_sim", "gyro_ctl")

#: docstring flavour: reStructuredText (``code``, :func:`x`, ``::`` blocks), converted by pdoc to Markdown
DOCFORMAT = "restructuredtext"


@dataclass
class ApiDocs:
    """What :func:`build` wrote: ``out`` (open ``out/index.html``), the modules documented, those left out
    (module → (extra, the missing module)) and pdoc's warnings (one string each)."""

    out: Path
    modules: list = field(default_factory=list)
    skipped: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)


def public_modules(packages: Sequence[str] = PACKAGES) -> list:
    """Names of the packages and of every submodule without a leading underscore in its dotted name, sorted
    (found on disk; subpackages are imported to look inside them)."""
    names = []
    for pkg in packages:
        names.append(pkg)
        path = importlib.import_module(pkg).__path__
        for info in pkgutil.walk_packages(path, pkg + "."):
            if not any(part.startswith("_") for part in info.name.split(".")):
                names.append(info.name)
    return sorted(names)


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


def build(out: Path | str, packages: Sequence[str] = PACKAGES) -> ApiDocs:
    """Write the HTML reference of ``packages`` to ``out`` (made if needed): a page per module,
    ``index.html`` and the search index. Raises :class:`gyro_sim.extras.MissingExtra` without pdoc."""
    require("docs", "the API reference (gyro-sim api-docs)")
    import pdoc
    import pdoc.doc
    import pdoc.render

    out = Path(out)
    pdoc_dir = str(Path(pdoc.__file__).parent)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        names, skipped = _importable(public_modules(packages))
        pdoc.render.configure(docformat=DOCFORMAT, math=False, show_source=True,
                              footer_text="gyro_sim API reference (gyro-sim api-docs)")
        modules = {name: pdoc.doc.Module.from_name(name) for name in names}
        pages = {name: pdoc.render.html_module(mod, modules) for name, mod in modules.items()}
        index, search = pdoc.render.html_index(modules), pdoc.render.search_index(modules)
    for name, html in pages.items():
        page = out / f"{name.replace('.', '/')}.html"
        page.parent.mkdir(parents=True, exist_ok=True)
        page.write_text(html, encoding="utf-8")
    (out / "index.html").write_text(index, encoding="utf-8")
    if search:
        (out / "search.js").write_text(search, encoding="utf-8")
    # (a package's page lists its submodules: pdoc tries those left out again and says it could not import them)
    expected = tuple(f"Couldn't import {name}:" for name in skipped)
    said = [str(w.message) for w in caught
            if str(w.filename).startswith(pdoc_dir) and not (expected and str(w.message).startswith(expected))]
    return ApiDocs(out=out, modules=names, skipped=skipped, warnings=said)
