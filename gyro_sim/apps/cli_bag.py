"""The ``gyro-sim`` commands on recorded bags (:mod:`gyro_sim.apps.cli`): ``info``, ``plot``, ``replay`` and
``bag recover``, and the summary of a bag that ``run --record`` / ``--ros`` print."""
from __future__ import annotations

import math
import sys
from pathlib import Path

from gyro_sim.apps.console import _write
from gyro_sim.apps.cli_common import (
    EXIT_FAILURE, EXIT_OK, EXIT_USAGE, _error, _num, _ros_missing, format_summary,
)


#: samples of a bag read for its summary and plot (every k-th and the last)
PLOT_SAMPLES = 20_000


def _bag_scene(b):
    """The bag's embedded scene (a Scene: stator axes for the plot's slip), or None if it has none or it is unreadable."""
    from gyro_sim.io.results import _bag_scene as embedded_scene

    try:
        return embedded_scene(b, None)
    except Exception:  # noqa: BLE001 - an old or damaged bag: the plot goes without slip
        return None


class NoSamples(ValueError):
    """A bag that holds no state sample (its recording was stopped before the first one): valid, but with nothing
    to summarise or plot; the message says so in one line."""


def no_samples(bag, info: dict) -> str:
    """The one line describing a bag without a state sample, from its :func:`~gyro_sim.io.recording.bag_info`."""
    return (f"the bag {bag} holds no state sample: its recording was stopped before the first one "
            f"(end: {info.get('end_reason') or 'not recorded'})")


def _sample_count(info: dict):
    """The state samples of a bag from its :func:`~gyro_sim.io.recording.bag_info`, None if it has no such topic."""
    from gyro_sim.io.messages import TOPIC_KINETIC_MOMENT

    topic = info["topics"].get(TOPIC_KINETIC_MOMENT)
    return None if topic is None else int(topic.get("count") or 0)


def _bag_result(bag: Path):
    """A RunResult-like view of a recorded bag (for the summary and the plot)."""
    from types import SimpleNamespace

    import numpy as np

    from gyro_sim.io.recording import bag_info, read_bag

    b = read_bag(bag, max_samples=PLOT_SAMPLES)  # (thinned: memory bounded however long the run)
    info = bag_info(bag)
    if not len(b.t):
        raise NoSamples(no_samples(bag, info))
    J = None
    try:
        from gyro_sim.scenes.scene_text import parse_scene_text

        J = np.array(parse_scene_text(b.scene_text)["rotor"]["inertia"], dtype=float)
    except Exception:
        pass
    energy = 0.5 * np.sum(b.omega_b**2 * J, axis=1) if J is not None else np.full(len(b.t), np.nan)
    from gyro_sim.engine.simulate import error_summary
    from gyro_sim.io.results import bag_commands, parse_error_estimate

    res = SimpleNamespace(t=b.t, L=b.L, q=b.q, omega_b=b.omega_b, euler=b.euler, current=b.current,
                          field_rate=b.rate, stator_names=b.stator_names, commands=bag_commands(b),
                          scene=_bag_scene(b) or SimpleNamespace(name=b.scene_name or bag.name))
    wall = info["custom"].get("gyro_sim.wall_time")
    steps = info["custom"].get("gyro_sim.steps")
    est = parse_error_estimate(info["custom"].get("gyro_sim.error_estimate"))
    summary: dict = {"spin_rate": float(b.omega_b[-1, 2]), "spin_rev_s": float(b.omega_b[-1, 2] / (2 * math.pi)),
               "theta_deg": float(np.degrees(b.euler[-1, 1])), "L_norm": float(np.linalg.norm(b.L[-1])),
               "energy": float(energy[-1]), "t_end": float(b.t[-1]),
               "wall_time": float(wall) if wall else None, "steps": int(steps) if steps else None,
               "realtime_factor": float(b.t[-1]) / float(wall) if wall else None}
    if est is not None:
        summary.update(error_summary(est))
    end = str(info.get("end_reason") or "")
    if end.startswith("failed:"):
        summary["failure"] = end
    return res, summary, b, info


def _unreadable(bag: Path, exc: Exception) -> int:
    """The one error line for a bag that cannot be read: a recording that was not closed is named as
    such, with the command that recovers it. A Ctrl-C that ``exc`` wraps (one that stopped a lazy import) is
    raised again: it is an interruption, not a bag's fault."""
    from gyro_sim.io.signals import reraise_interrupt

    reraise_interrupt(exc)
    from gyro_sim.io.bag_repair import not_closed_message

    if isinstance(exc, NoSamples):  # (valid, but nothing to show)
        return _error(f"{exc}: nothing to plot")
    return _error(not_closed_message(bag) or f"cannot read the bag {bag}: {exc}")


