"""The applied commands' log (gyro_sim/engine/command_log.py): the compiled tick loop logs a block of ticks as arrays,
made into ``(t, names, currents, rates)`` tuples only where the log is read. Before, every tick made a tuple and three
lists at once: 60,000 of them in a 20-minute spin-up, about 13 % of its CPU (0.175 of 1.37 s measured)."""
from __future__ import annotations

import math

import numpy as np

import gyro_sim
from gyro_sim.engine.command_log import CommandLog
from gyro_sim.engine.ticks import python_ticks


def test_the_tick_loop_logs_blocks_that_read_as_one_tuple_a_tick():
    """A spin-up over 6 s (300 ticks at 50 Hz): the compiled loop's log holds a few blocks, not a tuple a tick, and
    reads as the Python loop's log, entry for entry."""
    scene = gyro_sim.load_scene("spinup_thin_shell")
    r = gyro_sim.run(scene, duration=6.0)
    assert isinstance(r.commands, CommandLog)
    parts = len(r.commands._parts)
    with python_ticks():
        ref = gyro_sim.run(scene, duration=6.0)
    print(f"\n  {len(ref.commands)} commands logged in {parts} parts")
    assert len(r.commands) == len(ref.commands) >= 300
    assert parts <= len(ref.commands) / 5  # (a block a compiled call: the checks end ~23 calls)
    assert r.commands == list(ref.commands) and list(r.commands) == list(ref.commands)
    assert r.commands[0] == ref.commands[0] and r.commands[-1] == ref.commands[-1]
    t, names, cur, rate = r.commands[5]
    assert type(t) is float and names == ["z3"] and type(cur[0]) is float and type(rate[0]) is float


def _log() -> CommandLog:
    log = CommandLog([(0.0, ["a"], [1.0], [None])])
    log.add_ticks(np.array([0.1, 0.2, 0.3]), ["a", "b"], np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]),
                  np.array([[math.nan, 1.0], [2.0, math.nan], [3.0, 4.0]]), nan_is_none=True)
    log.append((0.35, ["b"], [None], [7.0]))
    log.add_ticks(np.array([0.4]), ["a"], np.array([[8.0]]), np.array([[math.nan]]))
    return log


def test_entries_in_order_and_nan_rates_as_none_where_asked():
    log = _log()
    assert len(log) == 6
    want = [(0.0, ["a"], [1.0], [None]), (0.1, ["a", "b"], [1.0, 2.0], [None, 1.0]),
            (0.2, ["a", "b"], [3.0, 4.0], [2.0, None]), (0.3, ["a", "b"], [5.0, 6.0], [3.0, 4.0]),
            (0.35, ["b"], [None], [7.0])]
    got = list(log)
    assert got[:5] == want and got[5][0] == 0.4 and math.isnan(got[5][3][0])  # (NaN kept where not asked)
    assert got[1][1] is not got[2][1]  # (each entry its own names list, as apply_commands logs)


def test_truncate_take_copy_and_clear():
    log = _log()
    full = _log().to_list()
    log.truncate(3)  # (within the first block)
    assert len(log) == 3 and log.to_list() == full[:3]
    c = log.copy()
    log.append((0.9, ["a"], [0.0], [0.0]))
    assert len(c) == 3 and c == full[:3] and len(log) == 4
    taken = log.take()
    assert taken == full[:3] + [(0.9, ["a"], [0.0], [0.0])] and len(log) == 0 and log == []
    log = _log()
    log.truncate(10)  # (longer than the log: nothing dropped)
    assert len(log) == 6
    log.truncate(0)
    assert len(log) == 0 and list(log) == []
    log.add_ticks(np.zeros(0), ["a"], np.zeros((0, 1)), np.zeros((0, 1)))  # (an empty block: nothing)
    assert len(log) == 0 and log._parts == []
