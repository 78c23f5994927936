"""``gyro-sim run`` (:mod:`gyro_sim.apps.cli`): a scene in-process (``--record``: streamed to its bag), over ROS 2
(``--ros``) or shown live in Foxglove (``--live``)."""
from __future__ import annotations

import math
import sys
from pathlib import Path

from gyro_sim.apps.console import _write
from gyro_sim.apps.cli_bag import _summarise_bag, _unreadable
from gyro_sim.apps.cli_common import (
    EXIT_FAILURE, EXIT_OK, EXIT_USAGE, _error, _ros_missing, format_summary,
)


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


def _start_live(args, scene, name):
    """The live view's server (gyro_sim.live.LiveView), announced on stderr with the scene's Foxglove layout
    (written to OUT/<name>_foxglove_layout.json); (None, error text) if it cannot listen or write the layout.
    Waits for --live-wait subscriptions."""
    from gyro_sim.io.foxglove_layout import write_layout
    from gyro_sim.io.live import LiveView

    try:
        live = LiveView(scene, host=args.live_host, port=args.live_port, rate_factor=args.rate_factor)
    except Exception as exc:  # (an address in use or not resolvable)
        return None, f"--live: cannot listen on {args.live_host}:{args.live_port}: {exc}"
    layout = Path(args.out) / f"{name}_foxglove_layout.json"
    try:
        write_layout(scene, layout)
    except OSError as exc:
        live.close()
        return None, f"cannot write the Foxglove layout {layout}: {exc.strerror or exc}"
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
    if args.ros:
        from gyro_sim.ros.launch import node_cpus

        try:
            node_cpus(args.node_cpu)
        except ValueError as exc:
            return _error(str(exc))
    if args.ros and args.fidelity not in (None, "full"):
        return _error(f"--fidelity {args.fidelity}: the ROS simulator node runs the full model; drop --ros or --fidelity")
    try:
        overrides = _set_overrides(args.set)
    except ValueError as exc:
        return _error(str(exc))
    if args.fidelity:
        overrides["fidelity"] = args.fidelity
    try:
        scene = scene_mod.load_scene(args.scene, overrides=overrides or None)
        if args.duration is not None:  # the limits the scene file's own duration met on loading, before any work
            from gyro_sim.engine.budget import check_run_size

            check_run_size(scene, args.duration, "--duration")
    except scene_mod.SceneError as exc:
        return _error(str(exc))
    name = getattr(scene, "name", None) or Path(str(args.scene)).stem
    if args.ros:
        if not args.force:  # the step budget, before the nodes start (in-process: the Runner refuses, before the bag)
            bad = _over_budget(scene, args.duration)
            if bad:
                return _error(bad)
        src = scene.source or args.scene
        if args.set:  # the nodes load a file: the changed scene is written for them
            src = Path(args.out) / f"{name}_set.yaml"
            try:
                _write_scene(scene, src)
            except OSError as exc:
                return _error(f"cannot write the changed scene {src}: {exc.strerror or exc}")
            _write(sys.stderr, f"scene with --set written to {src}\n")
        return _run_ros(args, scene, name, src)
    force = {"force": True} if args.force else {}
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
                live, bad = _start_live(args, scene, name)
            if bad:
                return _error(bad)

            def on_samples(s, live=live):
                progress(s)
                live(s)
        if args.record is not None:
            # streamed: the bag is written as the run goes (a signal or a full disk leaves it closed with
            # everything up to then); it integrates the attitude whatever output.attitude says (/gyro/imu needs it)
            # (keep_bytes=0: the summary and the plot need only its preview, so memory stays flat)
            result = record_run(scene, args.record, duration=args.duration, on_samples=on_samples, keep_bytes=0,
                                **force)
        else:
            with sigterm_as_interrupt():
                # --live: the attitude is integrated whatever output.attitude says (/tf and /gyro/imu need it)
                result = simulate.run(scene, duration=args.duration, on_samples=on_samples, **force,
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
        _ignore_signals()  # (the rest of a burst of Ctrl-C: the bag is closed; only the summary below may stop)
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
        try:
            _ignore_signals(False)  # (a summary of a long bag takes a while: Ctrl-C skips it)
            _summarise_bag(args.record, png)
            _ignore_signals()
        except KeyboardInterrupt as again:  # a second Ctrl-C: the bag is closed already; it stops the summary
            _interrupted(again, f" again: no summary; the bag {args.record} is closed (gyro-sim info {args.record})")
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
    failure = getattr(result, "failure", None)  # (its state broke: the run stopped there; the bag's end says so too)
    if failure is not None:
        _write(sys.stderr, f"error: the run {failure}\n")
        return EXIT_FAILURE
    return EXIT_OK


def _over_budget(scene, duration):
    """The one line refusing a ``--ros`` run whose plan exceeds the step budget (gyro_sim/engine/budget.py), or None,
    checked here before the nodes start (the simulator node checks it too, its ``force`` parameter)."""
    from gyro_sim.engine.budget import check_budget
    from gyro_sim.engine.model import controller_period
    from gyro_sim.engine.simulator import Simulator
    from gyro_sim.scenes.scene import SceneError

    T = float(duration or scene.duration)
    try:
        # (the node integrates the attitude, and ticks every DEFAULT_CONTROL_PERIOD without a controller)
        sim = Simulator(scene, attitude=True, horizon=T, quiet=True)
        period = controller_period(scene) or 0.01
        check_budget(sim, T, period)
    except SceneError as exc:
        return str(exc)
    return None


def _interrupted(exc: KeyboardInterrupt, what: str = "") -> int:
    """The one line of a command stopped by a signal that it did not handle itself, and its status (128 + the
    signal: 130 Ctrl-C, 143 SIGTERM, 129 SIGHUP; ``what`` follows it on the line). Later signals are ignored: the
    command is ending, and a recorded bag was closed by the handler that the first one went through."""
    from gyro_sim.io.signals import exit_status

    _ignore_signals()
    code = exit_status(exc)
    _write(sys.stderr, f"interrupted ({_signal_name(code)}){what}\n")
    return code


def _run_failed(bag: Path) -> bool:
    """Whether a bag's end says its run failed (``failed: …``: a broken state, a lost controller), not its
    recording."""
    from gyro_sim.io.recording import bag_info

    try:
        return str(bag_info(bag)["end_reason"]).startswith("failed:")
    except Exception:  # (unreadable: not a run's failure it could say)
        return False


def _failed_recording(bag: Path, png: Path) -> int:
    """A ``--ros`` simulator node that ended with status 1, its recording failed (a full disk, a file size limit;
    its log said why): one ``error:`` line with how its bag ended, then the summary of what fit; status 1, as an
    in-process run's. A bag that does not read (a node that crashed): the error line of an unreadable bag, 2."""
    from gyro_sim.io.recording import bag_info

    try:
        end = bag_info(bag)["end_reason"]
    except Exception as exc:  # (a node that crashed before closing it)
        _error(f"the simulator node ended with status {EXIT_FAILURE}")
        return _unreadable(bag, exc)
    _error(f"the simulator node could not write the bag {bag} whole: {end}")
    status = _summarise_bag(bag, png)
    return EXIT_FAILURE if status == EXIT_OK else status


def _ignore_signals(ignore: bool = True) -> None:
    """Ignore SIGINT, SIGTERM and SIGHUP from now on (a command ending after a signal: the rest of a burst of
    Ctrl-C must not kill it while it says so); ``ignore`` False: Ctrl-C raises KeyboardInterrupt again."""
    import signal

    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        try:
            signal.signal(sig, signal.SIG_IGN if ignore else
                          signal.default_int_handler if sig == signal.SIGINT else signal.SIG_IGN)
        except (ValueError, OSError):  # (not the main thread)
            pass


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


def _set_overrides(texts) -> dict:
    """The ``--set KEY=VALUE`` options as scene overrides (dotted key → value), parsed as ``gyro-sim sweep --set``
    parses them (gyro_sim/apps/sweep_axes.py: numbers, true/false, null, [a, b] lists, else text); ValueError (one
    line) for one without ``=`` or with an empty key."""
    from gyro_sim.apps.sweep_axes import _parse_value, _split_assignment

    out = {}
    for text in texts:
        key, value = _split_assignment(text, "--set")
        if not key:
            raise ValueError(f"--set {text!r}: expected KEY=VALUE with a dotted key, e.g. stators.2.current=0.5")
        out[key] = _parse_value(value)
    return out


def _write_scene(scene, path: Path) -> None:
    """Write ``scene`` as a scene file (YAML) that loads back as the same scene."""
    from gyro_sim.scenes.scene_text import dump_scene_data

    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("# written by gyro-sim run --set (the scene with its changes)\n"
                    + dump_scene_data(scene.model_dump(mode="json", exclude={"source"})), encoding="utf-8")


def _run_ros(args, scene, name, src) -> int:
    """Both nodes as processes over DDS; the bag they record is summarised and plotted, also that of a run stopped by
    SIGINT/SIGTERM (exit status 130/143; see gyro_sim.ros.launch for the signals)."""
    import signal
    import time

    from gyro_sim.ros.launch import launch

    bag = args.record or Path(args.out) / f"{name}_{time.strftime('%Y%m%d-%H%M%S')}"
    code = launch(src, mode=args.mode, record=str(bag), duration=args.duration, rate_factor=args.rate_factor,
                  with_controller=scene.controller is not None, force=args.force, node_cpu=args.node_cpu)
    if code == 0:
        return _summarise_bag(bag, Path(args.out) / f"{name}.png")
    stopped_by = {128 + int(s): s.name for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}.get(code)
    if code == EXIT_FAILURE and Path(bag).exists():
        if not _run_failed(bag):  # its recording failed (a full disk): the bag holds what fit
            return _failed_recording(bag, Path(args.out) / f"{name}.png")
        stopped_by = "the run failed"  # (its state broke or its controller was lost: the bag's end says which)
    if stopped_by is None:
        return _error(f"the simulator node ended with status {code}"
                      + (f" ({signal.Signals(-code).name})" if -code in set(signal.Signals) else ""))
    if not Path(bag).exists():  # stopped before the simulator opened its bag
        _write(sys.stderr, f"interrupted: {stopped_by} before the run started; nothing recorded\n")
        return code
    from gyro_sim.apps.cli_bag import _sample_count
    from gyro_sim.io.recording import bag_info

    try:
        info = bag_info(bag)
    except Exception as exc:  # (e.g. the node was killed while closing it)
        return _error(f"cannot read the bag {bag}: {exc}")
    if not _sample_count(info):  # stopped before the first sample
        _write(sys.stderr, f"interrupted: {stopped_by} before the first sample; the bag {bag} holds none\n")
        return code
    status = _summarise_bag(bag, Path(args.out) / f"{name}.png")
    if status != EXIT_OK:
        return status
    _write(sys.stdout, f"{'end':<16}  {info['end_reason']} (exit status {code})\n")
    return code