def _summarise_bag(bag: Path, png: Path) -> int:
    from gyro_sim.io import plotting

    try:
        res, summary, b, info = _bag_result(bag)
    except NoSamples as exc:  # (a run stopped before its first sample: said, not an error)
        _write(sys.stderr, f"{exc}\n")
        return EXIT_OK
    except Exception as exc:  # a bag that cannot be read
        return _unreadable(bag, exc)
    plotting.plot_run(res, png)
    _write(sys.stdout, format_summary(res.scene.name, summary, png))
    _write(sys.stdout, f"{'bag':<16}  {bag} ({info['message_count']} messages)\n")
    if b.status:
        _write(sys.stdout, f"{'last status':<16}  {b.status[-1]}\n")
    if summary.get("failure"):  # (the run's state broke: the bag holds it up to the last sound sample)
        _write(sys.stderr, f"error: the run {summary['failure']}\n")
        return EXIT_FAILURE
    return EXIT_OK


def _cmd_info(args) -> int:
    from gyro_sim.io.recording import bag_info

    try:
        info = bag_info(args.bag)
    except Exception as exc:
        return _unreadable(args.bag, exc)
    rows = _info_rows(info)
    width = max(len(r[0]) for r in rows)
    _write(sys.stdout, "".join(f"{a:<{width}}  {b}\n" for a, b in rows))
    tw = max(len(t) for t in info["topics"]) if info["topics"] else 0
    for topic, ti in info["topics"].items():
        _write(sys.stdout, f"  {topic:<{tw}}  {ti['type']:<34} {ti['count']:>8}\n")
    return EXIT_OK


