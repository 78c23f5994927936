"""Running a scene: :func:`run` (in-process, the fastest) and :func:`drive` (a Runner to its end with the scene's law).

The simulator is the one piece of code every front end drives: :func:`run`, the ROS simulator node (lockstep /
real-time) and the tests. Units SI, L in the case frame, attitude quaternion body → case. Its parts live beside
this module and are re-exported here (``gyro_sim.simulate`` is this module):

* :mod:`gyro_sim.engine.terms`: the model's terms (conductor modes, stators, field phasors, effects, torque, body
  rates);
* :mod:`gyro_sim.engine.step_size`: the controller of the step (a segment's stepper and largest step);
* :mod:`gyro_sim.engine.steppers`: one interface to the compiled steppers;
* :mod:`gyro_sim.engine.saving`: the output instants, sample arrays and the :class:`RunResult` of a run;
* :mod:`gyro_sim.engine.simulator`: :class:`Simulator` (a run's state, composing the parts above);
* :mod:`gyro_sim.engine.runner`: :class:`Runner` (the run loop: breaks, ticks, the error control);
* :mod:`gyro_sim.engine.model`: shared pieces (step knobs, lawson8's table, :func:`integrates_attitude`,
  :func:`controller_period`, :func:`stator_triad`, body rates, kinetic energy);
* :mod:`gyro_sim.engine.result`: :class:`RunResult`.

A run without attitude (:func:`integrates_attitude` False: ``output.attitude: false`` on an isotropic
rotor without effects, full fidelity, no controller law that reads the attitude) integrates L and the eddy
modes in the case frame only (gyro_sim/compiled/kernels.py): q, the Euler angles and θ are NaN, ``omega_b`` holds
Ω = L/J in the case frame (the body frame is not known; |Ω| is the same) and ``spin_rate`` is |Ω|.
"""
from __future__ import annotations

from typing import Optional

from gyro_sim.compiled.compile_watch import CompileClock
from gyro_sim.engine.model import (_TABLEAU, AVERAGED_ERROR, DEFAULT_RATE_CHANGE, DEFAULT_STEPS_PER_TURN,  # noqa: F401
                                   FROZEN_FLOW_COST, LAWS_WITHOUT_ATTITUDE, _case_flag, _initial_attitude, _tableau,
                                   body_rates, controller_period, integrates_attitude, kinetic_energy, lawson8_cost,
                                   stator_triad, system_energy)
from gyro_sim.engine.result import RunResult, error_summary  # noqa: F401
from gyro_sim.engine.runner import Runner
from gyro_sim.engine.saving import output_times
from gyro_sim.engine.simulator import Simulator
from gyro_sim.scenes.scene import Scene

__all__ = ["Simulator", "RunResult", "Runner", "run", "drive", "stator_triad", "integrates_attitude",
           "controller_period", "output_times", "kinetic_energy", "system_energy", "body_rates", "error_summary"]


def run(scene: Scene, duration: Optional[float] = None, on_samples=None, attitude: Optional[bool] = None,
        estimate: Optional[bool] = None, force: bool = False) -> RunResult:
    """Run a scene in-process (no ROS) and return its time series at the scene's output rate.

    A scene with a ``controller`` runs its law (gyro_ctl) at every tick, and with ``sampling: events``
    also at the exact zeros of the law's switching functions between ticks. ``on_samples(dict)``, if
    given, is called with each new chunk of output rows (see :meth:`Runner.samples`). ``attitude``: None
    = the scene's ``output.attitude``, True = integrate it anyway (:func:`integrates_attitude`).
    ``estimate``: False runs without the error control's shadow run (:class:`Runner`; the estimate is then the
    step plan's model), e.g. to time the integrator alone at given knobs; None: with it where it can follow.
    ``force``: run a scene whose plan exceeds the step budget (:data:`gyro_sim.scenes.step_control.STEP_BUDGET`;
    without it such a run is refused before any work with a :class:`~gyro_sim.scenes.step_control.StepBudgetError`
    saying what to loosen). Ctrl-C / SIGTERM stop a run within about a second wherever it is (KeyboardInterrupt).
    """
    if scene.fidelity != "full":
        from gyro_sim.engine.fidelity import run_hybrid  # (on first use: SciPy's solvers cost a full run's start-up)

        return run_hybrid(scene, duration, estimate=estimate, force=force)
    ctl = scene.controller
    switching = ctl is not None and ctl.sampling == "events"
    # samples are breaks where a caller acts on them, and where switching events are looked for between
    # breaks (the node does the same: the same events, the same bits)
    r = Runner(scene, duration, sample_breaks=on_samples is not None or switching, attitude=attitude,
               estimate=estimate, force=force)
    drive(r, on_samples)
    return r.result()


def drive(r: Runner, on_samples=None, release: bool = False) -> None:
    """Run a :class:`Runner` to its end with the scene's controller law (if any; at the exact switching instants
    with ``sampling: events``), calling ``on_samples(dict)`` with each new chunk of output rows
    (:meth:`Runner.samples`). ``release``: after each call the rows (and logged commands) are released, so
    memory stays flat (a streamed run: the caller took them). ``r.wall_time`` / ``r.compile_time`` are set even
    when the run is interrupted (KeyboardInterrupt), up to the interruption. Ticks and samples between the other
    breaks go through the compiled tick loop where it applies (gyro_sim/engine/ticks.py: the same numbers)."""
    from gyro_ctl.laws import make_law, make_switching

    from gyro_sim.engine import ticks

    ctl = r.scene.controller
    law = make_law(ctl) if ctl is not None else None
    switching = make_switching(ctl) if ctl is not None and ctl.sampling == "events" else None
    loop = ticks.tick_loop(r, law) if switching is None else None  # ticks in compiled code where they can be
    clock = CompileClock()
    try:
        with clock:
            while not r.done:
                if r.row > 0 and law is not None and r.is_control_tick:
                    r.apply_commands(law(r.control_input()))
                rows = (r.advance_located(law, switching) if switching is not None and r.row > 0
                        else ticks.advance(r, loop))
                if on_samples is not None and rows.stop > rows.start:
                    on_samples(r.samples(rows))
                    if release:
                        r.release()
    finally:
        r.wall_time, r.compile_time = clock.wall, clock.compile
