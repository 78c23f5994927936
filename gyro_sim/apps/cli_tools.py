"""The other ``gyro-sim`` commands (:mod:`gyro_sim.apps.cli`): ``phase``, ``flywheel-plan``, ``ros-index``,
``scenes``, ``api-docs`` and ``warmup``."""
from __future__ import annotations

import math
import sys
from pathlib import Path

from gyro_sim.apps.console import _write
from gyro_sim.apps.cli_bag import _bag_result, _unreadable
from gyro_sim.apps.cli_common import (
    EXIT_OK, EXIT_USAGE, _error,
)


def _cmd_phase(args) -> int:
    from gyro_sim.scenes import scene as scene_mod
    from gyro_sim.apps.phase import plot_phase

    src = Path(args.source)
    try:
        is_dir = src.is_dir()
    except (OSError, ValueError):  # a name too long for the file system, a NUL: not a bag; the scene says why
        is_dir = False
    try:
        if is_dir:
            try:
                res, _, b, _ = _bag_result(src)
            except Exception as exc:  # (a bag without a sample, or one that cannot be read)
                return _unreadable(src, exc)
            where = f"{src} (embedded scene)"
            scene = scene_mod.scene_from_dict(scene_mod.parse_scene_text(b.scene_text, where), where=where)
        else:
            from gyro_sim.engine import simulate

            from gyro_sim.engine.budget import check_run_size

            scene = scene_mod.load_scene(args.source)
            if args.duration is not None:
                check_run_size(scene, args.duration, "--duration")
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
        docs = build(args.out, progress=lambda line: _write(sys.stderr, f"api-docs: {line}\n"))
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
