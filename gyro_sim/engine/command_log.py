"""The commands a run applied, as a sequence of ``(t s, names, currents A | None, rates rad/s | None)``
(:class:`CommandLog`: ``Runner.command_log`` and ``RunResult.commands``).

The compiled tick loop (gyro_sim.engine.ticks) logs a controller's commands a block of ticks at a time, as arrays:
a spin-up with its law at 50 Hz logs 60,000 commands in 20 minutes. Made into Python tuples at once, they took
about 13 % of that run's CPU (their ~240,000 objects also slow every garbage collection after). Here a block stays
arrays until someone reads it, and is made into tuples then, once; a run whose commands nobody reads (a sweep, a
benchmark) never pays for them. Reading gives the same entries, in the same order, as one tuple per command.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Iterator

import numpy as np


class _Block:
    """Commands of ticks ``times`` (s) to stators ``names``: currents ``cur`` (A) and rates ``rate`` (rad/s), one row a
    tick; ``nan_is_none``: a NaN rate means "unchanged" (None), as the law 'off' commands."""

    __slots__ = ("times", "names", "cur", "rate", "nan_is_none")

    def __init__(self, times: np.ndarray, names: list, cur: np.ndarray, rate: np.ndarray, nan_is_none: bool):
        self.times, self.names, self.cur, self.rate, self.nan_is_none = times, names, cur, rate, nan_is_none

    def __len__(self) -> int:
        return self.times.size

    def entries(self) -> list:
        """The block as ``(t, names, currents, rates)`` tuples (each its own names list, as apply_commands logs)."""
        cs, rs = self.cur.tolist(), self.rate.tolist()
        if self.nan_is_none:
            rs = [[None if v != v else v for v in row] for row in rs]
        names = self.names
        return [(t, list(names), c, v) for t, c, v in zip(self.times.tolist(), cs, rs, strict=True)]


class CommandLog(Sequence):
    """A run's applied commands in time order: single entries (:meth:`append`) and blocks of ticks
    (:meth:`add_ticks`), read as one sequence of ``(t, names, currents, rates)`` tuples; equal to a list with the
    same entries."""

    def __init__(self, entries: "list | None" = None):
        self._parts: list = []  # tuples and _Blocks, in time order
        self._n = 0
        for e in entries or ():
            self.append(e)

    # --- writing ---------------------------------------------------------------------------------
    def append(self, entry: tuple) -> None:
        """One command message ``(t s, names, currents, rates)``."""
        self._parts.append(entry)
        self._n += 1

    def add_ticks(self, times: np.ndarray, names: list, cur: np.ndarray, rate: np.ndarray,
                  nan_is_none: bool = False) -> None:
        """The commands of ticks ``times`` (s), one row of ``cur`` (A) and ``rate`` (rad/s) each, to stators
        ``names`` (kept as given: pass arrays the caller no longer writes into)."""
        if times.size:
            self._parts.append(_Block(times, names, cur, rate, nan_is_none))
            self._n += times.size

    def truncate(self, n: int) -> None:
        """Keep the first ``n`` entries."""
        if n >= self._n:
            return
        kept, left = [], n
        for p in self._parts:
            if left <= 0:
                break
            if isinstance(p, _Block):
                if len(p) > left:
                    p = _Block(p.times[:left], p.names, p.cur[:left], p.rate[:left], p.nan_is_none)
                left -= len(p)
            else:
                left -= 1
            kept.append(p)
        self._parts, self._n = kept, n

    def clear(self) -> None:
        self._parts, self._n = [], 0

    def take(self) -> list:
        """The entries as a list, and the log emptied."""
        out = self._flat()
        self.clear()  # (a new list: out is the caller's)
        return out

    def copy(self) -> "CommandLog":
        """A log with the same entries (blocks are shared: neither log writes into them)."""
        c = CommandLog()
        c._parts, c._n = list(self._parts), self._n
        return c

    # --- reading ---------------------------------------------------------------------------------
    def to_list(self) -> list:
        """The entries as a new list of tuples."""
        return list(self._flat())

    def _flat(self) -> list:
        """The entries, blocks made into tuples once and kept so (the log's own list: not to be written into)."""
        if any(isinstance(p, _Block) for p in self._parts):
            flat: list = []
            for p in self._parts:
                if isinstance(p, _Block):
                    flat.extend(p.entries())
                else:
                    flat.append(p)
            self._parts = flat
        return self._parts

    def __len__(self) -> int:
        return self._n

    def __iter__(self) -> Iterator[tuple]:
        return iter(self._flat())

    def __getitem__(self, i):
        return self._flat()[i]

    def __eq__(self, other) -> bool:
        if isinstance(other, (CommandLog, list, tuple)):
            return len(self) == len(other) and self._flat() == list(other)
        return NotImplemented

    def __repr__(self) -> str:
        return f"CommandLog({self.to_list()!r})"
