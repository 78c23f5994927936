"""Where numba compiles: one line saying so, and its time kept out of a run's real-time factor.

The compiled kernels are cached on disk (``cache=True``: next to the modules, or numba's user cache where the
package directory is read-only, or ``NUMBA_CACHE_DIR``), so a scene's kernels compile once per install and
Python version (an install compiles them at build time: build_support/precompile_kernels.py). When they do
compile, the user sees a line, then one a kernel (:func:`announce_compiles`), and
:class:`~gyro_sim.simulate.Runner` counts the time apart (``compile_time``), so the real-time factor of a first
run is that of the integration alone.
"""
from __future__ import annotations

import sys
import threading
import time
from typing import Callable, Literal, Optional, TextIO

__all__ = ["compile_seconds", "announce_compiles", "CompileClock", "hold_interrupts_while_compiling", "sigint_came"]

_lock = threading.Lock()
_state: dict = {"depth": 0, "t0": 0.0, "total": 0.0, "installed": False, "announce": None, "locked": 0, "held": False,
                "progress": None, "kernels": 0, "sigint": False}


def _install() -> None:
    """Register the process-wide numba compile listener (once)."""
    with _lock:
        if _state["installed"]:
            return
        from numba.core import event

        class _Listener(event.Listener):
            def on_start(self, ev):
                if _state["depth"] == 0:
                    _state["t0"] = time.perf_counter()
                    say = _state["announce"]
                    if say is not None:
                        _state["announce"] = None  # once a process
                        say()
                _state["depth"] += 1

            def on_end(self, ev):
                _state["depth"] -= 1
                if _state["depth"] == 0:
                    dt = time.perf_counter() - _state["t0"]
                    _state["total"] += dt
                    _state["kernels"] += 1
                    say = _state["progress"]
                    if say is not None:  # one line a kernel compiled (with the ones it calls)
                        name = getattr(getattr(ev.data.get("dispatcher"), "py_func", None), "__name__", "kernel")
                        say(f"gyro_sim:   compiled {name} in {dt:.1f} s ({_state['kernels']} kernels, "
                            f"{_state['total']:.1f} s so far; Ctrl-C stops after the kernel being compiled)")

        class _LockListener(event.Listener):
            """numba's compiler lock: held while it compiles or loads a kernel from its cache (LLVM calls back
            into Python through ctypes there, and a KeyboardInterrupt raised in such a callback is printed and
            swallowed by ctypes)."""

            def on_start(self, ev):
                _state["locked"] += 1

            def on_end(self, ev):
                _state["locked"] -= 1
                if _state["locked"] == 0 and _state["held"]:
                    _state["held"] = False
                    raise KeyboardInterrupt  # (the Ctrl-C held while numba worked: raised in plain Python code)

        event.register("numba:compile", _Listener())
        event.register("numba:compiler_lock", _LockListener())
        _state["installed"] = True


class _HoldingHandler:
    """SIGINT: KeyboardInterrupt, as Python's default handler, but held while numba's compiler lock is (raised when
    it is released). ``default_int``: io.signals treats it as Python's default."""

    default_int = True

    def __call__(self, signum, frame):
        _state["sigint"] = True  # (sigint_came: an error it leaves behind is the interruption's)
        if _state["locked"] > 0:
            _state["held"] = True
            return
        raise KeyboardInterrupt


def hold_interrupts_while_compiling() -> None:
    """Where SIGINT has Python's default handler (KeyboardInterrupt): a Ctrl-C that comes while numba compiles or
    loads a kernel is held until it is done, then raised (a command's start: ``gyro-sim``'s main). Handlers a
    command installs later (a run's stop flag) are left alone."""
    import signal

    if "numba" in sys.modules:
        _install()  # (else kernels.py calls it when it imports numba: a light command imports none)

    handler = _HoldingHandler()
    try:
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, handler)
    except ValueError:  # (not the main thread)
        pass


def sigint_came() -> bool:
    """Whether a Ctrl-C came to the handler :func:`hold_interrupts_while_compiling` installed. A Ctrl-C inside C
    code that imports a module can come out as another error with no trace of it (NumPy's start-up:
    ``ImportError: PyCapsule_Import could not import module "datetime"``); the command's main asks this."""
    return _state["sigint"]


def compile_seconds() -> float:
    """Wall seconds this process has spent compiling numba functions so far (outermost compiles only; counted
    from the first call of this module's functions)."""
    _install()
    return _state["total"]


def announce_compiles(stream: Optional[TextIO] = None, say: Optional[Callable[[str], None]] = None) -> None:
    """At the first numba compile of this process, print one line saying what is happening, then one line a
    kernel as each is compiled (progress: a compile takes seconds a kernel), to ``stream`` (default stderr) or
    through ``say``. An install that compiled its kernels at build time (``pip install .``, colcon,
    ``.ci/setup``: build_support/precompile_kernels.py) prints nothing."""
    text = ("gyro_sim: compiling the numba kernels this scene needs (not compiled with this install: "
            "`gyro-sim warmup` compiles them ahead; cached on disk for later runs); the real-time factor leaves "
            "this time out")

    def emit(line: str) -> None:
        if say is not None:
            say(line)
        else:
            print(line, file=stream or sys.stderr, flush=True)

    _install()
    _state["announce"] = lambda: emit(text)
    _state["progress"] = emit


class CompileClock:
    """Wall time of a block less the numba compile time inside it: ``with clock: ...``; ``clock.wall`` and
    ``clock.compile`` accumulate over uses."""

    def __init__(self):
        _install()
        self.wall = 0.0
        self.compile = 0.0

    def __enter__(self) -> "CompileClock":
        self._w0, self._c0 = time.perf_counter(), _state["total"]
        return self

    def __exit__(self, *exc) -> Literal[False]:
        c = _state["total"] - self._c0
        self.compile += c
        self.wall += time.perf_counter() - self._w0 - c
        return False
