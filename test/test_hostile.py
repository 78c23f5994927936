"""Hostile scene files and commands: refused with one bounded message, never a traceback, a hang or GBs.

Each hostile file is made here, in tmp_path. Those that cost minutes and GBs before the limits (the alias
bomb, deep nesting, the huge files) are loaded in a subprocess with an address-space limit and a timeout,
so a regression fails the test instead of taking the machine; the timeout bounds a hang, it measures
nothing (the limits trigger before any work, a load takes well under a second).

Fuzzing (hypothesis, derandomized in the default suite; ``pytest --stress`` runs 1,000 random examples
each): scene documents (mutated valid scenes, random YAML text and bytes) and /gyro/stator_commands
messages either load / are accepted, or are refused with a bounded message.
"""
from __future__ import annotations

import copy
import json
import math
import subprocess
import sys
import textwrap
from collections import Counter
from types import SimpleNamespace

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gyro_sim.scenes import scene as scene_mod
from gyro_sim.scenes.scene import (MAX_ERRORS, RESULT_BYTES_ENV, Scene, SceneError, builtin_scenes, load_scene,
                                   scene_from_dict)
from gyro_sim.scenes.scene_text import (MAX_ALIASES, MAX_DEPTH, MAX_SCENE_BYTES, PREVIEW_CHARS, dump_scene_data,
                                        parse_scene_text)

#: a refusal's message: the head line, MAX_ERRORS errors and "... and K more errors"
MAX_LINES = MAX_ERRORS + 2
MAX_LINE_CHARS = 400  # "invalid scene <file>: " + one clipped error line (300 characters)

SPINUP = builtin_scenes()["spinup_thin_shell"]


def spinup_text() -> str:
    return SPINUP.read_text()


def bounded(msg: str, path=None) -> None:
    """A SceneError's message: at most MAX_LINES lines of at most MAX_LINE_CHARS characters, the scene file's
    ``path`` counted as "<file>" (its length is the caller's: pytest's temporary folders are longer under xdist)."""
    lines = (msg if path is None else msg.replace(str(path), "<file>")).split("\n")
    assert len(lines) <= MAX_LINES and max(map(len, lines)) <= MAX_LINE_CHARS, \
        f"{len(lines)} lines, longest {max(map(len, lines))} characters: {msg[:500]!r}"


def refused(path, *fragments) -> str:
    """The one-line SceneError of load_scene(path), holding every fragment."""
    with pytest.raises(SceneError) as ei:
        load_scene(path)
    msg = str(ei.value)
    print(f"\n  {msg}")
    bounded(msg, path)
    for f in fragments:
        assert f in msg, f"{f!r} not in {msg!r}"
    return msg


_LOADER = textwrap.dedent("""
    import json, resource, sys
    limit = int(sys.argv[2])
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    from gyro_sim.scenes.scene import SceneError, load_scene
    try:
        load_scene(sys.argv[1])
        out = {"outcome": "loaded"}
    except SceneError as e:
        out = {"outcome": "SceneError", "message": str(e)}
    except BaseException as e:  # noqa: BLE001 - what the test reports
        out = {"outcome": type(e).__name__, "message": str(e)[:300]}
    print(json.dumps(out))
""")


