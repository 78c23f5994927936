"""The API reference (gyro-sim api-docs, pdoc) builds, has a page for the public API, and pdoc has nothing to
say about the docstrings: built here so it cannot rot (docs/api.md)."""
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
    "gyro_sim/scenes/scene.html": ["load_scene", "Scene"],
    "gyro_sim/io/recording.html": ["record_run", "read_bag", "bag_info"],
    "gyro_sim/common/extras.html": ["require", "MissingExtra"],
    "gyro_ctl/laws.html": ["make_law", "ControlInput"],
    "gyro_ctl/config.html": ["ControllerConfig"],
}


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("api") / "api"
    from gyro_sim.apps.api_docs import build

    return build(out)


def test_api_reference_builds_without_warnings(built):
    assert built.warnings == [], "\n".join(built.warnings)
    assert (built.out / "index.html").is_file() and (built.out / "search.js").is_file()
    assert {"gyro_sim", "gyro_ctl", "gyro_sim.engine.simulate", "gyro_sim.io.recording", "gyro_ctl.laws"} <= set(built.modules)
    assert not any(part.startswith("_") for m in built.modules for part in m.split("."))


@pytest.mark.parametrize("page", sorted(PUBLIC))
def test_public_api_has_pages(built, page):
    html = (built.out / page).read_text(encoding="utf-8")
    ids = set(re.findall(r'<(?:section|div) id="([^"]+)"', html))  # (modules' members: section; classes': div)
    assert set(PUBLIC[page]) <= ids, sorted(set(PUBLIC[page]) - ids)


def test_every_module_has_its_page(built):
    for name in built.modules:
        assert (built.out / f"{name.replace('.', '/')}.html").is_file(), name
    if not built.skipped:  # (rclpy installed: the ROS adapters are documented too)
        assert {"gyro_sim.ros.simulator_node", "gyro_ctl.ros.controller_node"} <= set(built.modules)


def test_pdoc_warnings_are_caught(tmp_path, monkeypatch):
    """The check above can fail: a package whose __all__ names something that does not exist is reported."""
    from gyro_sim.apps.api_docs import build

    pkg = tmp_path / "src" / "brokenpkg"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text('"""A package."""\n__all__ = ["nowhere"]\n')
    monkeypatch.syspath_prepend(str(tmp_path / "src"))
    docs = build(tmp_path / "out", packages=("brokenpkg",))
    assert any("nowhere" in w for w in docs.warnings), docs.warnings


def test_modules_needing_a_missing_extra_are_left_out(tmp_path):
    """Without rclpy (hidden in a new process), gyro_ctl.ros.controller_node is left out with its extra named;
    the rest is built (one package here, to keep it short)."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text("import sys\nsys.modules['rclpy'] = None\n")
    code = ("import json, sys; from gyro_sim.apps.api_docs import build; "
            "d = build(sys.argv[1], packages=('gyro_ctl',)); "
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

    def fake_build(out):
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
