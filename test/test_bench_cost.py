"""The benchmark's cost part (gyro_sim/apps/bench_cost.py): its rows, table and headline (not its timings)."""
from __future__ import annotations

import math
from types import SimpleNamespace

from gyro_sim.apps import bench_cost


def test_cost_part_rows_table_and_headline(monkeypatch):
    monkeypatch.setattr(bench_cost, "QUICK_DURATIONS", (0.2, 0.4))
    monkeypatch.setattr(bench_cost, "SCENES", ("free_rotor",))
    res = SimpleNamespace()
    said = []
    out = bench_cost.cost_part(res, quick=True, say=said.append)
    assert res.cost is out and len(out.rows) == 4 and len(said) == 6
    assert [(r.duration, r.what) for r in out.rows] == [(0.2, "as shipped"), (0.2, "old defaults"),
                                                       (0.4, "as shipped"), (0.4, "old defaults")]
    for r in out.rows:
        assert r.steps > 0 and r.cpu > 0 and "L " in r.estimate
    shipped = [r for r in out.rows if r.what == "as shipped"]
    assert all(r.met for r in shipped)  # (the old defaults run no error control: their estimate is the model's)
    text = "\n".join(bench_cost.markdown_lines(res))
    assert "## Cost against duration" in text and "| 0.4 | as shipped |" in text
    assert math.isnan(bench_cost.linearity(out))  # (no duration of 20 s or more)
    assert any("within" in line for line in bench_cost.headline(res))
    # every built-in scene over its own duration, as shipped and at the old defaults (here one)
    assert [(r.scene, r.what) for r in out.scene_rows] == [("free_rotor", "as shipped"), ("free_rotor", "old defaults")]
    assert "| free_rotor | 10 |" in text and "free_rotor" in bench_cost.headline(res)[-1]