def load_bounded(path, memory: int = 2 << 30, timeout: float = 120.0) -> dict:
    """load_scene(path) in a subprocess limited to ``memory`` bytes of address space and ``timeout`` s:
    {"outcome": "loaded" | "SceneError" | an exception's name, "message": ...}."""
    try:
        r = subprocess.run([sys.executable, "-c", _LOADER, str(path), str(memory)], capture_output=True,
                           text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        pytest.fail(f"loading {path.name} ({path.stat().st_size} bytes) did not end in {timeout:.0f} s")
    assert r.returncode == 0 and r.stdout.strip(), f"status {r.returncode}: {r.stderr[-2000:]}"
    out = json.loads(r.stdout.strip().splitlines()[-1])
    print(f"\n  {path.name} ({path.stat().st_size} bytes): {out['outcome']}: {out.get('message', '')}")
    return out


def scene_error(out: dict, *fragments) -> None:
    assert out["outcome"] == "SceneError", out
    bounded(out["message"])
    assert len(out["message"].split("\n")) == 1, out["message"]
    for f in fragments:
        assert f in out["message"], f"{f!r} not in {out['message']!r}"


# --- defect 1: costly or crashing files ----------------------------------------------------

def test_alias_bomb_is_refused_before_it_expands(tmp_path):
    """A 1.2 KB "billion laughs" (9 levels of 9 aliases = 9⁹ leaves, used as duration) ran 180 s at 6 GB."""
    levels = ["a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    for i in range(1, 9):
        prev, name = chr(ord("a") + i - 1), chr(ord("a") + i)
        levels.append(f"{name}: &{name} [" + ", ".join([f"*{prev}"] * 9) + "]")
    p = tmp_path / "bomb.yaml"
    p.write_text(spinup_text().replace("duration:", "old_duration:") + "\n".join(levels) + "\nduration: *i\n")
    assert p.stat().st_size < 2000
    scene_error(load_bounded(p), str(p), "YAML nodes", "alias")


def test_many_aliases_are_refused(tmp_path):
    """More than MAX_ALIASES alias uses, each one cheap."""
    p = tmp_path / "aliases.yaml"
    p.write_text(spinup_text() + "x: &x 1\ny: [" + ", ".join(["*x"] * (MAX_ALIASES + 1)) + "]\n")
    refused(p, f"more than {MAX_ALIASES} uses of YAML aliases", "line ")


def test_deep_nesting_is_refused(tmp_path):
    """100k nested lists ended in a RecursionError."""
    p = tmp_path / "deep.yaml"
    p.write_text(spinup_text().replace("duration:", "old_duration:") + "duration: " + "[" * 100_000 + "]" * 100_000)
    out = load_bounded(p)
    scene_error(out, str(p))
    assert "nest" in out["message"], out


@pytest.mark.parametrize("pure", [False, True], ids=["libyaml", "pure-python"])
def test_nesting_limit_counts_aliases(pure):
    """MAX_DEPTH levels through aliases too: 40 levels named, used 20 levels down."""
    ok = "a: &a " + "[" * 20 + "1" + "]" * 20 + "\nb: " + "[" * 20 + "*a" + "]" * 20 + "\n"
    assert parse_scene_text(ok, "ok.yaml", pure=pure)["b"]
    deep = "a: &a " + "[" * 40 + "1" + "]" * 40 + "\nb: " + "[" * 20 + "*a" + "]" * 20 + "\n"
    with pytest.raises(SceneError, match=f"nested deeper than {MAX_DEPTH} levels"):
        parse_scene_text(deep, "deep.yaml", pure=pure)
    # an anchored scalar after a deep sibling is one level high
    sibling = "a: " + "[" * 45 + "1" + "]" * 45 + "\nb: &b 1\nc: " + "[" * 45 + "*b" + "]" * 45 + "\n"
    assert parse_scene_text(sibling, "sibling.yaml", pure=pure)["b"] == 1
    with pytest.raises(SceneError, match="recursive"):
        parse_scene_text("a: &a [1, *a]\n", "rec.yaml", pure=pure)


def test_huge_file_is_refused_on_its_size(tmp_path):
    """A 12 MB comment padding (50 MB parsed 86 s before): refused on its size, read no further."""
    p = tmp_path / "padded.yaml"
    with open(p, "w") as f:
        f.write(spinup_text())
        line = "# " + "padding " * 12 + "\n"
        f.write(line * (12_000_000 // len(line)))
    size = p.stat().st_size
    scene_error(load_bounded(p), str(p), f"the file is {size} bytes", f"at most {MAX_SCENE_BYTES} bytes (1 MiB)")


def test_many_bad_commands_list_ten_errors(tmp_path):
    """A file of thousands of bad commands (5 MB printed a 121,934-line error): MAX_ERRORS errors listed,
    then how many more; each value previewed."""
    p = tmp_path / "commands.yaml"
    bad = "".join(f"  - {{time: -{i}.5, stator: z3, current: on}}\n" for i in range(1, 10_001))
    p.write_text(spinup_text().replace("commands:", "old_commands:") + "commands:\n" + bad)
    assert p.stat().st_size < MAX_SCENE_BYTES
    msg = refused(p, "commands.0.time = -1.5", "a boolean is not a number", "... and 19990 more errors")
    assert len(msg.split("\n")) == MAX_ERRORS + 2


def test_non_utf8_names_the_byte(tmp_path):
    """Latin-1 bytes ended in a UnicodeDecodeError."""
    p = tmp_path / "latin1.yaml"
    text = spinup_text().replace("description:", "description: caf\xe9 ", 1)
    p.write_bytes(text.encode("latin-1"))
    offset = text.encode("latin-1").index(b"\xe9")
    refused(p, f"byte {offset}", "is not UTF-8 (0xe9)", "line ")


@pytest.mark.parametrize("key,value,what", [
    ("duration", "1e12", "duration = 1e+12 s"),
    ("output", "{rate: 1e10}", "output.rate = 1e+10 /s"),
])
def test_result_memory_bound(tmp_path, key, value, what):
    """duration: 1e12 and output.rate: 1e10 ended in numpy's _ArrayMemoryError at the run: refused at load
    with samples, bytes per sample, total and the limit; nothing is allocated."""
    p = tmp_path / f"{key}.yaml"
    data = parse_scene_text(spinup_text())
    data[key] = parse_scene_text(f"v: {value}")["v"]
    p.write_text(yaml.safe_dump(data, sort_keys=False))
    msg = refused(p, what, "output samples", "bytes", "the limit is 4.29e+09 bytes (4 GiB", RESULT_BYTES_ENV,
                  "lower duration")
    assert len(msg.split("\n")) == 1


def test_result_memory_bound_env_override(monkeypatch):
    """GYRO_SIM_MAX_RESULT_BYTES lowers or raises the limit; a bad value is named."""
    data = parse_scene_text(spinup_text())
    samples, ticks, row = scene_mod.result_size(scene_from_dict(data))
    need = (samples + ticks) * row
    print(f"\n  spinup_thin_shell: {samples:.0f} samples + {ticks:.0f} ticks × {row} bytes = {need:.3g} bytes")
    assert samples >= data["duration"] * data["output"]["rate"] and row == 8 * (18 + 3 * 3 + 3 * 1)  # 3 stators, 1 eddy mode (thin shell)
    monkeypatch.setenv(RESULT_BYTES_ENV, f"{need * 0.9:.0f}")
    with pytest.raises(SceneError, match="controller ticks"):
        scene_from_dict(data)
    monkeypatch.setenv(RESULT_BYTES_ENV, f"{need * 1.1:.0f}")
    scene_from_dict(data)
    monkeypatch.setenv(RESULT_BYTES_ENV, "lots")
    with pytest.raises(SceneError, match=f"{RESULT_BYTES_ENV} = 'lots': must be a positive number"):
        scene_from_dict(data)


def test_sample_count_bounds_sample_times():
    """Output.sample_count (arithmetic) is an upper bound of sample_times(T).size, tight within the windows."""
    out = scene_mod.Output(rate=7.0, windows=[{"start": 0.1, "end": 0.5, "rate": 1000.0},
                                              {"start": 0.3, "end": 9.0, "rate": 30.0}])
    for T in (0.05, 0.4, 1.0, 3.3):
        n, bound = out.sample_times(T).size, out.sample_count(T)
        print(f"  T = {T} s: {n} samples, bound {bound:.1f}")
        assert n <= bound <= n + 3 + 0.4 * 7.0 + (T - 0.3) * 30.0 * (T > 0.3) + 3


# --- defect 2: accepted silently -----------------------------------------------------------

@pytest.mark.parametrize("pure", [False, True], ids=["libyaml", "pure-python"])
def test_duplicate_keys_are_refused(pure):
    """A key given twice (the last one won): the key and both lines named."""
    text = spinup_text()
    first = text.splitlines().index(next(x for x in text.splitlines() if x.startswith("duration:"))) + 1
    dup = text + "duration: 5.0\n"
    with pytest.raises(SceneError) as ei:
        parse_scene_text(dup, "dup.yaml", pure=pure)
    msg = str(ei.value)
    print(f"\n  {msg}")
    assert "key 'duration' is given twice" in msg and f"first at line {first}" in msg
    assert f"line {len(text.splitlines()) + 1}," in msg
    # a merge key may still be overridden (that is what it is for)
    assert parse_scene_text("a: &a {x: 1, y: 2}\nb: {<<: *a, x: 3}\n", pure=pure)["b"] == {"x": 3, "y": 2}


@pytest.mark.parametrize("yaml_value", ["on", "yes", "true", "off"])
def test_booleans_are_not_numbers(tmp_path, yaml_value):
    """`current: on` was 1 A."""
    p = tmp_path / "bool.yaml"
    p.write_text(spinup_text().replace("current: 1.0", f"current: {yaml_value}", 1))
    assert p.read_text() != spinup_text()
    refused(p, "current = True" if yaml_value in ("on", "yes", "true") else "current = False",
            "a boolean is not a number")


def test_texts_are_not_numbers_but_yaml12_floats_are(tmp_path):
    """'2.5e7' quoted is a text (refused); 2.5e7, 1e-3, .5 unquoted are numbers (YAML 1.2 floats)."""
    data = parse_scene_text("a: 2.5e7\nb: 1e-3\nc: .5\nd: -1E+2\ne: '2.5e7'\nf: 1_000.5\ng: 7\nh: .inf\n")
    assert data == {"a": 2.5e7, "b": 1e-3, "c": 0.5, "d": -100.0, "e": "2.5e7", "f": 1000.5, "g": 7,
                    "h": math.inf}
    p = tmp_path / "quoted.yaml"
    p.write_text(spinup_text().replace("conductivity: 2.5e7", "conductivity: '2.5e7'"))
    assert p.read_text() != spinup_text()
    refused(p, "rotor.conductor.conductivity = '2.5e7'", "a text is not a number")
    assert scene_from_dict(parse_scene_text(spinup_text())).rotor.conductor.conductivity == 2.5e7


def test_builtin_scenes_read_the_same_numbers():
    """Every config/*.yaml scene loads, with the numbers PyYAML 1.1 plus pydantic's coercion gave before."""
    for name, path in builtin_scenes().items():
        old = yaml.safe_load(path.read_text())  # 1.1: 2.5e7 a text, coerced by the old (lax) models

        def coerce(x):
            if isinstance(x, dict):
                return {k: coerce(v) for k, v in x.items()}
            if isinstance(x, list):
                return [coerce(v) for v in x]
            if isinstance(x, str):
                try:
                    return float(x)
                except ValueError:
                    return x
            return x

        assert parse_scene_text(path.read_text(), str(path)) == coerce(old), name
        load_scene(name)


def test_long_values_are_previewed():
    """A 100 kB text given for duration: the message quotes at most PREVIEW_CHARS characters of it."""
    data = parse_scene_text(spinup_text())
    data["duration"] = "x" * 100_000
    data["rotor"]["y" * 5000] = 1
    with pytest.raises(SceneError) as ei:
        scene_from_dict(data, where="long.yaml")
    msg = str(ei.value)
    print(f"\n  {msg}")
    bounded(msg)
    line = next(x for x in msg.split("\n") if x.strip().startswith("duration"))
    assert ("…" in line or "..." in line) and len(line) < PREVIEW_CHARS + 150


def test_yaml_errors_are_one_line(tmp_path):
    """YAML syntax errors, bad tags, timestamps and huge integers: one line naming the place."""
    for text in ("rotor: [unclosed\n", "a:\n\tb: 1\n", "a: !!python/object:os.system x\n", "a: 2001-13-45\n",
                 "a: " + "9" * 5000 + "\n", "a: 1\n---\nb: 2\n", "a: \x00\n", "? [1, 2]\n: 3\n"):
        p = tmp_path / "bad.yaml"
        p.write_text(text)
        msg = refused(p, str(p))
        assert len(msg.split("\n")) == 1


def test_overrides_that_do_not_fit_are_named():
    with pytest.raises(SceneError, match=r"override 'stators.9.current': '9' is not an index of stators \(3 items\)"):
        load_scene("spinup_thin_shell", overrides={"stators.9.current": 1.0})
    with pytest.raises(SceneError, match="override 'duration.x': duration = 60.0 is not a mapping or a list"):
        load_scene("spinup_thin_shell", overrides={"duration.x": 1.0})


def test_many_stators_load_in_linear_time():
    """2,000 stators and 20,000 commands: the checks for unique names and known stators are linear (they were
    quadratic: 4·10⁸ comparisons); refused only for the memory of the result."""
    data = parse_scene_text(spinup_text())
    data["stators"] = [{"name": f"s{i}", "axis": [0, 0, 1], "coil_constant": 1e-3} for i in range(2000)]
    data["commands"] = [{"time": 1.0, "stator": f"s{i % 2000}", "current": 0.5} for i in range(20_000)]
    data.pop("controller")
    s = scene_from_dict(data)
    assert len(s.stators) == 2000 and len(s.commands) == 20_000


def test_the_limits_check_reads_the_scene_once_not_once_a_stator(monkeypatch):
    """The limits' check (scenes/limits.py) gathered each stator's currents and rates by scanning every stator,
    command and law parameter again: 2,000 stators and 20,000 commands took 51 s to load (the test above, on the
    2-core machine). Now one pass gives every stator's values: the law's parameters are read a few times a scene,
    not 5 times a stator (1000 for these 200 before)."""
    from gyro_sim.scenes import limits

    calls = []
    real = limits._law_values
    monkeypatch.setattr(limits, "_law_values", lambda ctl: calls.append(1) or real(ctl))
    data = parse_scene_text(spinup_text())
    data["stators"] = [{"name": f"s{i}", "axis": [0, 0, 1], "coil_constant": 1e-3} for i in range(200)]
    data["commands"] = [{"time": 1.0, "stator": f"s{i % 200}", "current": 0.5} for i in range(2000)]
    data.pop("controller")
    scene_from_dict(data)
    assert 0 < len(calls) <= 10, len(calls)


# --- fuzzing: scene documents --------------------------------------------------------------

FAST = settings(max_examples=300, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much])
STRESS = settings(max_examples=1000, deadline=None, database=None,
                  suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much])

BASES = [parse_scene_text(builtin_scenes()[n].read_text()) for n in
         ("spinup_thin_shell", "drift_sources", "reorient_L", "flywheel_reorientation", "spinup_solid_sphere")]
BASE_TEXTS = [builtin_scenes()[n].read_text() for n in ("spinup_thin_shell", "three_stators")]


def _paths(x, prefix=()):
    """Every path (keys and indexes) into a document."""
    out = [prefix]
    if isinstance(x, dict):
        for k, v in x.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            out += _paths(v, prefix + (i,))
    return out


LEAF = st.one_of(
    st.none(), st.booleans(), st.integers(-10**30, 10**30), st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-1e3, 1e3), st.text(max_size=20),
    st.sampled_from(["on", "2.5e7", "z1", "z3", "lag", "auto", "", "nan", "thin_shell", "psi_switching", "x" * 500]))
VALUE = st.recursive(LEAF, lambda kids: st.one_of(st.lists(kids, max_size=4),
                                                  st.dictionaries(st.text(max_size=10), kids, max_size=4)),
                     max_leaves=12)
KEYS = st.one_of(st.text(max_size=12), st.sampled_from(["rotor", "duration", "stators", "commands", "controller",
                                                        "output", "windows", "effects", "params", "modes", "rate"]))


@st.composite
def mutated_scenes(draw):
    """A built-in scene with 1–5 random edits: a value replaced, a key deleted or added, a list repeated."""
    doc = copy.deepcopy(draw(st.sampled_from(BASES)))
    for _ in range(draw(st.integers(1, 5))):
        paths = _paths(doc)
        path = draw(st.sampled_from(paths))
        op = draw(st.sampled_from(["set", "set", "delete", "add", "repeat"]))
        if not path:
            if op == "add" and isinstance(doc, dict):
                doc[draw(KEYS)] = draw(VALUE)
            continue
        parent = doc
        for part in path[:-1]:
            parent = parent[part]
        last = path[-1]
        if op == "set":
            parent[last] = draw(VALUE)
        elif op == "delete":
            del parent[last]
        elif op == "add" and isinstance(parent[last], dict):
            parent[last][draw(KEYS)] = draw(VALUE)
        elif op == "repeat" and isinstance(parent[last], list):
            parent[last] = parent[last] * draw(st.integers(0, 40))
    return doc


TOKENS = ["rotor:", "duration:", "stators:", "commands:", "output:", " ", " ", "\n", "\n  ", "  ", "- ", "[", "]",
          "{", "}", ", ", ": ", "&a ", "*a", "&b ", "*b", "<<: ", "!!str ", "!!float ", "!!binary ", "!!set ",
          "!!timestamp ", "!foo ", "? ", "|\n", ">\n", "'", '"', "# c", "1", "2.5e7", "1e-3", ".5", "on", "nan",
          ".inf", "-", "\t", "\x00", "\ufeff", "%YAML 1.2\n", "---\n", "...\n", "\\", "é", "0x1F", "1:30",
          "2001-12-14", "~", "null", "z3", "9" * 30]


@st.composite
def yaml_texts(draw):
    """Random YAML text: tokens alone, or spliced into a built-in scene's text."""
    noise = "".join(draw(st.lists(st.sampled_from(TOKENS), max_size=40)))
    if draw(st.booleans()):
        return noise
    base = draw(st.sampled_from(BASE_TEXTS))
    at = draw(st.integers(0, len(base)))
    cut = draw(st.integers(0, 20))
    return base[:at] + noise + base[at + cut:]


def _outcome(make) -> str:
    """'loaded' (a Scene) or 'refused' (a SceneError with a bounded message); anything else fails."""
    try:
        s = make()
    except SceneError as e:
        bounded(str(e))
        return "refused"
    assert isinstance(s, Scene)
    return "loaded"


def _check_documents(doc, text, blob, tally: Counter) -> None:
    as_dict = _outcome(lambda: scene_from_dict(doc, where="fuzz.yaml"))
    tally["dict " + as_dict] += 1
    # dump_scene_data's YAML reads back to the same outcome (yaml.safe_dump writes the text '2.5e7' unquoted,
    # which YAML 1.2 reads as a number)
    dumped = dump_scene_data(doc)
    as_dump = _outcome(lambda: scene_from_dict(parse_scene_text(dumped, "fuzz.yaml"), where="fuzz.yaml"))
    assert as_dump == as_dict, dumped
    tally["dump " + as_dump] += 1
    for pure in (False, True):
        tally["text " + _outcome(lambda pure=pure: scene_from_dict(parse_scene_text(text, "fuzz.yaml", pure=pure),
                                                          where="fuzz.yaml"))] += 1
    tally["bytes " + _outcome(lambda: scene_from_dict(parse_scene_text(blob, "fuzz.yaml"), where="fuzz.yaml"))] += 1


def _fuzz_documents(config) -> Counter:
    tally: Counter = Counter()

    @config
    @given(doc=mutated_scenes(), text=yaml_texts(), blob=st.binary(max_size=200))
    def check(doc, text, blob):
        _check_documents(doc, text, blob, tally)

    check()
    print(f"\n  outcomes: {dict(sorted(tally.items()))}")
    return tally


def test_fuzz_scene_documents():
    """Mutated built-in scenes (as dicts and as YAML), random YAML text (both parsers) and random bytes: a
    Scene or one bounded SceneError, never another exception."""
    tally = _fuzz_documents(FAST)
    assert tally["dict loaded"] and tally["dict refused"] and tally["text refused"]


@pytest.mark.slow
def test_fuzz_scene_documents_stress():
    _fuzz_documents(STRESS)


# --- fuzzing: commands ---------------------------------------------------------------------

STATORS = ["z1", "z2", "z3"]
NUMBER = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(0, 10), st.integers(-5, 5),
                   st.booleans(), st.text(max_size=3), st.none())
