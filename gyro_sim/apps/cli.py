"""The ``gyro-sim`` command.

    gyro-sim run SCENE [--duration S] [--out DIR] [--record BAG] [--fidelity F] [--ros [--mode M]]
                   [--live [--rate-factor F] [--live-port N] [--live-host H] [--live-wait N] [--live-hold S]]
    gyro-sim scenes                 list the built-in scenes
    gyro-sim info BAG               topics, counts, duration, scene of a recorded run
    gyro-sim plot BAG [--out PNG]   spin rate, θ, L and stator currents of a recorded run
    gyro-sim replay BAG [--rate F] [--wait-for-subscribers N]  publish a bag over ROS 2 with its timing;
                                    --check re-simulates it
    gyro-sim phase SCENE|BAG        (θ, φ) phase portrait over the averaged ψ-switching model
    gyro-sim bag recover BAG        rebuild a bag whose recording was cut (kill -9, crash, power loss)
    gyro-sim bench [--quick]        work-precision benchmark (table + PNG)
    gyro-sim sweep SCENE|SWEEP ...  parameter sweeps and Monte Carlo on Dask
    gyro-sim flywheel-plan ...      wheel axis, turn and speed profile for a wanted attitude ([S]);
                                    --write-scene FILE writes a ready-to-run scene
    gyro-sim ros-index [PREFIX]     the ament index of an editable install, for `ros2 run gyro_sim ...`
    gyro-sim api-docs [OUT_DIR]     the API reference (HTML, pdoc) of gyro_sim and gyro_ctl

Scene errors (``gyro_sim.scene.SceneError``) are reported as ``error: <message>``
on stderr with exit status 2, without a traceback.

Exit status: 0 a complete run; 1 a run that failed (its bag could not be written whole: it is closed with what
fit); 2 bad usage, a bad scene or an unusable output path (checked before the run); 128 + the signal for a run
ended by a signal (130 Ctrl-C / SIGINT, 143 SIGTERM, 129 SIGHUP): a recorded run's bag is then closed with
everything up to the signal and summarised; 141 (128 + SIGPIPE, what ``cat`` or ``yes`` give) when the reader of
its output went away early (``gyro-sim scenes | head -1``): no traceback, the rest of the output is dropped.

A command that needs an optional dependency (a pip extra of setup.py: ``ros``, ``sweep``, ``live``, ``data``,
``docs``) checks for it before doing anything and, where it is missing, says so in one ``error:`` line naming the
extra to install, status 2 (:mod:`gyro_sim.extras`).
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from gyro_sim import __version__
from gyro_sim.common.extras import MissingExtra
from gyro_sim.compiled.compile_watch import hold_interrupts_while_compiling, sigint_came
from gyro_sim.io.signals import wrapped_interrupt
from gyro_sim.apps.console import _write

# the commands, by group, and what they share (re-exported: `cli._cmd_scenes` and the like are the names the parser
# reads at each call, so a test may patch them here)
from gyro_sim.apps.cli_bag import (  # noqa: F401
    PLOT_SAMPLES, _bag_result, _bag_scene, _cmd_bag_recover, _cmd_info, _cmd_plot, _cmd_replay, _error_row,
    _format_recovery, _info_rows, _seconds, _summarise_bag, _unreadable,
)
from gyro_sim.apps.cli_common import (  # noqa: F401
    EXIT_BROKEN_PIPE, EXIT_FAILURE, EXIT_OK, EXIT_USAGE, _error, _num, _ros_missing, format_summary,
)
from gyro_sim.apps.cli_run import (  # noqa: F401
    _cmd_run, _interrupted, _live_usage, _Progress, _run_ros, _signal_name, _start_live, _unwritable_out,
)
from gyro_sim.apps.cli_tools import (  # noqa: F401
    _cmd_api_docs, _cmd_flywheel_plan, _cmd_phase, _cmd_ros_index, _cmd_scenes, _cmd_warmup,
)

__all__ = ["main", "build_parser", "format_summary"]


def _positive_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number of seconds: {text!r}") from None
    if not math.isfinite(value) or value <= 0.0:
        raise argparse.ArgumentTypeError(f"duration must be a positive number of seconds, got {text}")
    return value


def _run_epilog() -> str:
    from gyro_sim.ros.launch import CONTROLLER_GRACE, STOP_GRACE  # (no rclpy there)

    return f"""\