def _seconds(value) -> str:
    """A time in seconds to 3 significant digits (whole seconds from 1000 s up), with its unit."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        return str(value)
    return f"{v:.0f} s" if abs(v) >= 1000 else f"{v:.3g} s"


def _info_rows(info: dict) -> list:
    """(label, value) rows of ``gyro-sim info`` from :func:`gyro_sim.recording.bag_info`: one duration (the
    recorded span; the planned one beside it where the run ended early), times with units, the error estimate
    as in the run summary, then any other custom_data key as it is."""
    custom = {k.removeprefix("gyro_sim."): v for k, v in info["custom"].items()}
    span = f"{info['duration']:.6g} s (t = {info['start']:.6g} to {info['end']:.6g} s"
    planned = custom.get("planned_duration")
    try:
        early = planned is not None and abs(float(planned) - info["end"]) > 1e-9 * max(1.0, abs(float(planned)))
    except (TypeError, ValueError):
        early = False
    span += f"; planned {_num(float(planned), '.6g')} s)" if early else ")"
    rows = [("bag", str(info["path"])),
            ("storage", f"{info['storage']} (bag format version {info['bag_version']})"),
            ("scene", str(info["scene_name"])), ("gyro_sim version", str(info["version"])),
            ("duration", span), ("messages", str(info["message_count"])), ("end", str(info["end_reason"]))]
    if _sample_count(info) == 0:
        rows.append(("samples", "none: the recording was stopped before the first state sample"))
    if "mode" in custom:
        rows.append(("mode", str(custom["mode"])))
    if custom.get("wall_time"):
        wall = _seconds(custom["wall_time"])
        if custom.get("compile_time") and float(custom["compile_time"]) > 0:
            wall += f" (+ {_seconds(custom['compile_time'])} compiling the kernels, first use)"
        rows.append(("wall time", wall))
    if "steps" in custom:
        rows.append(("steps", str(custom["steps"])))
    if "control_period" in custom:
        rows.append(("control period", _seconds(custom["control_period"])))
    if custom.get("error_estimate") and _sample_count(info) != 0:  # (no sample: no run to estimate)
        rows.append(_error_row(custom["error_estimate"]))
    shown = {"scene_name", "version", "end", "scene", "duration", "planned_duration", "mode", "wall_time",
             "compile_time", "steps", "control_period", "error_estimate"}
    rows += [(_label(k), _readable(k, v)) for k, v in sorted(custom.items()) if k not in shown]
    return rows


def _is_time(key: str) -> bool:
    """A custom_data key holding seconds (``latency_median_s``; not a rate, ``control_ticks_per_s``)."""
    return key.endswith("_s") and not key.endswith("_per_s")


def _label(key: str) -> str:
    """The row label of a custom_data key: words, without the unit suffix of a time (its value carries the unit)."""
    return (key[:-2] if _is_time(key) else key).replace("_", " ")


def _readable(key: str, value) -> str:
    """A custom_data value as shown by ``gyro-sim info``: a real number to 4 significant digits (a time ``*_s``
    below 1 s in ms: ``latency median  0.412 ms``), anything else (integers, texts) as it is."""
    text = str(value)
    try:
        v = float(text)
    except ValueError:
        return text
    if text.lstrip("-").isdigit() or not math.isfinite(v):
        return text
    if _is_time(key):
        return f"{v * 1e3:.3g} ms" if abs(v) < 1 else _seconds(v)
    return f"{v:.4g}"


def _error_row(text: str) -> tuple:
    """The ``estimated error`` row (as in the run summary) of a bag's ``gyro_sim.error_estimate``, or its raw
    text if it cannot be read."""
    from gyro_sim.engine.simulate import error_summary
    from gyro_sim.io.results import parse_error_estimate

    est = parse_error_estimate(text)
    if est is None:
        return ("error estimate", str(text))
    summary = error_summary(est)
    row = [r for r in format_summary("", summary).splitlines() if r.startswith("estimated error")]
    return ("estimated error", row[0].removeprefix("estimated error").strip()) if row else ("error estimate", str(text))


def _cmd_plot(args) -> int:
    from gyro_sim.io import plotting

    try:
        res, _, _, _ = _bag_result(args.bag)
    except Exception as exc:
        return _unreadable(args.bag, exc)
    png = args.out or args.bag / f"{res.scene.name}.png"
    plotting.plot_run(res, png)
    _write(sys.stdout, f"plot: {png}\n")
    return EXIT_OK


def _cmd_replay(args) -> int:
    if not args.check and _ros_missing("gyro-sim replay (without --check)"):
        return EXIT_USAGE
    if not (math.isfinite(args.rate) and args.rate > 0):
        return _error(f"--rate {args.rate}: must be a positive number")
    if args.wait_for_subscribers < 0:
        return _error(f"--wait-for-subscribers {args.wait_for_subscribers}: must be an integer ≥ 0")
    from gyro_sim.io.bag_repair import not_closed_message

    if (cut := not_closed_message(args.bag)) is not None:  # (neither the re-run nor the player could read it)
        return _error(cut)
    if args.check:
        from gyro_sim.io.rerun import rerun_bag
        from gyro_sim.scenes.scene import SceneError

        try:
            rep = rerun_bag(args.bag)
        except SceneError as exc:
            return _error(str(exc))
        except Exception as exc:  # a bag that cannot be read (damaged, not a bag)
            return _unreadable(args.bag, exc)
        if not rep["samples_recorded"]:
            from gyro_sim.io.recording import bag_info

            _write(sys.stdout, f"{no_samples(args.bag, bag_info(args.bag))}: nothing to re-run\n")
            return EXIT_OK
        d = rep["max_abs_diff"]
        _write(sys.stdout, f"re-ran {rep['samples_rerun']} samples (bag: {rep['samples_recorded']}); largest |Δ|: "
                           + ", ".join(f"{k} {v:.3g}" for k, v in d.items())
                           + (" — identical to the bit\n" if rep["identical"] else " — NOT identical\n"))
        return EXIT_OK if rep["identical"] else 1
    import subprocess

    from gyro_sim.ros.launch import ros_env

    return subprocess.call([sys.executable, "-m", "gyro_sim.ros.replay", str(args.bag), repr(float(args.rate)),
                            "--wait-for-subscribers", str(args.wait_for_subscribers)], env=ros_env())


def _cmd_bag_recover(args) -> int:
    from gyro_sim.io.bag_repair import RecoverError, recover_bag

    try:
        rep = recover_bag(args.bag)
    except RecoverError as exc:
        return _error(str(exc))
    _write(sys.stdout, _format_recovery(rep))
    return EXIT_OK


def _format_recovery(rep: dict) -> str:
    """What ``gyro-sim bag recover`` prints, from :func:`gyro_sim.bag_repair.recover_bag`'s report."""
    span = (f"t = {rep['start_ns'] / 1e9:.6g} to {rep['end_ns'] / 1e9:.6g} s"
            if rep["messages"] else "no time span")
    used = sum(1 for _, n in rep["topics"].values() if n)
    lines = [f"recovered {rep['path']}: {rep['messages']} messages on {used} of {len(rep['topics'])} topics, {span}",
             f"  scene     {rep['scene_name']}" + ("" if rep["scene_found"] else " (no scene found in the bag)")]
    if rep["cut"]:
        lines.append(f"  dropped   the last {rep['dropped_bytes']} of {rep['size']} bytes: {rep['stop']}")
    elif rep["bad_chunks"]:
        lines.append(f"  dropped   {len(rep['bad_chunks'])} damaged chunk(s) (below); the rest of the data section is "
                     f"whole, the {rep['dropped_bytes']} bytes after it (summary, footer) are rebuilt")
    else:
        lines.append(f"  dropped   no message: the data section is whole; the {rep['dropped_bytes']} bytes after it "
                     "(summary, footer) are rebuilt")
    for bad in rep["bad_chunks"]:
        lines.append(f"  skipped   {bad}")
    for kind, n in sorted(rep["not_copied"].items()):
        lines.append(f"  not kept  {n} {kind} record(s) (not carried over by the rosbag2 writer)")
    for old, aside in rep["set_aside"].items():
        lines.append(f"  kept      the {'damaged' if old.endswith('.mcap') else 'old'} {old} as {aside}")
    width = max((len(t) for t in rep["topics"]), default=0)
    lines += [f"  {t:<{width}}  {ty:<34} {n:>8}" for t, (ty, n) in sorted(rep["topics"].items())]
    return "".join(line + "\n" for line in lines)
