"""Lint and types (issue 22): ruff and mypy (configured in pyproject.toml) find nothing that
test/lint_baseline.json does not hold, and the baseline holds nothing they no longer find (it only shrinks:
``python scripts/lint_baseline.py --update``). Also the packaging files of the same issue: LICENSE, py.typed.

mypy keeps its incremental cache in .mypy_cache: about 20 s the first time on 2 cores, 1–2 s with the cache.
"""
import ast
import importlib.util
from importlib.resources import files
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("lint_baseline", ROOT / "scripts" / "lint_baseline.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


lint = _script()


@pytest.fixture(scope="module")
def baseline():
    assert lint.BASELINE.is_file(), f"no {lint.BASELINE}: run `{lint.UPDATE}`"
    return lint.load_baseline()


@pytest.mark.parametrize("tool", ["ruff", "mypy"])
def test_no_findings_beyond_the_baseline(tool, baseline):
    pytest.importorskip(tool, reason=f"{tool} is not installed (the test extra: pip install -e '.[test]')")
    found = {"ruff": lint.ruff_findings, "mypy": lint.mypy_findings}[tool]()
    empty = lint.Counter()
    new, gone = lint.compare({"ruff": empty, "mypy": empty, tool: found}, {tool: baseline.get(tool, {})})
    assert not (new or gone), "\n" + lint.report(new, gone, baseline)


def test_baseline_round_trip(baseline):
    """The file is what --update writes (sorted, so that its diffs show what changed)."""
    found = lint.from_json(baseline)
    for tool in ("ruff", "mypy"):
        assert baseline[tool] == _sorted(baseline[tool])
        assert all(n > 0 for n in found[tool].values())
    assert lint.compare(found, baseline) == ([], [])


def _sorted(d: dict) -> dict:
    return {k: dict(sorted(v.items())) for k, v in sorted(d.items())}


def test_compare_names_new_and_gone_findings():
    base = {"ruff": {"a.py": {"B905: zip": 2}}, "mypy": {}}
    c = lint.Counter
    new, gone = lint.compare({"ruff": c({("a.py", "B905", "zip"): 3, ("b.py", "B023", "x"): 1}), "mypy": c()}, base)
    assert (new, gone) == (["ruff: a.py: B905: zip", "ruff: b.py: B023: x"], [])
    new, gone = lint.compare({"ruff": c({("a.py", "B905", "zip"): 1}), "mypy": c()}, base)
    assert (new, gone) == ([], ["ruff: a.py: B905: zip"])


def test_license_and_typed_markers():
    assert "Apache License" in (ROOT / "LICENSE").read_text(encoding="utf-8")[:200]
    assert "<license>Apache-2.0</license>" in (ROOT / "package.xml").read_text(encoding="utf-8")
    from test_packaging import pyproject

    assert pyproject()["project"]["license"] == {"text": "Apache-2.0"}
    call = next(n for n in ast.walk(ast.parse((ROOT / "setup.py").read_text())) if isinstance(n, ast.Call)
                and getattr(n.func, "id", "") == "setup")
    kw = {k.arg: k.value for k in call.keywords}
    assert ast.literal_eval(kw["package_data"]) == {"gyro_sim": ["py.typed"], "gyro_ctl": ["py.typed"]}
    for package in ("gyro_sim", "gyro_ctl"):
        assert files(package).joinpath("py.typed").is_file()
