"""What the ``gyro-sim`` commands share (:mod:`gyro_sim.apps.cli`): the exit statuses, the summary table of a run
and the one-line ``error:`` report."""
from __future__ import annotations

import sys

from gyro_sim.apps.console import _write

__all__ = ["format_summary", "EXIT_OK", "EXIT_FAILURE", "EXIT_USAGE", "EXIT_BROKEN_PIPE"]

EXIT_OK = 0
EXIT_FAILURE = 1  # a run that failed (e.g. its bag could not be written whole)
EXIT_USAGE = 2  # argparse's status for bad usage; scene errors use it too
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE: the reader of stdout closed it early (as a shell reports `yes | head -1`)


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
    accuracy_rtol, accuracy_attitude, accuracy_met (the run's estimated error, gyro_sim.accuracy), failure
    (``failed: <what> at t = … s``: a run whose state broke).
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
    if s("failure"):  # (the run's state broke: it stopped there, with no error estimate)
        rows.append(("status", str(s("failure"))))
    if s("error_L") is not None and s("error_L") == s("error_L"):  # (NaN: no estimate)
        eq = s("error_attitude")
        tol_q = s("accuracy_attitude")
        att = (f"attitude {eq:.2g} rad" + (f" ({tol_q:g})" if tol_q is not None and tol_q == tol_q else "")
               if eq is not None and eq == eq else "attitude not a result")
        ep, tol_p = s("error_phase"), s("accuracy_phase")
        if ep is not None and ep == ep:
            att += f", spin phase {ep:.2g} rad" + (f" ({tol_p:.2g})" if tol_p is not None and tol_p == tol_p else "")
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
