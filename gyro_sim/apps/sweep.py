"""Parameter sweeps: every variant of a scene run as an independent task (``gyro-sim sweep``).

A sweep is a scene, the keys it varies (a grid, random draws, or both; any scene key by its
dotted path, list items by index: ``stators.0.current``, ``controller.params.nu.1``) and the
metrics kept per run. It is given on the command line or in a sweep file (``config/sweep_*.yaml``;
format in ``docs/sweeps.md``)::

    gyro-sim sweep nutation_oblate --vary controller.period=0.004:0.02:17 \\
        --metric theta_end=final(theta_deg) --metric t_settle=time_below(theta_deg,0.1)
    gyro-sim sweep sweep_psi_rate                 # a built-in sweep file
    gyro-sim sweep sweep_psi_rate --scheduler tcp://127.0.0.1:8786

Every variant is validated like a scene file before it runs (once, where it runs); a variant that does not
validate, a run that raises or ends in a non-finite state is recorded (``status`` ``invalid`` /
``failed`` with the reason) and the sweep goes on. Runs are independent Dask tasks on a local
cluster (all cores by default, bound to 127.0.0.1) or on an existing scheduler (``--scheduler``);
``--workers 0`` runs them in this process without Dask. Results go to a Parquet table (one row per
variant: the varied values, the metrics, optional time series, the package version) keyed by a
hash of (scene, fixed overrides, variant values, metrics); a sweep run again skips what its file
already holds, and a hard stop loses at most the runs in flight and those of the last second (a journal beside
the file, written in batches). Each row records the seed of its random draws.

A task runs several variants one after the other in the worker, so the per-task costs (scheduling
round trip, (de)serialisation, result hand-back) are paid once per task: by default (``--batch auto``)
each task is sized as it is sent to last about 0.25 s at the run time seen so far
(:mod:`gyro_sim.sweep_tasks`); ``--batch N`` gives every task N variants. It does not vectorise the
integrator: each run is the same compiled code as ``gyro_sim.run``. ``--measure`` reports runs/s
in-process, with one worker and all cores (one run per task, N per task, auto), the overhead per task
and the cost of a run inside a worker against in-process.

The core (specs, variants, metrics, serial execution, the Parquet writer aside) needs no Dask:
``dask.distributed``, ``pyarrow`` and ``tqdm`` (the ``sweep`` extra) are imported only where used.

The code lives beside this module, by what it holds: :mod:`~gyro_sim.apps.sweep_axes` (values, axes, random
variables, :class:`SweepError`), :mod:`~gyro_sim.apps.sweep_metrics`, :mod:`~gyro_sim.apps.sweep_spec` (the
sweep's definition and its loading), :mod:`~gyro_sim.apps.sweep_io` (Parquet), :mod:`~gyro_sim.apps.sweep_exec`
(runs in a task, Dask, :func:`run_sweep`, :func:`measure`), :mod:`~gyro_sim.apps.sweep_plot` and
:mod:`~gyro_sim.apps.sweep_tasks` (task sizes); this module keeps the command line and re-exports every name
it had (``gyro_sim.sweep.X`` and ``gyro_sim.apps.sweep.X`` keep working).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Optional, Sequence

from gyro_sim.apps.sweep_axes import (  # noqa: F401 - re-exported
    _DISTS,
    _FIXED_COLUMNS,
    Axis,
    RandomVar,
    SweepError,
    _is_number,
    _parse_value,
    _plain,
    _range_values,
    _split_assignment,
    _split_top,
    parse_axis,
    parse_random,
)
from gyro_sim.apps.sweep_exec import (  # noqa: F401 - re-exported
    MEASURE_CONFIGS,
    SweepResult,
    _batch_arg,
    _dask_client,
    _decimate,
    _execute,
    _noop,
    _pass_figures,
    _Progress,
    _require_extras,
    _run_scene,
    _timed_rows,
    _worker_label,
    measure,
    measure_lines,
    run_chunk,
    run_sweep,
)
from gyro_sim.apps.sweep_io import (  # noqa: F401 - re-exported
    _META_KEY,
    _flat_row,
    _journal_path,
    _read_journal,
    _row_from_flat,
    read_results,
    write_results,
)
from gyro_sim.apps.sweep_metrics import (  # noqa: F401 - re-exported
    _K_ATTRS,
    DEFAULT_METRICS,
    METRIC_ALIASES,
    METRIC_FUNCTIONS,
    QUANTITIES,
    Metric,
    _drift,
    _first_time,
    _initial_L,
    _k_metric,
    _mean,
    _q_current,
    _quantity,
    _settle_below,
    parse_metric,
)
from gyro_sim.apps.sweep_plot import (  # noqa: F401 - re-exported
    _xval,
    plot_sweep,
)
from gyro_sim.apps.sweep_spec import (  # noqa: F401 - re-exported
    _SWEEP_KEYS,
    SweepSpec,
    Variant,
    _fmt,
    _load_scene_ref,
    _scene_for,
    builtin_sweeps,
    load_sweep,
    spec_from_dict,
)
from gyro_sim.scenes.scene import SceneError

__all__ = [
    "SweepError", "Axis", "RandomVar", "Metric", "Variant", "SweepSpec", "SweepResult",
    "parse_axis", "parse_random", "parse_metric", "load_sweep", "spec_from_dict", "builtin_sweeps",
    "run_chunk", "run_sweep", "read_results", "write_results", "plot_sweep", "measure", "measure_lines", "sweep_main",
    "QUANTITIES", "METRIC_FUNCTIONS", "METRIC_ALIASES",
]

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


# ------------------------------------------------------------------------------------------
# command line
# ------------------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="gyro-sim sweep",
        description="Run every variant of a scene (grid and/or Monte Carlo) on Dask; results as Parquet + PNG. "
                    "SOURCE is a sweep file (config/sweep_*.yaml by name, or a path), a scene (built-in name or "
                    "path), or a results .parquet file (summarise and plot it).",
        epilog="Examples: gyro-sim sweep sweep_psi_rate;  gyro-sim sweep nutation_oblate --vary "
               "controller.period=0.004:0.02:17 --metric 't=time_below(theta_deg,0.1)' --set duration=3;  "
               "gyro-sim sweep free_rotor --random initial.theta=uniform(0,0.5) --samples 100 --workers 2.")
    p.add_argument("source", metavar="SOURCE")
    p.add_argument("--vary", metavar="KEY=START:STOP:N", action="append", default=[],
                   help="grid axis: START:STOP:N (N values, ends included), START:STOP:N:log, or v1,v2,...; "
                        "START/STOP may be lists [a,b] for a vector key (repeatable)")
    p.add_argument("--random", metavar="KEY=DIST", action="append", default=[],
                   help="Monte Carlo key: uniform(a,b), normal(mu,sigma), loguniform(a,b), randint(a,b), "
                        "choice(v1,...) (repeatable; with --samples)")
    p.add_argument("--samples", metavar="N", type=int, default=None, help="random draws (per grid point)")
    p.add_argument("--seed", metavar="S", type=int, default=None, help="seed of the random draws (default 0)")
    p.add_argument("--set", metavar="KEY=VALUE", action="append", default=[],
                   help="fixed override of every variant, e.g. duration=1.0 (repeatable)")
    p.add_argument("--metric", metavar="[NAME=]FUNC(ARGS)", action="append", default=[],
                   help="metric column (repeatable; adds to the sweep file's): final(Q), max(Q), min(Q), mean(Q), "
                        "max_abs(Q), drift(Q), time_below(Q,x), time_above(Q,x), settle_below(Q,x), wall_time(), "
                        "steps(), k(NAME[,x]); aliases " + ", ".join(METRIC_ALIASES))
    p.add_argument("--series", metavar="Q[,Q...]", default=None,
                   help="keep these time series per run (e.g. theta_deg,spin); 'none' to drop the file's")
    p.add_argument("--workers", metavar="N", type=int, default=None,
                   help="local Dask worker processes (default: all cores); 0 = run in this process without Dask")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="an existing Dask scheduler (tcp://host:port or a scheduler file) instead of a local cluster")
    p.add_argument("--batch", metavar="N|auto", default="auto",
                   help="variants per task; auto (default): each task sized to last about 0.25 s at the run time "
                        "seen so far, the tasks shrinking towards the end so the workers finish together")
    p.add_argument("--out", metavar="FILE", type=Path, default=None,
                   help="results table (default runs/sweep_<name>.parquet; the plot goes beside it as .png)")
    p.add_argument("--no-resume", action="store_true", help="run everything again (default: skip what FILE holds)")
    p.add_argument("--retry-failed", action="store_true", help="run the failed variants again when resuming")
    p.add_argument("--no-plot", action="store_true", help="no PNG")
    p.add_argument("--dry-run", action="store_true", help="list and validate the variants; run nothing")
    p.add_argument("--measure", action="store_true",
                   help="time the runs in this process, with 1 worker and all cores (1 run per task, N per task, "
                        "auto), the overhead per task and a run's cost in a worker (no results file)")
    p.add_argument("--quiet", action="store_true", help="no progress bar, no table")
    return p


def _apply_cli(spec: SweepSpec, args) -> SweepSpec:
    try:
        grid = {a.key: a for a in spec.grid}
        for text in args.vary:
            k, v = _split_assignment(text, "--vary")
            grid[k] = parse_axis(k, v)
        rnd = {r.key: r for r in spec.random}
        for text in args.random:
            k, v = _split_assignment(text, "--random")
            rnd[k] = parse_random(k, v)
        fixed = dict(spec.set)
        for text in args.set:
            k, v = _split_assignment(text, "--set")
            fixed[k] = _parse_value(v)
        mets = {} if spec.default_metrics else {m.name: m for m in spec.metrics}
        for text in args.metric:
            m = parse_metric(text)
            mets[m.name] = m
        spec.grid, spec.random, spec.set = list(grid.values()), list(rnd.values()), fixed
        if args.metric:
            spec.metrics, spec.default_metrics = list(mets.values()), False
        if args.samples is not None:
            spec.samples = args.samples
        if args.seed is not None:
            spec.seed = args.seed
        if args.series is not None:
            spec.series = [] if args.series.strip().lower() == "none" else [
                s.strip() for s in args.series.split(",") if s.strip()]
        return spec.check()
    except SweepError:
        raise


def _print_table(rows: list, spec_meta: dict, stream, limit: int = 60) -> None:
    keys = list(spec_meta.get("grid", [])) + list(spec_meta.get("random", {}))
    names = list(spec_meta.get("metrics", {}))
    head = ["#"] + keys + names + ["status"]
    lines = [head]
    for r in rows[:limit]:
        cells = [str(r["index"])] + [_fmt(r.get(k)) for k in keys]
        cells += [_fmt(r.get(n)) if r["status"] == "ok" else "-" for n in names]
        cells.append(r["status"])
        lines.append(cells)
    widths = [max(len(line[i]) for line in lines) for i in range(len(head))]
    for line in lines:
        stream.write("  " + "  ".join(c.rjust(w) for c, w in zip(line, widths)) + "\n")
    if len(rows) > limit:
        stream.write(f"  ... {len(rows) - limit} more rows in the results file\n")
    bad = [r for r in rows if r["status"] != "ok"]
    for r in bad[:10]:
        stream.write(f"  #{r['index']} {r['status']}: {r.get('error')}\n")
    if len(bad) > 10:
        stream.write(f"  ... {len(bad) - 10} more failed or invalid variants\n")


def _write(stream, text: str) -> None:
    from gyro_sim.apps.console import _write as write  # one encoding-safe writer for every command

    write(stream, text)


def _check_command_extras(args) -> None:
    """What ``gyro-sim sweep`` with these arguments needs of the ``sweep`` extra (see :func:`_require_extras`)."""
    if args.source.endswith(".parquet"):
        _require_extras(True, True)
    elif args.measure:
        _require_extras(False, False, "gyro-sim sweep --measure")
    elif not args.dry_run:
        _require_extras(True, args.workers == 0 and not args.scheduler)


def sweep_main(argv: Optional[Sequence[str]] = None) -> int:
    """``gyro-sim sweep``: returns the exit status (0 done, 1 every run failed, 2 bad sweep/usage, 130 interrupted)."""
    from gyro_sim.common.extras import MissingExtra

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        _check_command_extras(args)
    except MissingExtra as e:
        _write(sys.stderr, f"error: {e}\n")
        return EXIT_USAGE
    try:
        if args.source.endswith(".parquet"):
            rows, meta = read_results(args.source)
            if not args.quiet:
                _print_table(rows, meta, sys.stdout)
            if not args.no_plot and rows:
                png = Path(args.source).with_suffix(".png")
                plot_sweep(rows, meta, png)
                _write(sys.stdout, f"plot: {png}\n")
            return EXIT_OK
        spec = load_sweep(args.source)
        spec = _apply_cli(spec, args)
        args.batch = _batch_arg(args.batch)
        if args.workers is not None and args.workers < 0:
            raise SweepError(f"--workers {args.workers}: must be ≥ 0")
        variants = spec.variants()
        if args.dry_run:
            n_bad = 0
            for v in variants:
                try:
                    spec.scene_for(v.values)
                    status = "ok"
                except SceneError as e:
                    status, n_bad = f"invalid: {e}", n_bad + 1
                _write(sys.stdout, f"  #{v.index} {v.run_id} " + " ".join(f"{k}={_fmt(x)}" for k, x in v.values.items())
                       + f"  {status}\n")
            _write(sys.stdout, f"sweep {spec.name}: {len(variants)} variants, {n_bad} invalid; metrics: "
                               + ", ".join(m.spec for m in spec.metrics) + "\n")
            return EXIT_OK
        if args.measure:
            measure(spec, workers=args.workers or None, batch=args.batch if args.batch != "auto" else None,
                    scheduler=args.scheduler)
            return EXIT_OK
        out = args.out or Path("runs") / f"sweep_{spec.name}.parquet".replace("sweep_sweep_", "sweep_")
        res = run_sweep(spec, out=out, workers=args.workers, scheduler=args.scheduler, batch=args.batch,
                        resume=not args.no_resume, retry_failed=args.retry_failed, progress=not args.quiet)
    except (SweepError, SceneError) as e:
        _write(sys.stderr, f"error: {e}\n")
        return EXIT_USAGE
    meta = dict(spec.meta())
    if not args.quiet:
        _print_table(res.rows, meta, sys.stdout)
    rate = f", {res.runs_per_second:.2f} runs/s" if res.n_run and res.wall > 0 else ""
    _write(sys.stdout,
           f"sweep {spec.name}: {res.n_total} variants ({res.n_run} run now, {res.n_skipped} from {res.out}), "
           f"{res.n_failed} failed, {res.n_invalid} invalid; {res.wall:.2f} s{rate}"
           + (f" on {res.mode}" if res.mode else "")
           + (f" in {res.tasks} tasks" if res.workers and res.mode != "in-process" and res.tasks else "") + "\n")
    _write(sys.stdout, f"results: {res.out}\n")
    if not args.no_plot and res.rows:
        png = res.out.with_suffix(".png")
        plot_sweep(res.rows, meta, png)
        _write(sys.stdout, f"plot: {png}\n")
    if res.interrupted:
        _write(sys.stderr, f"interrupted: {len(res.rows)} of {res.n_total} done; run the same command again to resume\n")
        return EXIT_INTERRUPTED
    if res.rows and all(r["status"] != "ok" for r in res.rows):
        return EXIT_FAILED
    return EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(sweep_main())