NAME = st.one_of(st.sampled_from(STATORS), st.text(max_size=4), st.integers(), st.none(), st.lists(st.integers(), max_size=2))


def joint_state(names, effort, velocity, sec=1, nanosec=0):
    return SimpleNamespace(name=names, effort=effort, velocity=velocity,
                           header=SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nanosec)))


@st.composite
def valid_commands(draw):
    """Commands of distinct known stators with finite currents ≥ 0 and no or finite rates."""
    names = draw(st.lists(st.sampled_from(STATORS), unique=True, max_size=3))
    effort = draw(st.lists(st.floats(0, 1e3), min_size=len(names), max_size=len(names)))
    velocity = draw(st.one_of(st.just([]), st.lists(st.floats(-1e4, 1e4), min_size=len(names), max_size=len(names))))
    return joint_state(names, effort, velocity)


@st.composite
def hostile_commands(draw):
    """Repeated, unknown and non-text names, NaN/inf/bool/text/None values, mismatched lengths, lists of 100k."""
    blow_up = draw(st.sampled_from([1, 1, 1, 50_000]))
    names, effort = draw(st.lists(NAME, max_size=4)), draw(st.lists(NUMBER, max_size=4))
    return joint_state(names * blow_up, effort * draw(st.sampled_from([1, blow_up])), draw(st.lists(NUMBER, max_size=4)))


