"""CPU cost of control ticks in in-process runs, for whichever gyro_sim is imported, so that two versions of the code
can be compared in turns on the same machine (the figures of docs/benchmark.md "Control ticks in compiled code"):

    git archive <commit> gyro_sim gyro_ctl config | tar -x -C /tmp/base     # the other version, with its scenes
    PYTHONPATH=/tmp/base .venv/bin/python scripts/tick_cost.py 3 > /tmp/base1.json
    .venv/bin/python scripts/tick_cost.py 3 > /tmp/new1.json                  # ... and again, in turns
    .venv/bin/python scripts/tick_cost.py --table /tmp/base1.json /tmp/new1.json

``tick_cost.py [N]`` runs each case once (numba compiles or loads its kernels) then N times (default 3) and prints,
as JSON, the least CPU time (``time.process_time``) of each, its steps and duration. ``--table A B`` prints the
cases of two such files side by side with B's speed-up over A and each file's cost with the controller over
without it. Uses only ``gyro_sim.load_scene`` and ``gyro_sim.run``, which every version has.
"""
import json
import sys
import time

#: name → (scene, overrides): the default scene as shipped with and without its controller, the same with the
#: accuracy of L alone, nutation_slow at fidelity auto as shipped and at the averaged-models part's rtol 2e-3
CASES = {
    "default_on": ("spinup_thin_shell", {}),
    "default_off": ("spinup_thin_shell", {"controller": None}),
    "default_L_on": ("spinup_thin_shell", {"accuracy": {"attitude": None}}),
    "default_L_off": ("spinup_thin_shell", {"accuracy": {"attitude": None}, "controller": None}),
    "nutation_slow_auto": ("nutation_slow", {"fidelity": "auto"}),
    "nutation_slow_auto_2e-3": ("nutation_slow", {"fidelity": "auto", "accuracy.rtol": 2e-3}),
}
PAIRS = (("default_on", "default_off"), ("default_L_on", "default_L_off"))


def measure(n: int) -> dict:
    import gyro_sim

    out = {"module": gyro_sim.__file__}
    for key, (name, overrides) in CASES.items():
        scene = gyro_sim.load_scene(name, overrides=overrides)
        r = gyro_sim.run(scene)  # compiles or loads the kernels
        best = float("inf")
        for _ in range(n):
            c0 = time.process_time()
            gyro_sim.run(scene)
            best = min(best, time.process_time() - c0)
        out[key] = {"cpu": best, "steps": int(r.steps), "duration": float(r.t[-1])}
    return out


def table(a: dict, b: dict) -> str:
    lines = [f"A = {a['module']}", f"B = {b['module']}", "",
             "| case | A CPU s | B CPU s | A / B | steps A | steps B |", "|---|---|---|---|---|---|"]
    for key in CASES:
        x, y = a[key], b[key]
        lines.append(f"| {key} | {x['cpu']:.4g} | {y['cpu']:.4g} | {x['cpu'] / y['cpu']:.2f} | {x['steps']} "
                     f"| {y['steps']} |")
    lines.append("")
    for on, off in PAIRS:
        lines.append(f"{on} / {off}: A {a[on]['cpu'] / a[off]['cpu']:.3g}, B {b[on]['cpu'] / b[off]['cpu']:.3g}")
    return "\n".join(lines)


def main(argv: list) -> int:
    if argv[:1] == ["--table"] and len(argv) == 3:
        with open(argv[1]) as fa, open(argv[2]) as fb:
            print(table(json.load(fa), json.load(fb)))
        return 0
    if len(argv) > 1 or (argv and not argv[0].isdigit()):
        print(__doc__)
        return 2
    print(json.dumps(measure(int(argv[0]) if argv else 3)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
