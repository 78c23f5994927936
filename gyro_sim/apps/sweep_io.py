"""A sweep's results (:mod:`gyro_sim.apps.sweep`): the Parquet table (:func:`write_results`, :func:`read_results`)
and the journal a hard stop leaves. pyarrow is imported only here, where used.
"""
from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path

from gyro_sim import __version__
from gyro_sim.apps.sweep_axes import SweepError, _is_number
from gyro_sim.apps.sweep_spec import SweepSpec, Variant

_META_KEY = b"gyro_sim.sweep"
#: s between two writes of the journal: a hard stop (kill, power) loses at most the runs of the last JOURNAL_SECONDS
JOURNAL_SECONDS = 1.0


# ------------------------------------------------------------------------------------------
# results: Parquet table (+ journal)
# ------------------------------------------------------------------------------------------
def _journal_path(out: Path) -> Path:
    return out.with_name(out.name + ".journal.jsonl")


class Journal:
    """The runs a sweep has finished, appended to ``FILE.journal.jsonl`` (one JSON row a line) in batches: the rows
    wait in memory and go to the file in one write and one flush when :data:`JOURNAL_SECONDS` have passed since the
    last write (``seconds``), and at :meth:`close` (also on Ctrl-C). A line per run and a flush per run cost the
    sweep's client a system call per run; a hard stop now loses at most the last ``seconds`` of runs."""

    def __init__(self, path: Path, seconds: float | None = None):
        self.path = Path(path)
        self.seconds = JOURNAL_SECONDS if seconds is None else float(seconds)
        self.pending: list = []
        self.writes = 0  # writes to the file so far
        self._file = open(self.path, "a", encoding="utf-8")
        self._last = time.monotonic()

    def add(self, rows) -> None:
        self.pending.extend(json.dumps(r) + "\n" for r in rows)
        if self.pending and time.monotonic() - self._last >= self.seconds:
            self.flush()

    def flush(self) -> None:
        if self.pending:
            self._file.write("".join(self.pending))
            self._file.flush()
            self.pending.clear()
            self.writes += 1
        self._last = time.monotonic()

    def close(self) -> None:
        try:
            self.flush()
        finally:
            self._file.close()


def _flat_row(spec: SweepSpec, v: Variant, r: dict) -> dict:
    # seed: that of the variant's random draws (RandomVar.draw(seed, sample)), None where it draws nothing
    row = {"run_id": v.run_id, "index": v.index, "sample": v.sample,
           "seed": int(spec.seed) if v.sample is not None else None, "status": r["status"], "error": r.get("error"),
           "wall_time_run": float(r.get("wall_time_run") or 0.0), "worker": r.get("worker", ""),
           "gyro_sim_version": r.get("gyro_sim_version", __version__)}
    row.update(v.values)
    for m in spec.metrics:
        row[m.name] = float(r.get("metrics", {}).get(m.name, math.nan)) if r["status"] == "ok" else math.nan
    if spec.series:
        ser = r.get("series") or {}
        for q in ["t"] + list(spec.series):
            row[f"series.{q}"] = ser.get(q)
    return row


def _row_from_flat(spec: SweepSpec, flat: dict) -> dict:
    r = {"run_id": flat["run_id"], "status": flat["status"], "error": flat.get("error"),
         "wall_time_run": flat.get("wall_time_run"), "worker": flat.get("worker"),
         "gyro_sim_version": flat.get("gyro_sim_version"),
         "metrics": {m.name: flat.get(m.name, math.nan) for m in spec.metrics}, "series": {}}
    if spec.series:
        r["series"] = {q: flat.get(f"series.{q}") for q in ["t"] + list(spec.series)}
    return r


def write_results(path: Path, rows: list, meta: dict) -> None:
    """Write the flat rows as a Parquet table (atomically) with the sweep's metadata in the schema."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    cols: dict = {}
    keys: list = []
    for r in rows:
        for k in r:
            if k not in cols:
                cols[k] = None
                keys.append(k)
    arrays = {}
    for k in keys:
        vals = [r.get(k) for r in rows]
        if k in ("index", "sample", "seed"):
            arrays[k] = pa.array(vals, type=pa.int64())
        elif k in ("run_id", "status", "error", "worker", "gyro_sim_version"):
            arrays[k] = pa.array(vals, type=pa.string())
        else:
            nonnull = [v for v in vals if v is not None]
            if all(isinstance(v, bool) for v in nonnull) and nonnull:
                arrays[k] = pa.array(vals, type=pa.bool_())
            elif all(_is_number(v) for v in nonnull):
                arrays[k] = pa.array([None if v is None else float(v) for v in vals], type=pa.float64())
            elif all(isinstance(v, list) and all(_is_number(x) for x in v) for v in nonnull):
                arrays[k] = pa.array([None if v is None else [float(x) for x in v] for v in vals],
                                     type=pa.list_(pa.float64()))
            else:
                arrays[k] = pa.array([None if v is None else (v if isinstance(v, str) else json.dumps(v)) for v in vals],
                                     type=pa.string())
    table = pa.table(arrays) if arrays else pa.table({"run_id": pa.array([], pa.string())})
    table = table.replace_schema_metadata({_META_KEY: json.dumps(meta, default=str).encode()})
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    pq.write_table(table, tmp)
    os.replace(tmp, path)


def read_results(path: str | Path) -> tuple:
    """(rows as dicts, sweep metadata dict) of a results file written by :func:`run_sweep`."""
    import pyarrow.parquet as pq

    path = Path(path)
    try:
        table = pq.read_table(path)
    except Exception as e:  # noqa: BLE001
        raise SweepError(f"cannot read results {path}: {e}") from None
    md = table.schema.metadata or {}
    meta = json.loads(md[_META_KEY]) if _META_KEY in md else {}
    return table.to_pylist(), meta


def _read_journal(path: Path) -> list:
    rows = []
    if path.is_file():
        with open(path, encoding="utf-8") as f:
            for line in f:
                try:
                    rows.append(json.loads(line))
                except json.JSONDecodeError:  # a line cut by a hard stop
                    continue
    return rows