def _check_command(msg, tally: Counter) -> None:
    from gyro_sim.ros.common import MAX_REASON, parse_command

    cmd, why = parse_command(msg, STATORS)
    if cmd is None:
        assert why and len(why) <= MAX_REASON and "\n" not in why, why
        tally["refused"] += 1
        return
    names, cur, rate, stamp = cmd
    assert why == "" and len(set(names)) == len(names) and set(names) <= set(STATORS)
    assert len(cur) == len(names) and all(math.isfinite(c) and c >= 0 for c in cur)
    assert rate is None or (len(rate) == len(names) and all(math.isfinite(r) for r in rate))
    tally["accepted"] += 1


def _fuzz_commands(config) -> Counter:
    pytest.importorskip("rclpy")
    tally: Counter = Counter()

    @config
    @given(msg=st.one_of(valid_commands(), hostile_commands()))
    def check(msg):
        _check_command(msg, tally)

    check()
    print(f"\n  outcomes: {dict(tally)}")
    return tally


def test_fuzz_commands():
    """JointState-like commands with repeated, unknown, non-text names, NaN/inf/bool/text values, mismatched
    lengths, 100k-entry lists: accepted valid, or refused with one line of at most MAX_REASON characters."""
    tally = _fuzz_commands(FAST)
    assert tally["refused"] and tally["accepted"]


