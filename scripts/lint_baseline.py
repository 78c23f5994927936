#!/usr/bin/env python3
"""Lint and type findings against their baseline, test/lint_baseline.json (issue 22).

    python scripts/lint_baseline.py            # compare: new findings and fixed ones, exit 1 on either
    python scripts/lint_baseline.py --update   # rewrite the baseline with what ruff and mypy find now

ruff checks the repository (its scope and rules: pyproject.toml), mypy the packages of ``[tool.mypy] files``.
A finding is keyed by file, rule and message, counted (no line numbers: code that moves keeps its key);
paths are recomputed on every run, so after files are moved ``--update`` makes the baseline anew. The
baseline only shrinks: a finding not in it fails test/test_lint.py, and so does an entry that no longer
occurs (run ``--update`` after fixing, and commit the smaller file).

mypy's incremental cache is ``.mypy_cache`` in the repository (``MYPY_CACHE_DIR`` to put it elsewhere).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / "test" / "lint_baseline.json"
UPDATE = "python scripts/lint_baseline.py --update"


def _run(args: list, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], cwd=ROOT, capture_output=True, text=True, **kw)


def tool_version(tool: str) -> str:
    r = _run([tool, "--version"])
    if r.returncode != 0:
        raise RuntimeError(f"{tool} is not installed (pip install -e '.[test]'): {r.stderr.strip()}")
    return r.stdout.split()[1]


def _rel(path: str) -> str:
    p = Path(path)
    return (p.resolve().relative_to(ROOT) if p.is_absolute() else p).as_posix()


def _ruff_message(code: str, message: str) -> str:
    # E501's message holds the line's length: "Line too long (123 > 120)"
    return "Line too long" if code == "E501" else message


def ruff_findings() -> Counter:
    """{(file, code, message): count} of ``ruff check`` over the repository."""
    r = _run(["ruff", "check", "--no-cache", "--output-format", "json", "--exit-zero", "."])
    if r.returncode != 0:
        raise RuntimeError(f"ruff failed ({r.returncode}): {r.stderr.strip()}")
    return Counter((_rel(f["filename"]), f["code"] or "syntax", _ruff_message(f["code"], f["message"]))
                   for f in json.loads(r.stdout))


def mypy_findings(cache_dir: str | None = None) -> Counter:
    """{(file, code, message): count} of mypy's errors (notes left out) on ``[tool.mypy] files``."""
    cache = cache_dir or os.environ.get("MYPY_CACHE_DIR") or str(ROOT / ".mypy_cache")
    r = _run(["mypy", "--cache-dir", cache, "--output", "json", "--no-error-summary"])
    if r.returncode not in (0, 1) or (r.returncode == 1 and not r.stdout.strip()):
        raise RuntimeError(f"mypy failed ({r.returncode}): {r.stderr.strip()}{r.stdout.strip()}")
    out: Counter = Counter()
    for line in r.stdout.splitlines():
        if not line.startswith("{"):  # a note on the configuration
            continue
        e = json.loads(line)
        if e["severity"] == "error":
            # messages that name a line ("defined on line 42") keep their key when code moves
            out[(_rel(e["file"]), e["code"] or "misc", re.sub(r"\bline \d+", "line N", e["message"]))] += 1
    return out


def findings(cache_dir: str | None = None) -> dict:
    return {"ruff": ruff_findings(), "mypy": mypy_findings(cache_dir)}


def to_json(found: dict) -> dict:
    data: dict = {"_about": "Lint and type findings left (issue 22): file -> 'code: message' -> count. It only "
                            f"shrinks; regenerate with `{UPDATE}` (test/test_lint.py compares).",
                  "versions": {tool: tool_version(tool) for tool in ("ruff", "mypy")}}
    for tool, counts in found.items():
        by_file: dict = {}
        for (path, code, message), n in sorted(counts.items()):
            by_file.setdefault(path, {})[f"{code}: {message}"] = n
        data[tool] = by_file
    return data


def from_json(data: dict) -> dict:
    out = {}
    for tool in ("ruff", "mypy"):
        c: Counter = Counter()
        for path, entries in data.get(tool, {}).items():
            for key, n in entries.items():
                code, message = key.split(": ", 1)
                c[(path, code, message)] = n
        out[tool] = c
    return out


def load_baseline(path: Path = BASELINE) -> dict:
    return json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}


def compare(found: dict, baseline: dict) -> tuple[list, list]:
    """(new, gone): lines naming the findings not in the baseline and the baseline's entries that no longer occur."""
    base = from_json(baseline)
    new, gone = [], []
    for tool in ("ruff", "mypy"):
        for (path, code, message), n in sorted((found[tool] - base[tool]).items()):
            new.append(f"{tool}: {path}: {code}: {message}" + (f" (x{n} more than the baseline)" if n > 1 else ""))
        for (path, code, message), n in sorted((base[tool] - found[tool]).items()):
            gone.append(f"{tool}: {path}: {code}: {message}" + (f" (x{n})" if n > 1 else ""))
    return new, gone


def report(new: list, gone: list, baseline: dict) -> str:
    lines = []
    if new:
        lines += [f"{len(new)} finding(s) not in {BASELINE.relative_to(ROOT)} (fix them):"] + ["  " + x for x in new]
        lines.append(f"  (ruff check --output-format concise . / mypy show the lines; tools now "
                     f"{ {t: tool_version(t) for t in ('ruff', 'mypy')} }, baseline made with "
                     f"{baseline.get('versions')})")
    if gone:
        lines += [f"{len(gone)} baseline entr(y/ies) no longer found: the baseline only shrinks, run `{UPDATE}` "
                  "and commit it:"] + ["  " + x for x in gone]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--update", action="store_true", help=f"rewrite {BASELINE.relative_to(ROOT)}")
    args = ap.parse_args(argv)
    found = findings()
    if args.update:
        BASELINE.write_text(json.dumps(to_json(found), indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
        print(f"{BASELINE.relative_to(ROOT)}: ruff {sum(found['ruff'].values())}, "
              f"mypy {sum(found['mypy'].values())} findings")
        return 0
    baseline = load_baseline()
    new, gone = compare(found, baseline)
    if new or gone:
        print(report(new, gone, baseline))
        return 1
    print(f"as the baseline: ruff {sum(found['ruff'].values())}, mypy {sum(found['mypy'].values())} findings")
    return 0


if __name__ == "__main__":
    sys.exit(main())