exit status:
  0    the run reached its end (summary and plot written)
  1    the bag could not be written whole (e.g. the disk filled; with --ros too): it is closed
       with what fit
  2    bad usage, a scene error, an unusable --record/--out (checked before the run), or (--ros)
       a node that failed: one 'error:' line
  130  stopped by SIGINT (Ctrl-C)   }} with --record or --ros: the summary and plot of what was
  143  stopped by SIGTERM           }} recorded; the bag is complete, marked interrupted
  129  stopped by SIGHUP (the terminal closed)

a recorded run writes its bag as it goes: a kill -9 or a crash loses at most the last
second; 'gyro-sim bag recover BAG' rebuilds such a bag.

with --ros: SIGINT/SIGTERM to gyro-sim (alone or with its process group) is passed to
both nodes, which close the bag; a node still running {STOP_GRACE:g} s later (the controller:
{CONTROLLER_GRACE:g} s) is killed (SIGKILL, said on stderr). The nodes die with gyro-sim, also if
it is killed (SIGKILL): they get SIGTERM and close the bag (gyro_sim/ros/launch.py).
"""


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
        description="Simulate SCENE, print a summary of the final state and write\n"
                    "DIR/<scene>.png (spin rate, nutation angle, stator currents).",
        epilog=_run_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    run.add_argument("scene", metavar="SCENE",
                     help="a built-in scene name (see 'gyro-sim scenes') or a path to a scene YAML file")
    run.add_argument("--duration", metavar="S", type=_positive_seconds, default=None,
                     help="simulated time in seconds (default: the scene's duration)")
    run.add_argument("--set", metavar="KEY=VALUE", action="append", default=[],
                     help="change a value of the scene, a dotted key from its top (repeatable; the syntax of "
                          "gyro-sim sweep --set): --set stators.2.current=0.5 --set initial.theta=0.1 "
                          "--set controller=null (docs/scenes.md)")
    run.add_argument("--out", metavar="DIR", type=Path, default=Path("runs"),
                     help="folder for the plot (default: runs/)")
    run.add_argument("--record", metavar="BAG", type=Path, default=None,
                     help="record the run as a rosbag2 bag (MCAP) in this new directory")
    run.add_argument("--ros", action="store_true",
                     help="run the simulator and controller nodes as separate ROS 2 processes (DDS on localhost)")
    run.add_argument("--mode", choices=("lockstep", "realtime", "freerun"), default="lockstep",
                     help="with --ros: timing mode of the simulator node (default: lockstep)")
    run.add_argument("--node-cpu", metavar="CPU", default="auto",
                     help="with --ros: the CPU both nodes run on (default auto: in lockstep one of this process's, "
                          "the bag's writer on the others; none: left to the scheduler; or a CPU number). On one CPU "
                          "a lockstep tick's hand-over stays prompt beside busy cores")
    run.add_argument("--rate-factor", metavar="F", type=float, default=1.0,
                     help="with --ros --mode realtime, or --live: simulated seconds per wall second (default 1)")
    run.add_argument("--live", action="store_true",
                     help="serve the run over the Foxglove WebSocket protocol while it runs, paced to the wall clock "
                          "x --rate-factor (in-process; needs pip install 'gyro_sim[live]'; the scene's Foxglove "
                          "layout is written to OUT/SCENE_foxglove_layout.json; docs/live.md)")
    run.add_argument("--live-host", metavar="HOST", default="127.0.0.1",
                     help="with --live: address to listen on (default 127.0.0.1: this machine only)")
    run.add_argument("--live-port", metavar="N", type=int, default=8765,
                     help="with --live: TCP port (default 8765, Foxglove's; 0 = a free one, printed)")
    run.add_argument("--live-wait", metavar="N", type=int, default=0,
                     help="with --live: start the run once N channel subscriptions are made, so a client connected "
                          "first misses no sample (default 0: start at once)")
    run.add_argument("--live-hold", metavar="S", type=float, default=2.0,
                     help="with --live: after the run, keep serving until the clients unsubscribe, at most S wall "
                          "seconds (default 2), so they get the last samples")
    run.add_argument("--fidelity", choices=("full", "averaged", "auto"), default=None,
                     help="model fidelity instead of the scene's (in-process only; gyro_sim/engine/fidelity.py)")
    run.add_argument("--quiet", action="store_true", help="no progress line")
    run.add_argument("--force", action="store_true",
                     help="run a scene whose plan exceeds the step budget (1e9 steps, gyro_sim/engine/budget.py); "
                          "without it such a run is refused before it starts, saying which tolerance or parameter "
                          "to loosen")
    run.set_defaults(func=_cmd_run)

    info = sub.add_parser("info", help="describe a recorded bag",
                          description="Topics with types and counts, duration, scene and version of a bag.")
    info.add_argument("bag", metavar="BAG", type=Path)
    info.set_defaults(func=_cmd_info)

    plot = sub.add_parser("plot", help="plot a recorded bag",
                          description="Write a PNG of spin rate, θ, L components and stator currents of a bag.")
    plot.add_argument("bag", metavar="BAG", type=Path)
    plot.add_argument("--out", metavar="PNG", type=Path, default=None, help="default: BAG/<scene>.png")
    plot.set_defaults(func=_cmd_plot)

    replay = sub.add_parser("replay", help="replay a bag over ROS 2, or re-simulate it (--check)",
                            description="Publish every topic of BAG with its original timing (x --rate), /clock "
                                        "included; with --check, re-simulate the bag's embedded scene with its "
                                        "recorded commands and report the largest difference (expected 0).")
    replay.add_argument("bag", metavar="BAG", type=Path)
    replay.add_argument("--rate", metavar="F", type=float, default=1.0, help="playback speed factor (default 1)")
    replay.add_argument("--wait-for-subscribers", metavar="N", type=int, default=0,
                        help="wait until N subscriptions (summed over the topics) are matched before publishing")
    replay.add_argument("--check", action="store_true", help="re-simulate instead of publishing")
    replay.set_defaults(func=_cmd_replay)

    phase = sub.add_parser("phase", help="phase portrait (θ, φ) of a run over the analytic curves of [K] §3",
                           description="Run SCENE in-process (or read BAG) and draw its (θ, φ) phase portrait over "
                                       "the averaged ψ-switching model: ellipsoid (3.5), equilibria, limit cycles.")
    phase.add_argument("source", metavar="SCENE|BAG", help="a scene (name or YAML) or a recorded bag directory")
    phase.add_argument("--duration", metavar="S", type=_positive_seconds, default=None)
    phase.add_argument("--out", metavar="PNG", type=Path, default=None, help="default: runs/<scene>_phase.png")
    phase.set_defaults(func=_cmd_phase)

    bag = sub.add_parser("bag", help="bag tools: recover a recording that was cut",
                         description="Tools for recorded bags.")
    bag_sub = bag.add_subparsers(dest="bag_command", metavar="TOOL", required=True)
    recover = bag_sub.add_parser(
        "recover", help="rebuild a bag whose recording was cut (kill -9, crash or power loss)",
        description="Rebuild BAG, a recording that was not closed (no metadata.yaml, an MCAP file without summary "
                    "and footer), into a complete bag: every whole message is kept, the cut tail is dropped, "
                    "custom_data says gyro_sim.end = interrupted: recovered (...). The damaged original stays "
                    "as BAG/<name>.mcap.damaged (and an old metadata.yaml as metadata.yaml.damaged); a complete "
                    "bag is refused. Details: gyro_sim/io/bag_repair.py.")
    recover.add_argument("bag", metavar="BAG", type=Path, help="the bag directory")
    recover.set_defaults(func=_cmd_bag_recover)

    # listed here for `gyro-sim --help`; main() hands their arguments to bench_main / sweep_main
    sub.add_parser("bench", help="work-precision benchmark (gyro-sim bench --help)", add_help=False)

    sub.add_parser("sweep", help="parameter sweeps and Monte Carlo on Dask (gyro-sim sweep --help)", add_help=False)

    fp = sub.add_parser(
        "flywheel-plan",
        help="plan a reorientation of the body by its internal flywheel ([S], docs/flywheel.md)",
        description="Wheel axis (body frame), wheel turn and a trapezoid speed profile that take a body at rest "
                    "(zero kinetic moment) from the initial to the target attitude ([S] (21)-(24), (29)). "
                    "Attitudes are quaternions w x y z, body to case, or z-x-z Euler angles psi theta phi (rad). "
                    "Give two of --peak-speed, --ramp, --duration (or --duration alone; default --duration 1).",
    )
    fp.add_argument("--inertia", metavar="J", type=float, nargs=3, required=True,
                    help="principal moments J1 J2 J3 of the body with the wheel locked, kg·m²")
    fp.add_argument("--wheel-inertia", metavar="JF", type=float, required=True,
                    help="axial moment of the wheel, kg·m²")
    tgt = fp.add_mutually_exclusive_group(required=True)
    tgt.add_argument("--target-quaternion", metavar="Q", type=float, nargs=4, help="target attitude w x y z")
    tgt.add_argument("--target-euler", metavar="A", type=float, nargs=3, help="target attitude psi theta phi, rad")
    ini = fp.add_mutually_exclusive_group()
    ini.add_argument("--initial-quaternion", metavar="Q", type=float, nargs=4,
                     help="initial attitude (default 1 0 0 0)")
    ini.add_argument("--initial-euler", metavar="A", type=float, nargs=3, help="initial attitude psi theta phi, rad")
    fp.add_argument("--peak-speed", metavar="W", type=float, default=None, help="peak wheel speed, rad/s")
    fp.add_argument("--ramp", metavar="S", type=float, default=None, help="acceleration (and deceleration) time, s")
    fp.add_argument("--duration", metavar="S", type=float, default=None, help="start-to-stop time of the wheel, s")
    fp.add_argument("--start", metavar="S", type=float, default=0.0, help="time the wheel starts, s (default 0)")
    fp.add_argument("--hold", metavar="S", type=float, default=0.5,
                    help="with --write-scene: simulated time after the wheel stops, s (default 0.5)")
    fp.add_argument("--write-scene", metavar="FILE", type=Path, default=None,
                    help="write a ready-to-run scene YAML (gyro-sim run FILE); "
                         "refuses an existing file without --force")
    fp.add_argument("--force", action="store_true", help="with --write-scene: overwrite FILE")
    fp.set_defaults(func=_cmd_flywheel_plan)

    idx = sub.add_parser(
        "ros-index",
        help="make `ros2 run gyro_sim ...` work from an editable install (pip install -e)",
        description="Lay out what `pip install .` and `colcon build` install for ROS 2 and `pip install -e` does "
                    "not: the ament index entries of gyro_sim and gyro_ctl, their package.xml, config/, launch/ "
                    "and the `ros2 run` executables, under PREFIX (default: this Python's prefix, e.g. the venv), "
                    "as symlinks into the source tree. Then AMENT_PREFIX_PATH=PREFIX finds the packages. "
                    "Idempotent.",
    )
    idx.add_argument("prefix", metavar="PREFIX", type=Path, nargs="?", default=None,
                     help=f"install prefix (default: {sys.prefix})")
    idx.set_defaults(func=_cmd_ros_index)

    scenes = sub.add_parser(
        "scenes",
        help="list the built-in scenes",
        description="List the built-in scenes with a one-line description of each.",
    )
    scenes.set_defaults(func=_cmd_scenes)

    api = sub.add_parser(
        "api-docs",
        help="write the API reference of gyro_sim and gyro_ctl (HTML, from the docstrings; needs the docs extra)",
        description="Generate the API reference (pdoc) of the public modules of gyro_sim and gyro_ctl from their "
                    "docstrings into OUT_DIR (open OUT_DIR/index.html). Modules whose import needs an optional "
                    "dependency that is not installed (gyro_sim.ros without rclpy) are left out, with a note. "
                    "Needs the 'docs' extra (pdoc); docs/api.md.",
    )
    api.add_argument("out", metavar="OUT_DIR", type=Path, nargs="?", default=Path("runs/api"),
                     help="folder for the HTML (default: runs/api)")
    api.set_defaults(func=_cmd_api_docs)

    warm = sub.add_parser(
        "warmup",
        help="compile the numba kernels of scenes ahead of their first run",
        description="Run each scene (default: every built-in one) for a few ms so that every kernel it uses is "
                    "compiled into numba's on-disk cache (.ci/setup does this once after installing).",
    )
    warm.add_argument("scenes", nargs="*", metavar="SCENE", help="built-in names or YAML paths (default: all built-in)")
    warm.set_defaults(func=_cmd_warmup)
    return parser


def main(argv=None) -> int:
    """Entry point of ``gyro-sim``; returns the exit status.

    A missing optional dependency (:class:`gyro_sim.extras.MissingExtra`) ends the command with one ``error:`` line,
    status 2; stdout closed by its reader (``gyro-sim scenes | head -1``) ends it quietly, status 141. (Its first
    statement is the ``try``: a Ctrl-C from the call on is handled.)"""
    try:
        try:
            hold_interrupts_while_compiling()
            status = _main(argv)
        except MissingExtra as exc:
            status = _error(str(exc))
        except KeyboardInterrupt as exc:  # Ctrl-C / SIGTERM / SIGHUP where no command handled it (e.g. while
            status = _interrupted(exc)    # starting, or a second one while a stopped run is summarised)
        except (RuntimeError, ImportError) as exc:  # (a Ctrl-C inside an import: 3.11 wraps one in a class body's
            # __set_name__, C code that imports (NumPy's PyCapsule_Import) replaces it with an ImportError)
            interrupt = wrapped_interrupt(exc) or (KeyboardInterrupt() if sigint_came() else None)
            if interrupt is None:
                raise
            status = _interrupted(interrupt)
        except OSError as exc:  # a file system error on a path that the checks before the work did not foresee
            if isinstance(exc, BrokenPipeError) or exc.filename is None:
                raise
            from gyro_sim.common.paths import shown

            status = _error(f"{shown(exc.filename)}: {exc.strerror or exc}")
        except SystemExit:  # argparse's --help, --version or usage error: its output is flushed here too
            sys.stdout.flush()
            raise
        sys.stdout.flush()  # (inside the try: a pipe closed early fails here, with the buffered output)
    except BrokenPipeError:
        _drop_stdout()
        return EXIT_BROKEN_PIPE
    return status


def _drop_stdout() -> None:
    """Point stdout at /dev/null: the interpreter's last flush at exit then has nowhere to fail (the recipe of
    the Python docs, "Note on SIGPIPE")."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):  # (no file descriptor: a replaced sys.stdout)
        pass


