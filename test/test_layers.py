"""The layers of gyro_sim (issue 22, docs/architecture.md): the import graph, read from the source (module-level and
function-level imports alike), has no circle and no edge from a layer to one above it."""
import ast
from pathlib import Path

import pytest

import gyro_sim

PKG = Path(gyro_sim.__file__).parent

#: the layers, bottom first: a module may import its own layer and those before it in this list (the one place
#: the order is declared; each folder's __init__ says the same in words)
LAYERS = ("common", "physics", "compiled", "scenes", "averaging", "engine", "io", "ros", "apps")


def module_files() -> dict:
    """{dotted name: path} of every module of gyro_sim."""
    out = {}
    for path in sorted(PKG.rglob("*.py")):
        parts = ("gyro_sim",) + path.relative_to(PKG).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def imports(name: str, path: Path, modules: dict) -> dict:
    """{imported gyro_sim module: first line number} of module ``name`` (``from X import y`` counts as an import
    of X.y where that is a module, else of X)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = {}
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        targets = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[:len(package.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in modules else mod for a in node.names]
        for t in targets:
            while t and t not in modules:  # `import gyro_sim.io.recording.x`: the module part
                t = t.rpartition(".")[0]
            if t and t != name and t != "gyro_sim" and not name.startswith(t + "."):
                found.setdefault(t, node.lineno)
    return found


def layer_of(name: str):
    parts = name.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in LAYERS else None


MODULES = module_files()
GRAPH = {name: imports(name, path, MODULES) for name, path in MODULES.items()}
#: the root: the package, its deprecated flat paths (a shim each, gyro_sim/_moved.py) and gyro_sim.testing (the
#: kit's public name): above every layer, like gyro_sim itself
ROOT_MODULES = {"gyro_sim", "gyro_sim._moved", "gyro_sim.testing"} | {f"gyro_sim.{old}" for old in gyro_sim.MOVED}


def test_every_module_is_in_a_layer():
    loose = [n for n in MODULES if n not in ROOT_MODULES and layer_of(n) is None]
    assert not loose, f"modules outside the layer folders {LAYERS}: {loose}"
    assert sorted({layer_of(n) for n in MODULES if n not in ROOT_MODULES}) == sorted(LAYERS)


def test_no_upward_edge():
    rank = {layer: i for i, layer in enumerate(LAYERS)}
    up = [f"{a} (layer {layer_of(a)}, line {line}) imports {b} (layer {layer_of(b)})"
          for a, deps in GRAPH.items() if a not in ROOT_MODULES for b, line in deps.items()
          if b in ROOT_MODULES or rank[layer_of(b)] > rank[layer_of(a)]]
    assert not up, "imports that go up a layer:\n  " + "\n  ".join(up)


def test_no_import_circle():
    """Depth-first search over the graph; any back edge closes a circle (named in full)."""
    state, stack, circles = {}, [], []

    def visit(n):
        state[n] = "open"
        stack.append(n)
        for m in sorted(GRAPH[n]):
            if state.get(m) == "open":
                circles.append(" -> ".join(stack[stack.index(m):] + [m]))
            elif m not in state:
                visit(m)
        stack.pop()
        state[n] = "done"

    for n in sorted(GRAPH):
        if n not in state:
            visit(n)
    assert not circles, "import circles:\n  " + "\n  ".join(circles)


def test_root_imports_nothing_at_import():
    """gyro_sim/__init__ loads its public names on first use only (a layer above everything, imported by all)."""
    tree = ast.parse((PKG / "__init__.py").read_text(encoding="utf-8"))
    top = [n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]
    assert all(isinstance(n, ast.Import) and all(not a.name.startswith("gyro_sim") for a in n.names) for n in top)


@pytest.mark.parametrize("old", sorted(gyro_sim.MOVED))
def test_old_paths_are_shims_that_warn_and_give_the_new_modules(old):
    """Each flat path of before the layers is a module file of its own (no import hook: nothing in sys.meta_path)
    that warns and gives the new home's module object."""
    import importlib
    import sys

    sys.modules.pop(f"gyro_sim.{old}", None)
    with pytest.warns(DeprecationWarning, match=rf"gyro_sim\.{old} is deprecated .*gyro_sim\.{gyro_sim.MOVED[old]}"):
        mod = importlib.import_module(f"gyro_sim.{old}")
    assert mod is importlib.import_module(f"gyro_sim.{gyro_sim.MOVED[old]}")
    assert (PKG / f"{old}.py").is_file()
    assert not [f for f in sys.meta_path if type(f).__module__.startswith("gyro_sim")]


def test_gyro_sim_testing_is_the_public_name_of_the_kit():
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        import gyro_sim.apps.testing
        import gyro_sim.testing
    assert gyro_sim.testing is gyro_sim.apps.testing


#: the engine's parts (issue 28, docs/architecture.md "One run"): a solver library's shape — the model's terms, the
#: controller of the step, one step interface, the output — each its own module
ENGINE_PARTS = ("terms", "step_size", "steppers", "saving")


def test_the_engine_parts_are_modules_that_never_reach_up_into_the_simulator_or_the_runner():
    """Each part is a module of gyro_sim/engine/ and imports neither the Simulator nor the Runner (nor the entry
    that drives them): they are handed what they need, so a reader follows one part without the hub."""
    above = {"gyro_sim.engine.simulator", "gyro_sim.engine.runner", "gyro_sim.engine.simulate",
             "gyro_sim.engine.ticks", "gyro_sim.engine.fidelity"}
    for part in ENGINE_PARTS:
        name = f"gyro_sim.engine.{part}"
        assert name in GRAPH, f"{name}: no such module"
        up = sorted(set(GRAPH[name]) & above)
        assert not up, f"{name} imports {up}"
    # and the Simulator composes them
    composed = {f"gyro_sim.engine.{p}" for p in ("terms", "step_size", "steppers")}
    assert composed <= set(GRAPH["gyro_sim.engine.simulator"])


def test_the_error_estimate_is_a_part_the_runner_calls_and_never_reaches_up_into_it():
    """The shadow run and the error control (gyro_sim/engine/shadow.py) are handed the run's simulator and breaks:
    the module imports neither the Runner nor what drives it, and the Runner composes it."""
    name = "gyro_sim.engine.shadow"
    assert name in GRAPH, f"{name}: no such module"
    up = sorted(set(GRAPH[name]) & {"gyro_sim.engine.runner", "gyro_sim.engine.simulate", "gyro_sim.engine.ticks",
                                    "gyro_sim.engine.fidelity"})
    assert not up, f"{name} imports {up}"
    assert name in GRAPH["gyro_sim.engine.runner"]
