"""Signals during a run (:mod:`gyro_sim.io.recording`): SIGTERM / SIGHUP as :class:`RunInterrupted` (a
KeyboardInterrupt, as Ctrl-C raises), signals held while one sample is written to a bag and deferred while a bag is
closed, and the exit status of a run a signal ended."""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Iterator, Optional

__all__ = ["RunInterrupted", "exit_status", "sigterm_as_interrupt", "signal_name", "interrupt_reason",
           "reraise_interrupt", "wrapped_interrupt"]


class RunInterrupted(KeyboardInterrupt):
    """A run stopped by a signal (SIGTERM, SIGHUP; SIGINT raises a plain KeyboardInterrupt): ``signum``.
    ``exit_status`` is the shell's convention, 128 + signal number (143 for SIGTERM, 130 for SIGINT)."""

    def __init__(self, signum: int):
        super().__init__(f"signal {signal.Signals(signum).name}")
        self.signum = int(signum)

    @property
    def exit_status(self) -> int:
        return 128 + self.signum


def signal_name(signum: Optional[int]) -> str:
    """'SIGINT' for 2 (the number for a signal without a name; 'stop' for None)."""
    if signum is None:
        return "stop"
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


def interrupt_reason(exc: BaseException) -> str:
    """What a bag's end says after ``interrupted: `` of a run that ``exc`` ended: ``signal SIGTERM`` (a
    :class:`RunInterrupted`), ``signal SIGINT`` (Ctrl-C's KeyboardInterrupt), else its type and message."""
    if isinstance(exc, RunInterrupted):
        return f"signal {signal_name(exc.signum)}"
    if isinstance(exc, KeyboardInterrupt):
        return "signal SIGINT"
    return type(exc).__name__ + (f" ({exc})" if str(exc) else "")


def exit_status(exc: BaseException) -> int:
    """128 + the signal that ended a run (130 for Ctrl-C's plain KeyboardInterrupt, 143 for SIGTERM)."""
    return exc.exit_status if isinstance(exc, RunInterrupted) else 128 + int(signal.SIGINT)


def wrapped_interrupt(exc: BaseException) -> Optional[KeyboardInterrupt]:
    """The KeyboardInterrupt in ``exc``'s ``__cause__`` / ``__context__`` chain (``exc`` itself included), or None.

    Python 3.11 wraps an exception raised while a class body is completed (a dataclass field's ``__set_name__``)
    in ``RuntimeError("Error calling __set_name__ …")``: a Ctrl-C that lands while a module is imported lazily
    then reaches an ``except Exception`` as an error of the work it stopped (seen on CI: a burst of Ctrl-C said
    ``cannot read the bag``)."""
    seen = set()
    e: Optional[BaseException] = exc
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return e
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return None


def reraise_interrupt(exc: BaseException) -> None:
    """Raise the KeyboardInterrupt that ``exc`` wraps, if any (:func:`wrapped_interrupt`): code that turns
    exceptions into an error line calls this first."""
    ki = wrapped_interrupt(exc)
    if ki is not None:
        raise ki from (None if ki is exc else exc)


#: [depth of the write sections open, the signal held meanwhile]: a signal that arrives while one sample's
#: messages are written is raised when they all are, so a bag never ends in half a sample
_HOLD: list = [0, None]


def _interrupt(signum: int) -> KeyboardInterrupt:
    return KeyboardInterrupt() if signum == signal.SIGINT else RunInterrupted(signum)


@contextmanager
def _held_signals() -> Iterator[None]:
    """A section no signal handler of :func:`sigterm_as_interrupt` breaks: a signal that arrives within is
    raised at its end (cheap: a counter, no system call)."""
    _HOLD[0] += 1
    try:
        yield
    finally:
        _HOLD[0] -= 1
        if _HOLD[0] == 0 and _HOLD[1] is not None:
            signum, _HOLD[1] = _HOLD[1], None
            raise _interrupt(signum)


@contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM and SIGHUP raise :class:`RunInterrupted` (a KeyboardInterrupt, as Ctrl-C
    raises) and Ctrl-C (while Python's default handler is in place) a KeyboardInterrupt, so ``finally`` /
    ``with BagRecorder`` close the bag. A signal that arrives while a sample is written to a bag is raised once
    the sample is whole. Main thread only (elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def _raise(signum, frame):
        if _HOLD[0]:
            _HOLD[1] = _HOLD[1] or signum
            return
        raise _interrupt(signum)

    sigs = [signal.SIGTERM, signal.SIGHUP]
    h = signal.getsignal(signal.SIGINT)
    if h is signal.default_int_handler or getattr(h, "default_int", False):  # (or compile_watch's, which holds it
        sigs.append(signal.SIGINT)                                           # while numba compiles)
    old = {sig: signal.signal(sig, _raise) for sig in sigs}
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)


@contextmanager
def _signals_deferred() -> Iterator[None]:
    """Hold SIGINT/SIGTERM while the bag's index and metadata are written (a second Ctrl-C
    must not leave a half-closed file); delivered to the previous handlers afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    sigs = [signal.SIGINT, signal.SIGTERM]
    old = {}
    for s in sigs:
        # a handler installed outside Python (getsignal() is None, e.g. rclpy's) is left alone:
        # it could not be put back
        if signal.getsignal(s) is None:
            continue
        try:
            old[s] = signal.signal(s, lambda signum, frame: pending.append(signum))
        except (ValueError, OSError):  # pragma: no cover - not settable here
            pass
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        for s in dict.fromkeys(pending):
            signal.raise_signal(s)
