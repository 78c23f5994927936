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
from gyro_sim.apps.console import _write

__all__ = ["main", "build_parser", "format_summary"]

EXIT_OK = 0
EXIT_FAILURE = 1  # a run that failed (e.g. its bag could not be written whole)
EXIT_USAGE = 2  # argparse's status for bad usage; scene errors use it too
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE: the reader of stdout closed it early (as a shell reports `yes | head -1`)


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
  1    the bag could not be written whole (e.g. the disk filled): it is closed with what fit
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
    run.add_argument("--out", metavar="DIR", type=Path, default=Path("runs"),
                     help="folder for the plot (default: runs/)")
    run.add_argument("--record", metavar="BAG", type=Path, default=None,
                     help="record the run as a rosbag2 bag (MCAP) in this new directory")
    run.add_argument("--ros", action="store_true",
                     help="run the simulator and controller nodes as separate ROS 2 processes (DDS on localhost)")
    run.add_argument("--mode", choices=("lockstep", "realtime", "freerun"), default="lockstep",
                     help="with --ros: timing mode of the simulator node (default: lockstep)")
    run.add_argument("--rate-factor", metavar="F", type=float, default=1.0,
                     help="with --ros --mode realtime, or --live: simulated seconds per wall second (default 1)")
    run.add_argument("--live", action="store_true",
                     help="serve the run over the Foxglove WebSocket protocol while it runs, paced to the wall clock "
                          "x --rate-factor (in-process; needs pip install 'gyro_sim[live]'; layout: "
                          "config/foxglove_layout.json)")
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
                     help="model fidelity instead of the scene's (in-process only; gyro_sim/fidelity.py)")
    run.add_argument("--quiet", action="store_true", help="no progress line")
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
                    "bag is refused. Details: gyro_sim/bag_repair.py.")
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