@pytest.mark.slow
def test_fuzz_commands_stress():
    _fuzz_commands(STRESS)


def test_huge_command_reason_is_bounded():
    """A command naming 100k stators flooded /gyro/status with its whole list."""
    pytest.importorskip("rclpy")
    from gyro_sim.ros.common import MAX_REASON, parse_command

    for msg in (joint_state(["z1", "zz"] * 50_000, [1.0] * 100_000, []),
                joint_state(["z1"], [float("nan")] * 100_000, []),
                joint_state(["z1", "z9"], [1.0, 1.0], [0.0] * 100_000),
                joint_state([], [1.0] * 100_000, [])):
        cmd, why = parse_command(msg, STATORS)
        print(f"  {why}")
        assert cmd is None and len(why) <= MAX_REASON
    cmd, why = parse_command(joint_state(["z3", "z1"], [1.0, 0], [3000.0, -1]), STATORS)
    assert why == "" and cmd == (["z3", "z1"], [1.0, 0.0], [3000.0, -1.0], 1_000_000_000)
    for names, eff, vel, fragment in ((["z1"], [True], [], "effort[z1] = True"), ([1], [1.0], [], "name[0] = 1"),
                                      (["z1", "z1"], [1.0, 1.0], [], "stator 'z1' is named twice"),
                                      (["z1"], ["1"], [], "effort[z1] = '1'")):
        cmd, why = parse_command(joint_state(names, eff, vel), STATORS)
        assert cmd is None and fragment in why, why