def _main(argv) -> int:
    """Parse ``argv`` and run its command (what :func:`main` does, without its handling of pipes and extras)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] in ("bench", "sweep"):  # these parse their own options (with their own --help)
        if argv[0] == "bench":
            from gyro_sim.apps.bench import bench_main

            return bench_main(argv[1:])
        from gyro_sim.apps.sweep import sweep_main

        return sweep_main(argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
    bad = _unusable_path_arg(parser, args)
    if bad:
        return _error(bad)
    _one_line_accuracy_warnings()
    return args.func(args)


def _unusable_path_arg(parser: argparse.ArgumentParser, args) -> "str | None":
    """The one line refusing a path argument of the chosen command (``--record``, ``--out``, ``BAG``, ...) that no
    file system call could take (a name longer than the file system allows, a NUL: gyro_sim.common.paths), or
    None; checked before any work."""
    from gyro_sim.common.paths import path_problem

    actions = list(parser._actions)
    for name in (getattr(args, "command", None), getattr(args, "bag_command", None)):
        sub = next((a for a in actions if isinstance(a, argparse._SubParsersAction)), None)
        if sub is None or name not in sub.choices:
            break
        actions = list(sub.choices[name]._actions)
    for a in actions:
        value = getattr(args, a.dest, None)
        if a.type is Path and isinstance(value, Path):
            why = path_problem(value)
            if why:
                return f"{a.option_strings[0] if a.option_strings else a.metavar or a.dest} {why}"
    return None


def _one_line_accuracy_warnings() -> None:
    """Show the runs' accuracy warnings (gyro_sim.accuracy.AccuracyWarning) as one ``warning:`` line each."""
    import warnings

    from gyro_sim.scenes.accuracy import AccuracyWarning

    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, AccuracyWarning):
            _write(sys.stderr, f"warning: {message}\n")
        else:
            shown(message, category, filename, lineno, file, line)

    warnings.showwarning = show


if __name__ == "__main__":
    sys.exit(main())