# --- output -----------------------------------------------------------------

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
    (N·m·s), energy (J), t_end (s), wall_time (s), steps, realtime_factor, attitude (False: a run
    without attitude, whose θ is not known and whose spin rate is |Ω|), error_L, error_attitude,
    accuracy_rtol, accuracy_attitude, accuracy_met (the run's estimated error, gyro_sim.accuracy).
    Missing keys are shown as '-'.
    """
    s = summary.get
    no_att = s("attitude", True) is False
    rows = [
        ("scene", str(name)),
        ("final spin rate", f"{_num(s('spin_rate'), '.6g')} rad/s  ({_num(s('spin_rev_s'), '.6g')} rev/s)"
         + ("  (|Ω|)" if no_att else "")),
        ("final θ", "not integrated (output.attitude: false)" if no_att else f"{_num(s('theta_deg'), '.6g')} deg"),
        ("|L|", f"{_num(s('L_norm'), '.6g')} N·m·s"),
        ("kinetic energy", f"{_num(s('energy'), '.6g')} J"),
        ("simulated time", f"{_num(s('t_end'), '.6g')} s"),
        ("wall time", f"{_num(s('wall_time'), '.3f')} s"
         + (f"  (+ {s('compile_time'):.1f} s compiling the kernels, first use)" if s("compile_time") else "")),
        ("steps", _num(s('steps'), 'd')),
        ("real-time factor", _num(s('realtime_factor'), '.4g')),
    ]
    if s("error_L") is not None and s("error_L") == s("error_L"):  # (NaN: no estimate)
        eq = s("error_attitude")
        tol_q = s("accuracy_attitude")
        att = (f"attitude {eq:.2g} rad" + (f" ({tol_q:g})" if tol_q is not None and tol_q == tol_q else "")
               if eq is not None and eq == eq else "attitude not a result")
        rows.append(("estimated error", f"L {s('error_L'):.2g}" + (f" (rtol {s('accuracy_rtol'):g})"
                                                                  if s("accuracy_rtol") else "") + f", {att}"
                     + ("" if s("accuracy_met") is not False else "  (beyond the scene's accuracy)")))
    if plot_path is not None:
        rows.append(("plot", str(plot_path)))
    width = max(len(label) for label, _ in rows)
    return "".join(f"{label:<{width}}  {value}\n" for label, value in rows)


def _error(message: str) -> int:
    _write(sys.stderr, f"error: {message}\n")
    return EXIT_USAGE


def _ros_missing(what: str) -> bool:
    """True (after one ``error:`` line) if rclpy cannot be found: ``what`` needs the ROS 2 Python packages.

    Checked in this process before anything starts: the node processes would each end in a traceback."""
    from gyro_sim.common.extras import missing_message

    message = missing_message("ros", what)
    if message is not None:
        _error(message)
    return message is not None


# --- commands ---------------------------------------------------------------

class _Progress:
    """A one-line progress display on stderr (simulated time, real-time factor), for runs over 2 s wall."""

    def __init__(self, total: float, enabled: bool):
        import time

        self.time = time
        from gyro_sim.compiled.compile_watch import compile_seconds

        self.compiled = compile_seconds
        self.total, self.enabled = total, enabled
        self.w0, self.c0 = time.perf_counter(), compile_seconds()
        self.last = self.w0
        self.shown = False
        self.t = 0.0  # s, the last sample seen

    def __call__(self, samples: dict) -> None:
        if samples["t"].size:
            self.t = float(samples["t"][-1])
        now = self.time.perf_counter()
        if not self.enabled or now - self.last < 1.0 or now - self.w0 < 2.0:
            return
        self.last = now
        t = float(samples["t"][-1])
        wall = max(now - self.w0 - (self.compiled() - self.c0), 1e-9)  # (compile time left out)
        _write(sys.stderr, f"\r  t = {t:.6g} / {self.total:.6g} s  ({t / wall:.3g}x real time)   ")
        self.shown = True

    def close(self) -> None:
        if self.shown:
            _write(sys.stderr, "\n")
            self.shown = False


def _live_usage(args):
    """Why the --live options cannot be used (checked before any work), or None."""
    if args.ros:
        return ("--live serves an in-process run; with --ros, serve the nodes' topics with foxglove_bridge "
                "(ros2 launch foxglove_bridge foxglove_bridge_launch.xml), or drop --ros")
    if not (math.isfinite(args.rate_factor) and args.rate_factor > 0):
        return f"--rate-factor {args.rate_factor}: must be a positive number (simulated s per wall s)"
    if not 0 <= args.live_port <= 65535:
        return f"--live-port {args.live_port}: must be a TCP port, 0 to 65535 (0: a free one)"
    if args.live_wait < 0:
        return f"--live-wait {args.live_wait}: must be an integer >= 0"
    if not (math.isfinite(args.live_hold) and args.live_hold >= 0):
        return f"--live-hold {args.live_hold}: must be a number of seconds >= 0"
    if args.fidelity not in (None, "full"):
        return f"--fidelity {args.fidelity}: --live streams the full model's samples; drop --live or --fidelity"
    from gyro_sim.io.live import LiveUnavailable, require_foxglove

    try:
        require_foxglove()
    except LiveUnavailable as e:
        return str(e)
    return None


def _start_live(args, scene):
    """The live view's server (gyro_sim.live.LiveView), announced on stderr; (None, error text) if it cannot
    listen. Waits for --live-wait subscriptions."""
    from gyro_sim.io.live import LiveView
    from gyro_sim.scenes.scene import config_dir

    try:
        live = LiveView(scene, host=args.live_host, port=args.live_port, rate_factor=args.rate_factor)
    except Exception as exc:  # (the SDK's error for an address in use or not resolvable)
        return None, f"--live: cannot listen on {args.live_host}:{args.live_port}: {exc}"
    layout = config_dir() / "foxglove_layout.json"
    _write(sys.stderr, f"live view: ws://{args.live_host}:{live.port} (Foxglove: Open connection > Foxglove WebSocket; "
                       f"layout {layout}), {args.rate_factor:g}x real time\n")
    sys.stderr.flush()
    if args.live_wait:
        _write(sys.stderr, f"live view: waiting for {args.live_wait} subscription(s)\n")
        sys.stderr.flush()
        live.wait_for_subscriptions(args.live_wait)
    return live, None


def _cmd_run(args) -> int:
    if args.ros and not args.live and _ros_missing("gyro-sim run --ros"):
        return EXIT_USAGE
    if args.live:
        bad = _live_usage(args)
        if bad:
            return _error(bad)
    # Imported here so that --help works fast and without the numerical stack.
    from gyro_sim.io import plotting
    from gyro_sim.scenes import scene as scene_mod
    from gyro_sim.engine import simulate

    if args.record is not None and args.record.exists():
        return _error(f"--record {args.record}: already exists; give a new directory")
    bad = _unwritable_out(args.out)
    if bad:
        return _error(bad)
    if args.record is not None:
        from gyro_sim.io.recording import RecordingError, check_write_target

        try:
            check_write_target(args.record, "--record")
        except (RecordingError, FileExistsError) as exc:
            return _error(str(exc))
    if args.ros and args.fidelity not in (None, "full"):
        return _error(f"--fidelity {args.fidelity}: the ROS simulator node runs the full model; drop --ros or --fidelity")
    try:
        scene = scene_mod.load_scene(args.scene, overrides={"fidelity": args.fidelity} if args.fidelity else None)
    except scene_mod.SceneError as exc:
        return _error(str(exc))
    name = getattr(scene, "name", None) or Path(str(args.scene)).stem
    if args.ros:
        return _run_ros(args, scene, name)
    from gyro_sim.compiled.compile_watch import announce_compiles

    announce_compiles()  # one line where numba compiles (a first use), before the long pause it explains
    from gyro_sim.io.recording import RecordingError, exit_status, record_run, sigterm_as_interrupt

    progress = _Progress(args.duration or scene.duration, not args.quiet and sys.stderr.isatty())
    png = Path(args.out) / f"{name}.png"
    live = None
    try:
        on_samples = progress
        if args.live:
            with sigterm_as_interrupt():  # (Ctrl-C / SIGTERM while waiting for --live-wait)
                live, bad = _start_live(args, scene)
            if bad:
                return _error(bad)

            def on_samples(s, live=live):
                progress(s)
                live(s)
        if args.record is not None:
            # streamed: the bag is written as the run goes (a signal or a full disk leaves it closed with
            # everything up to then); it integrates the attitude whatever output.attitude says (/gyro/imu needs it)
            # (keep_bytes=0: the summary and the plot need only its preview, so memory stays flat)
            result = record_run(scene, args.record, duration=args.duration, on_samples=on_samples, keep_bytes=0)
        else:
            with sigterm_as_interrupt():
                # --live: the attitude is integrated whatever output.attitude says (/tf and /gyro/imu need it)
                result = simulate.run(scene, duration=args.duration, on_samples=on_samples,
                                      **({"attitude": True} if live is not None else {}))
        if live is not None:
            try:
                with sigterm_as_interrupt():
                    live.hold(args.live_hold)
            except KeyboardInterrupt:  # (the run is complete: a signal here only stops the hold)
                pass
    except scene_mod.SceneError as exc:
        return _error(str(exc))
    except RecordingError as exc:
        progress.close()
        _error(str(exc))
        return EXIT_FAILURE
    except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM, SIGHUP
        progress.close()
        code = exit_status(exc)
        if args.record is None:
            _write(sys.stderr, f"interrupted ({_signal_name(code)}) at t = {progress.t:.6g} s; nothing was recorded "
                               "(--record BAG writes a run as it goes)\n")
            return code
        if not args.record.exists():  # (stopped while --live-wait waited)
            _write(sys.stderr, f"interrupted ({_signal_name(code)}) before the run started; nothing recorded\n")
            return code
        _write(sys.stderr, f"interrupted ({_signal_name(code)}): the bag holds the run up to the signal\n")
        _summarise_bag(args.record, png)
        return code
    finally:
        progress.close()
        if live is not None:
            live.close()
    try:
        plotting.plot_run(result.preview(), png)
    except OSError as exc:
        return _error(f"cannot write the plot {png}: {exc.strerror or exc}")
    _write(sys.stdout, format_summary(name, result.preview().summary(), png))
    if args.record is not None:
        _write(sys.stdout, f"{'bag':<16}  {args.record}\n")
    return EXIT_OK


def _signal_name(status: int) -> str:
    import signal

    try:
        return signal.Signals(status - 128).name
    except ValueError:
        return f"status {status}"


def _unwritable_out(out: Path):
    """Why the plot folder ``--out`` cannot be used (checked before the run), or None."""
    import os

    p = Path(out)
    if p.exists() and not p.is_dir():
        return f"--out {out}: is a file, not a folder for the plot"
    base = p
    while not base.exists() and base != base.parent:
        base = base.parent
    if not base.is_dir():
        return f"--out {out}: {base} is not a folder"
    if not os.access(base, os.W_OK | os.X_OK):
        return f"--out {out}: {base} is not writable"
    return None


def _run_ros(args, scene, name) -> int:
    """Both nodes as processes over DDS; the bag they record is summarised and plotted, also that of a run stopped by
    SIGINT/SIGTERM (exit status 130/143; see gyro_sim.ros.launch for the signals)."""
    import signal
    import time

    from gyro_sim.ros.launch import launch

    bag = args.record or Path(args.out) / f"{name}_{time.strftime('%Y%m%d-%H%M%S')}"
    src = scene.source or args.scene
    code = launch(src, mode=args.mode, record=str(bag), duration=args.duration, rate_factor=args.rate_factor,
                  with_controller=scene.controller is not None)
    if code == 0:
        return _summarise_bag(bag, Path(args.out) / f"{name}.png")
    stopped_by = {128 + int(s): s.name for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}.get(code)
    if stopped_by is None:
        return _error(f"the simulator node ended with status {code}"
                      + (f" ({signal.Signals(-code).name})" if -code in set(signal.Signals) else ""))
    if not Path(bag).exists():  # stopped before the simulator opened its bag
        _write(sys.stderr, f"interrupted: {stopped_by} before the run started; nothing recorded\n")
        return code
    from gyro_sim.io.messages import TOPIC_KINETIC_MOMENT
    from gyro_sim.io.recording import bag_info

    try:
        info = bag_info(bag)
    except Exception as exc:  # (e.g. the node was killed while closing it)
        return _error(f"cannot read the bag {bag}: {exc}")
    if not info["topics"].get(TOPIC_KINETIC_MOMENT, {}).get("count"):  # stopped before the first sample
        _write(sys.stderr, f"interrupted: {stopped_by} before the first sample; the bag {bag} holds none\n")
        return code
    status = _summarise_bag(bag, Path(args.out) / f"{name}.png")
    if status != EXIT_OK:
        return status
    _write(sys.stdout, f"{'end':<16}  {info['end_reason']} (exit status {code})\n")
    return code


#: samples of a bag read for its summary and plot (every k-th and the last)
PLOT_SAMPLES = 20_000


def _bag_scene(b):
    """The bag's embedded scene (a Scene: stator axes for the plot's slip), or None if it has none or it is unreadable."""
    from gyro_sim.scenes.scene import parse_scene_text, scene_from_dict

    try:
        return scene_from_dict(parse_scene_text(b.scene_text, "(embedded scene)"), where="(embedded scene)")
    except Exception:  # noqa: BLE001 - an old or damaged bag: the plot goes without slip
        return None


def _bag_result(bag: Path):
    """A RunResult-like view of a recorded bag (for the summary and the plot)."""
    from types import SimpleNamespace

    import numpy as np

    from gyro_sim.io.recording import bag_info, read_bag

    b = read_bag(bag, max_samples=PLOT_SAMPLES)  # (thinned: memory bounded however long the run)
    info = bag_info(bag)
    J = None
    try:
        from gyro_sim.scenes.scene_text import parse_scene_text

        J = np.array(parse_scene_text(b.scene_text)["rotor"]["inertia"], dtype=float)
    except Exception:
        pass
    energy = 0.5 * np.sum(b.omega_b**2 * J, axis=1) if J is not None else np.full(len(b.t), np.nan)
    from gyro_sim.io.plotting import commands_from_arrays

    res = SimpleNamespace(t=b.t, L=b.L, q=b.q, omega_b=b.omega_b, euler=b.euler, current=b.current,
                          field_rate=b.rate, stator_names=b.stator_names,
                          commands=commands_from_arrays(b.command_t, b.stator_names, b.command_current,
                                                        b.command_rate),
                          scene=_bag_scene(b) or SimpleNamespace(name=b.scene_name or bag.name))
    wall = info["custom"].get("gyro_sim.wall_time")
    steps = info["custom"].get("gyro_sim.steps")
    est = None
    if info["custom"].get("gyro_sim.error_estimate"):
        from gyro_sim.scenes.accuracy import ErrorEstimate
        from gyro_sim.engine.simulate import error_summary

        try:
            est = ErrorEstimate.from_json(str(info["custom"]["gyro_sim.error_estimate"]))
        except (ValueError, TypeError, KeyError):
            est = None
    summary = {"spin_rate": float(b.omega_b[-1, 2]), "spin_rev_s": float(b.omega_b[-1, 2] / (2 * math.pi)),
               "theta_deg": float(np.degrees(b.euler[-1, 1])), "L_norm": float(np.linalg.norm(b.L[-1])),
               "energy": float(energy[-1]), "t_end": float(b.t[-1]),
               "wall_time": float(wall) if wall else None, "steps": int(steps) if steps else None,
               "realtime_factor": float(b.t[-1]) / float(wall) if wall else None}
    if est is not None:
        summary.update(error_summary(est))
    return res, summary, b, info


def _unreadable(bag: Path, exc: Exception) -> int:
    """The one error line for a bag that cannot be read: a recording that was not closed is named as
    such, with the command that recovers it."""
    from gyro_sim.io.bag_repair import not_closed_message

    return _error(not_closed_message(bag) or f"cannot read the bag {bag}: {exc}")


def _summarise_bag(bag: Path, png: Path) -> int:
    from gyro_sim.io import plotting

    try:
        res, summary, b, info = _bag_result(bag)
    except Exception as exc:  # a bag that cannot be read
        return _unreadable(bag, exc)
    plotting.plot_run(res, png)
    _write(sys.stdout, format_summary(res.scene.name, summary, png))
    _write(sys.stdout, f"{'bag':<16}  {bag} ({info['message_count']} messages)\n")
    if b.status:
        _write(sys.stdout, f"{'last status':<16}  {b.status[-1]}\n")
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
    if custom.get("error_estimate"):
        rows.append(_error_row(custom["error_estimate"]))
    shown = {"scene_name", "version", "end", "scene", "duration", "planned_duration", "mode", "wall_time",
             "compile_time", "steps", "control_period", "error_estimate"}
    rows += [(k.replace("_", " "), str(v)) for k, v in sorted(custom.items()) if k not in shown]
    return rows


def _error_row(text: str) -> tuple:
    """The ``estimated error`` row (as in the run summary) of a bag's ``gyro_sim.error_estimate``, or its raw
    text if it cannot be read."""
    from gyro_sim.scenes.accuracy import ErrorEstimate
    from gyro_sim.engine.simulate import error_summary

    try:
        summary = error_summary(ErrorEstimate.from_json(str(text)))
    except (ValueError, TypeError, KeyError):
        return ("error estimate", str(text))
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
        except (SceneError, OSError, ValueError) as exc:
            return _error(str(exc))
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


def _cmd_phase(args) -> int:
    from gyro_sim.scenes import scene as scene_mod
    from gyro_sim.apps.phase import plot_phase

    src = Path(args.source)
    try:
        if src.is_dir():
            res, _, b, _ = _bag_result(src)
            where = f"{src} (embedded scene)"
            scene = scene_mod.scene_from_dict(scene_mod.parse_scene_text(b.scene_text, where), where=where)
        else:
            from gyro_sim.engine import simulate

            scene = scene_mod.load_scene(args.source)
            res = simulate.run(scene, duration=args.duration)
    except scene_mod.SceneError as exc:
        return _error(str(exc))
    png = args.out or Path("runs") / f"{scene.name}_phase.png"
    plot_phase(res, png, scene)
    _write(sys.stdout, f"phase portrait: {png}\n")
    return EXIT_OK


def _cmd_flywheel_plan(args) -> int:
    import yaml

    from gyro_sim.physics import flywheel

    nums = {"--inertia": args.inertia, "--wheel-inertia": [args.wheel_inertia],
            "--target-quaternion": args.target_quaternion, "--target-euler": args.target_euler,
            "--initial-quaternion": args.initial_quaternion, "--initial-euler": args.initial_euler,
            "--peak-speed": [args.peak_speed], "--ramp": [args.ramp], "--duration": [args.duration],
            "--start": [args.start], "--hold": [args.hold]}
    for opt, vals in nums.items():
        if vals is not None and not all(v is None or math.isfinite(v) for v in vals):
            return _error(f"{opt} {' '.join(str(v) for v in vals)}: must be finite numbers")
    if args.start < 0 or args.hold <= 0:
        return _error(f"--start {args.start} / --hold {args.hold}: need start >= 0 s and hold > 0 s")
    duration = args.duration
    given = [v is not None for v in (args.peak_speed, args.ramp, duration)]
    if all(given):
        return _error("--peak-speed, --ramp, --duration: give two of them (the wheel turn fixes the third)")
    if not any(given):
        duration = 1.0
    try:
        q1 = flywheel.quat_from_euler_zxz(*args.target_euler) if args.target_euler else args.target_quaternion
        q0 = (flywheel.quat_from_euler_zxz(*args.initial_euler) if args.initial_euler
              else args.initial_quaternion or (1.0, 0.0, 0.0, 0.0))
        plan = flywheel.plan_reorientation(args.inertia, args.wheel_inertia, q1, q0, peak_speed=args.peak_speed,
                                           ramp=args.ramp, duration=duration, start=args.start)
    except ValueError as exc:
        return _error(str(exc))
    text = "".join(line + "\n" for line in plan.lines())
    if args.write_scene is not None:
        from gyro_sim.scenes.scene import SceneError, scene_from_dict

        path = args.write_scene
        if path.exists() and not args.force:
            return _error(f"--write-scene {path}: already exists; give a new file or --force")
        data = flywheel.plan_scene(plan, name=path.stem, hold=args.hold)
        try:
            scene_from_dict(data, where=str(path))
        except SceneError as exc:  # e.g. inertia outside the scene's limits
            return _error(str(exc))
        header = ("# Written by gyro-sim flywheel-plan ([S], docs/flywheel.md). The body, at rest, is turned by its\n"
                  "# internal flywheel to the target attitude; plan:\n"
                  + "".join(f"#   {line}\n" for line in plan.lines()))
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            body = yaml.safe_dump(data, sort_keys=False, allow_unicode=True, default_flow_style=None, width=120)
            path.write_text(header + body, encoding="utf-8")
        except OSError as exc:
            return _error(f"cannot write the scene {path}: {exc.strerror or exc}")
        text += f"{'scene written':<20} {path}  (run: gyro-sim run {path})\n"
    _write(sys.stdout, text)
    return EXIT_OK


def _cmd_ros_index(args) -> int:
    from gyro_sim.ros.index import install_index, source_root

    prefix = (args.prefix or Path(sys.prefix)).absolute()
    if source_root() is None:  # an installed copy: pip installed the index with it
        return _error(f"gyro_sim is not an editable install (no source tree): `pip install` put its ament index "
                      f"under {sys.prefix} already")
    try:
        changed = install_index(prefix)
    except OSError as exc:
        return _error(f"cannot lay out the ament index under {prefix}: {exc}")
    _write(sys.stdout, f"ament index of gyro_sim and gyro_ctl under {prefix} ({len(changed)} paths made or updated); "
                       "use it with:\n"
                       f"  export AMENT_PREFIX_PATH={prefix}${{AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}}\n")
    return EXIT_OK


def _cmd_scenes(args) -> int:
    from gyro_sim.scenes import scene as scene_mod

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


def _cmd_api_docs(args) -> int:
    from gyro_sim.common.extras import require

    require("docs", "gyro-sim api-docs")
    if args.out.exists() and not args.out.is_dir():
        return _error(f"{args.out}: is a file, not a folder for the API reference")
    from gyro_sim.apps.api_docs import build

    try:
        docs = build(args.out)
    except OSError as exc:
        return _error(f"cannot write the API reference to {args.out}: {exc.strerror or exc}")
    for message in docs.warnings:
        _write(sys.stderr, f"warning: pdoc: {message}\n")
    for name, (extra, module) in sorted(docs.skipped.items()):
        _write(sys.stdout, f"left out {name}: it needs {module} (pip install 'gyro_sim[{extra}]')\n")
    _write(sys.stdout, f"API reference of {len(docs.modules)} modules: {docs.out / 'index.html'}\n")
    return EXIT_OK


def _cmd_warmup(args) -> int:
    import time

    from gyro_sim.scenes import scene as scene_mod
    from gyro_sim.engine.warmup import warm

    w0 = time.perf_counter()
    try:
        c = warm(args.scenes or None, say=lambda text: _write(sys.stdout, text + "\n"))
    except scene_mod.SceneError as exc:
        return _error(str(exc))
    _write(sys.stdout, f"warmup: kernels compiled in {c:.1f} s ({time.perf_counter() - w0:.1f} s wall)"
           if c > 0 else "warmup: every kernel was already compiled (numba's cache is warm)")
    _write(sys.stdout, "\n")
    return EXIT_OK


def main(argv=None) -> int:
    """Entry point of ``gyro-sim``; returns the exit status.

    A missing optional dependency (:class:`gyro_sim.extras.MissingExtra`) ends the command with one ``error:`` line,
    status 2; stdout closed by its reader (``gyro-sim scenes | head -1``) ends it quietly, status 141."""
    from gyro_sim.common.extras import MissingExtra

    try:
        try:
            status = _main(argv)
        except MissingExtra as exc:
            status = _error(str(exc))
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
    _one_line_accuracy_warnings()
    return args.func(args)


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
