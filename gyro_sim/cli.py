"""The ``gyro-sim`` command.

    gyro-sim run SCENE [--duration S] [--out DIR]   simulate, summarise, plot
    gyro-sim scenes                                 list the built-in scenes

Scene errors (``gyro_sim.scene.SceneError``) are reported as ``error: <message>``
on stderr with exit status 2, without a traceback.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from gyro_sim import __version__

__all__ = ["main", "build_parser", "format_summary"]

EXIT_OK = 0
EXIT_USAGE = 2  # argparse's status for bad usage; scene errors use it too


def _positive_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number of seconds: {text!r}") from None
    if not math.isfinite(value) or value <= 0.0:
        raise argparse.ArgumentTypeError(f"duration must be a positive number of seconds, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="gyro-sim",
        description="Simulate an electrodynamically controlled gyroscope rotor.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    run = sub.add_parser(
        "run",
        help="simulate a scene, print a summary and write a plot",
        description="Simulate SCENE, print a summary of the final state and write "
                    "DIR/<scene>.png (spin rate, nutation angle, stator currents).",
    )
    run.add_argument("scene", metavar="SCENE",
                     help="a built-in scene name (see 'gyro-sim scenes') or a path to a scene YAML file")
    run.add_argument("--duration", metavar="S", type=_positive_seconds, default=None,
                     help="simulated time in seconds (default: the scene's duration)")
    run.add_argument("--out", metavar="DIR", type=Path, default=Path("runs"),
                     help="folder for the plot (default: runs/)")
    run.set_defaults(func=_cmd_run)

    scenes = sub.add_parser(
        "scenes",
        help="list the built-in scenes",
        description="List the built-in scenes with a one-line description of each.",
    )
    scenes.set_defaults(func=_cmd_scenes)
    return parser


# --- output -----------------------------------------------------------------

def _write(stream, text: str) -> None:
    """Write text, replacing characters the stream's encoding cannot show (θ, ·)."""
    try:
        stream.write(text)
    except UnicodeEncodeError:
        enc = getattr(stream, "encoding", None) or "ascii"
        stream.write(text.encode(enc, "replace").decode(enc))


def _num(value, fmt: str) -> str:
    if value is None:
        return "-"
    try:
        return format(value, fmt)
    except (TypeError, ValueError):
        return str(value)


def format_summary(name: str, summary: dict, plot_path=None) -> str:
    """The summary table of a run, from ``RunResult.summary()``.

    Keys used: spin_rate (rad/s), spin_rev_s (rev/s), theta_deg (deg), L_norm
    (N·m·s), energy (J), t_end (s), wall_time (s), steps, realtime_factor.
    Missing keys are shown as '-'.
    """
    s = summary.get
    rows = [
        ("scene", str(name)),
        ("final spin rate", f"{_num(s('spin_rate'), '.6g')} rad/s  ({_num(s('spin_rev_s'), '.6g')} rev/s)"),
        ("final θ", f"{_num(s('theta_deg'), '.6g')} deg"),
        ("|L|", f"{_num(s('L_norm'), '.6g')} N·m·s"),
        ("kinetic energy", f"{_num(s('energy'), '.6g')} J"),
        ("simulated time", f"{_num(s('t_end'), '.6g')} s"),
        ("wall time", f"{_num(s('wall_time'), '.3f')} s"),
        ("steps", _num(s('steps'), 'd')),
        ("real-time factor", _num(s('realtime_factor'), '.4g')),
    ]
    if plot_path is not None:
        rows.append(("plot", str(plot_path)))
    width = max(len(label) for label, _ in rows)
    return "".join(f"{label:<{width}}  {value}\n" for label, value in rows)


def _error(message: str) -> int:
    _write(sys.stderr, f"error: {message}\n")
    return EXIT_USAGE


# --- commands ---------------------------------------------------------------

def _cmd_run(args) -> int:
    # Imported here so that --help works fast and without the numerical stack.
    from gyro_sim import plotting
    from gyro_sim import scene as scene_mod
    from gyro_sim import simulate

    try:
        scene = scene_mod.load_scene(args.scene)
        result = simulate.run(scene, duration=args.duration)
    except scene_mod.SceneError as exc:
        return _error(str(exc))

    name = getattr(scene, "name", None) or Path(str(args.scene)).stem
    png = Path(args.out) / f"{name}.png"
    try:
        plotting.plot_run(result, png)
    except OSError as exc:
        return _error(f"cannot write the plot {png}: {exc.strerror or exc}")
    _write(sys.stdout, format_summary(name, result.summary(), png))
    return EXIT_OK


def _cmd_scenes(args) -> int:
    from gyro_sim import scene as scene_mod

    scenes = scene_mod.builtin_scenes()
    if not scenes:
        _write(sys.stdout, "no built-in scenes\n")
        return EXIT_OK
    width = max(len(n) for n in scenes)
    status = EXIT_OK
    for name in sorted(scenes):
        try:
            desc = scene_mod.load_scene(scenes[name]).description or ""
            line = desc.strip().splitlines()[0] if desc.strip() else ""
        except scene_mod.SceneError as exc:
            line = f"[cannot load: {exc}]"
            status = EXIT_USAGE
        _write(sys.stdout, f"{name:<{width}}  {line}\n".rstrip() + "\n")
    return status


def main(argv=None) -> int:
    """Entry point of ``gyro-sim``; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
