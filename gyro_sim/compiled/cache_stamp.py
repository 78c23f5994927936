"""One source stamp for every cached numba kernel of the package, so that a kernel's cache follows the kernels it calls.

numba keeps a compiled kernel on disk (``cache=True``) under the stamp of its own module's source: a kernel that calls
another module's kept its old callee after only that module changed. The compiled tick loop
(:func:`gyro_sim.engine.ticks.breaks`) links in the frozen-flow step of :mod:`gyro_sim.compiled.frozen_flow`: after an
edit of that step (a ``git pull`` in a checkout, an editable or ``--symlink-install`` build) the tick loop ran the old
step from its cache while every other path ran the new one, and two ways of running one scene disagreed. Here every
cached kernel of the package is stamped with one hash of all its kernels' sources (:data:`KERNEL_SOURCES`): a change in
any of them makes every kernel compile again, once.

:func:`install` puts the stamping locators in front of numba's own (``numba.core.caching.CacheImpl.
_locator_classes``: numba has no public hook for the stamp; where that attribute is missing, numba's own locators
stay); :mod:`gyro_sim.compiled` calls it before any kernel module is imported. Other files keep numba's locators.
"""
from __future__ import annotations

import functools
import hashlib
import os
from pathlib import Path

__all__ = ["KERNEL_SOURCES", "STAMPED", "install", "kernel_sources", "stamp"]

_ROOT = Path(__file__).resolve().parent.parent.parent  # the folder holding gyro_sim/ and gyro_ctl/
#: the modules whose kernels take the stamp: those that call another module's kernels, and whose kernels are always
#: made after :func:`install` (it runs when gyro_sim.compiled is first imported; ticks.py imports it first)
STAMPED = ("gyro_sim/compiled/*.py", "gyro_sim/engine/ticks.py")
#: what the stamp covers: those, and the other sources their kernels call or read at compile time (the control laws'
#: kernels, which call no other module's and keep numba's stamp of their own file; the physical constants). Paths
#: relative to the folder holding gyro_sim/ and gyro_ctl/, a pattern's files in sorted order
KERNEL_SOURCES = STAMPED + ("gyro_ctl/law_kernels.py", "gyro_sim/physics/constants.py")


def kernel_sources(root: Path = _ROOT, patterns: tuple = KERNEL_SOURCES) -> list[Path]:
    """The files of ``patterns`` (:data:`KERNEL_SOURCES`) under ``root`` that exist (resolved: a symlinked install's
    sources)."""
    return list(_sources(root, patterns))


@functools.lru_cache(maxsize=None)
def _sources(root: Path, patterns: tuple) -> tuple:
    """:func:`kernel_sources`, globbed once a process (a run loads each kernel's cache under the stamp, ~80 times:
    globbing each time cost ~50 ms of a first run's start-up; a file's content is still read again when it changes)."""
    return tuple(p.resolve() for pattern in patterns for p in sorted(root.glob(pattern)) if p.is_file())


@functools.lru_cache(maxsize=None)
def _stamp_of(files: tuple) -> str:
    """The hash of ``files`` ((path, mtime_ns, size), …: read again where a file changed, as numba's own stamp)."""
    h = hashlib.sha256()
    for f, _, _ in files:
        h.update(f.name.encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()


def stamp(root: Path = _ROOT) -> str:
    """The hash (hex) of every kernel source under ``root``: the stamp each cached kernel of the package is kept
    under."""
    return _stamp_of(tuple((f, st.st_mtime_ns, st.st_size) for f in kernel_sources(root) for st in [f.stat()]))


@functools.lru_cache(maxsize=None)
def _ours() -> frozenset:
    """The files whose kernels take the stamp (:data:`STAMPED`)."""
    return frozenset(str(p) for p in kernel_sources(patterns=STAMPED))


def _stamped(base: type) -> type:
    """``base`` (a numba cache locator) for the package's kernel files only, with the package's one stamp."""

    class Stamped(base):  # type: ignore[misc, valid-type]
        _gyro_sim = True

        def get_source_stamp(self):
            return stamp()

        @classmethod
        def from_function(cls, py_func, py_file):
            if os.path.realpath(py_file) not in _ours():
                return None
            return super().from_function(py_func, py_file)

    Stamped.__name__ = Stamped.__qualname__ = f"GyroSim{base.__name__}"
    return Stamped


def install() -> bool:
    """Put the stamping locators (numba's user-provided, in-tree and user-wide ones, in that order) in front of
    numba's; once a process. Returns whether they are in place."""
    from numba.core import caching

    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)  # (numba >= 0.61; before)
    classes = getattr(impl, "_locator_classes", None)
    if not isinstance(classes, list):
        return False
    if any(getattr(c, "_gyro_sim", False) for c in classes):
        return True
    bases = [getattr(caching, n, None) for n in ("UserProvidedCacheLocator", "InTreeCacheLocator",
                                                  "UserWideCacheLocator")]
    classes[0:0] = [_stamped(b) for b in bases if isinstance(b, type)]
    return True
