"""The API reference (gyro-sim api-docs, pdoc) builds, has a page for the public API and none for the internals,
describes every scene field, shows no memory address, no ``PydanticUndefined`` and no reST ``::``, and pdoc has
nothing to say about the docstrings: built here so it cannot rot (docs/api.md)."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from gyro_sim.apps import cli

pytest.importorskip("pdoc", reason="the 'docs' extra (pdoc) builds the API reference")

ROOT = Path(__file__).resolve().parents[1]

#: page → names it must document (pdoc's anchor ids)
PUBLIC = {
    "gyro_sim.html": ["load_scene", "run", "Simulator", "RunResult", "Scene", "SceneError", "builtin_scenes"],
    "gyro_sim/engine/simulate.html": ["run", "Simulator", "RunResult", "RunResult.summary", "Simulator.advance",
                               "Simulator.set_stator"],
    "gyro_sim/scenes/scene.html": ["load_scene", "Scene", "Scene.duration", "Stator", "Stator.coil_constant",
                                   "Conductor.outer_radius"],
    "gyro_sim/testing.html": ["gyro_bench", "GyroBench", "ControllerError"],
    "gyro_sim/io/recording.html": ["record_run", "read_bag", "bag_info"],
    "gyro_sim/common/extras.html": ["require", "MissingExtra"],
    "gyro_ctl/laws.html": ["make_law", "ControlInput"],
    "gyro_ctl/config.html": ["ControllerConfig"],
}


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("api") / "api"
    from gyro_sim.apps.api_docs import build

    lines = []
    docs = build(out, progress=lines.append)
    docs.progress = lines
    return docs


def test_build_says_what_it_does(built):
    """Issue 33: 5 min 24 s with no output. One line per module rendered, then the index and the totals."""
    n = len(built.modules)
    assert built.progress[0] == f"importing {n} modules"
    assert [line for line in built.progress if line.startswith("[")] == [
        f"[{i}/{n}] {name}" for i, name in enumerate(built.modules, 1)]
    assert re.fullmatch(r"wrote \d+ pages, [\d.]+ MB, in [\d.]+ s", built.progress[-1]), built.progress[-1]


def test_api_reference_builds_without_warnings(built):
    assert built.warnings == [], "\n".join(built.warnings)
    assert (built.out / "index.html").is_file() and (built.out / "search.js").is_file()
    assert {"gyro_sim", "gyro_ctl", "gyro_sim.testing", "gyro_sim.engine.simulate", "gyro_sim.io.recording",
            "gyro_ctl.laws"} <= set(built.modules)
    assert not any(part.startswith("_") for m in built.modules for part in m.split("."))


#: module names that are internals: the reference must neither have a page for them nor link to one
INTERNAL = re.compile(r"gyro_sim[./](apps|compiled|ros|averaging|engine[./](runner|simulator|ticks|model|budget|warmup)"
                      r"|io[./](bag_|live|rerun|messages|signals)|scenes[./](limits|scene_text|step_control|tolerance))"
                      r"|gyro_sim[./](bench|cli|sweep)\w*|gyro_ctl[./](ros|law_kernels)")


def rendered(html: str) -> str:
    """A page without its source listings (the "View Source" blocks show the code as it is)."""
    return re.sub(r'<div class="pdoc-code codehilite">.*?</pre></div>', "", html, flags=re.S)


def pages(built):
    return {p.relative_to(built.out).as_posix(): p.read_text(encoding="utf-8") for p in built.out.rglob("*.html")}


def test_only_the_public_api_is_documented(built):
    """Issue 33: 93 modules in one flat list with bench_core, cli_common... Now the curated list, no internal page,
    no link to one from the pages or the index."""
    from gyro_sim.apps.api_docs import PUBLIC

    assert built.modules == list(PUBLIC) and built.skipped == {}
    assert not [m for m in built.modules if INTERNAL.search(m)]
    for name, html in pages(built).items():
        assert not INTERNAL.search(name), name
        links = re.findall(r'href="([^"#:]+\.html)', rendered(html))
        assert not [link for link in links if INTERNAL.search(link)], (name, links)


def test_no_memory_address_pydantic_internals_or_rest_markers(built):
    """Issue 33: ``BeforeValidator(func=<function _number at 0x7ffa…>)``, ``= PydanticUndefined`` and a leaked reST
    ``::`` in the pages."""
    bad = re.compile(r"0x[0-9a-fA-F]{6,}|PydanticUndefined|BeforeValidator|FieldInfo\(|Annotated\[|_Strict")
    for name, html in [*pages(built).items(), ("search.js", (built.out / "search.js").read_text(encoding="utf-8"))]:
        text = rendered(html)
        found = bad.search(text)
        assert found is None, (name, text[max(0, found.start() - 200):found.end() + 50])
        assert not re.search(r"[^:\s]::(</p>|</|\n)", text), name


def test_every_scene_field_has_its_meaning_and_unit(built):
    """Every field of the scene file (the scene, its sections, the effects, the controller's parameters) has a
    description in the model and on its page, with its plain type; required fields say so."""
    from pydantic import BaseModel

    from gyro_ctl import config, reorient
    from gyro_sim.scenes import effect_config, scene

    for module, page in [(scene, "gyro_sim/scenes/scene.html"), (effect_config, "gyro_sim/scenes/effect_config.html"),
                         (config, "gyro_ctl/config.html"), (reorient, "gyro_ctl/reorient.html")]:
        html = (built.out / page).read_text(encoding="utf-8")
        models = [v for n, v in vars(module).items() if not n.startswith("_") and isinstance(v, type)
                  and issubclass(v, BaseModel) and v.__module__ == module.__name__]
        assert models, page
        for model in models:
            for name, info in model.model_fields.items():
                assert info.description, f"{model.__name__}.{name} has no description"
                section = re.search(rf'<div id="{model.__name__}\.{name}".*?</div>\s*</div>', html, re.S)
                assert section, f"{page}: {model.__name__}.{name}"
                assert info.description.split()[0] in section.group(0), f"{model.__name__}.{name}"
    stator = re.search(r'<div id="Stator\.coil_constant".*?</div>\s*</div>',
                       (built.out / "gyro_sim/scenes/scene.html").read_text(encoding="utf-8"), re.S).group(0)
    assert "T/A" in stator and "required" in stator and "&gt; 0" in stator and ": float" in rendered(stator).replace(
        '<span class="annotation">', "").replace("</span>", "")


def test_landing_page_has_the_tour(built):
    """Issue 33: the landing page was empty. Now a tour that links the public modules, and the module list."""
    index = (built.out / "index.html").read_text(encoding="utf-8")
    text = re.sub(r"<[^>]+>", "", index)
    assert "A tour" in text and "gyro_sim.load_scene(" in text and "Test your own controller" in text
    for name in built.modules:
        assert f'href="{name.replace(".", "/")}.html"' in index, name


@pytest.mark.parametrize("page", sorted(PUBLIC))
def test_public_api_has_pages(built, page):
    html = (built.out / page).read_text(encoding="utf-8")
    ids = set(re.findall(r'<(?:section|div) id="([^"]+)"', html))  # (modules' members: section; classes': div)
    assert set(PUBLIC[page]) <= ids, sorted(set(PUBLIC[page]) - ids)


def test_every_module_has_its_page(built):
    for name in built.modules:
        assert (built.out / f"{name.replace('.', '/')}.html").is_file(), name


def test_pdoc_warnings_are_caught(tmp_path, monkeypatch):
    """The check above can fail: a package whose __all__ names something that does not exist is reported."""
    from gyro_sim.apps.api_docs import build

    pkg = tmp_path / "src" / "brokenpkg"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text('"""A package."""\n__all__ = ["nowhere"]\n')
    monkeypatch.syspath_prepend(str(tmp_path / "src"))
    docs = build(tmp_path / "out", modules=("brokenpkg",))
    assert any("nowhere" in w for w in docs.warnings), docs.warnings


def test_modules_needing_a_missing_extra_are_left_out(tmp_path):
    """Without rclpy (hidden in a new process), a module that needs it (gyro_ctl.ros.controller_node, not in the
    public API, asked for here) is left out with its extra named; the rest is built."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text("import sys\nsys.modules['rclpy'] = None\n")
    code = ("import json, sys; from gyro_sim.apps.api_docs import build; "
            "d = build(sys.argv[1], modules=('gyro_ctl', 'gyro_ctl.laws', 'gyro_ctl.ros.controller_node')); "
            "print(json.dumps({'modules': d.modules, 'skipped': d.skipped, 'warnings': d.warnings}))")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), str(ROOT)]))
    p = subprocess.run([sys.executable, "-c", code, str(tmp_path / "out")], capture_output=True, text=True,
                       timeout=300, env=env, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    import json

    got = json.loads(p.stdout)
    assert got["skipped"] == {"gyro_ctl.ros.controller_node": ["ros", "rclpy"]} and got["warnings"] == []
    assert "gyro_ctl.laws" in got["modules"] and (tmp_path / "out" / "gyro_ctl" / "laws.html").is_file()
    assert not (tmp_path / "out" / "gyro_ctl" / "ros" / "controller_node.html").exists()


def test_api_docs_command(tmp_path, capsys, monkeypatch):
    """The command wraps build(): one line naming the index (the build itself is the fixture's; stubbed here)."""
    from gyro_sim.apps import api_docs

    def fake_build(out, progress=None):
        (out / "index.html").parent.mkdir(parents=True)
        (out / "index.html").write_text("x")
        return api_docs.ApiDocs(out=out, modules=["gyro_sim"], skipped={"gyro_sim.ros.common": ("ros", "rclpy")})

    monkeypatch.setattr(api_docs, "build", fake_build)
    assert cli.main(["api-docs", str(tmp_path / "api")]) == 0
    out, err = capsys.readouterr()
    assert err == "" and out == ("left out gyro_sim.ros.common: it needs rclpy (pip install 'gyro_sim[ros]')\n"
                                 f"API reference of 1 modules: {tmp_path / 'api' / 'index.html'}\n")
    (tmp_path / "file").write_text("")
    assert cli.main(["api-docs", str(tmp_path / "file")]) == 2
    assert capsys.readouterr().err.startswith("error: ")
