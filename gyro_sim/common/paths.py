"""Paths the user gives (``--record``, ``--out``, a bag): why one cannot be used, in words, before any work.

A path whose component is longer than its file system allows (``NAME_MAX``, 255 bytes on most), or that is longer
than ``PATH_MAX`` in all, makes every ``os`` call on it fail (``ENAMETOOLONG``), also ``Path.exists()``; a NUL in it
makes them raise ValueError. :func:`path_problem` names such a path in one line instead.
"""
from __future__ import annotations

import errno
import os
from pathlib import Path
from typing import Optional, Union

__all__ = ["path_problem", "shown"]

#: characters of a path shown in a message (its start and end; the middle elided)
SHOWN_CHARS = 80


def shown(path: Union[str, os.PathLike]) -> str:
    """``path`` as text of at most :data:`SHOWN_CHARS` characters (a long one keeps its start and end)."""
    text = os.fspath(path)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    if len(text) <= SHOWN_CHARS:
        return text
    half = (SHOWN_CHARS - 1) // 2
    return f"{text[:half]}…{text[-half:]} ({len(text)} characters)"


def _limit(base: Path, name: str, default: int) -> int:
    try:
        return int(os.pathconf(base, name))
    except (OSError, ValueError, AttributeError):
        return default


def path_problem(path: Union[str, os.PathLike]) -> Optional[str]:
    """Why ``path`` cannot name a file here (its text, shortened, and the reason), or None where it can (whether
    it exists or not: that is for the caller). Checks a NUL, each component's length against the file system's
    ``NAME_MAX`` and the whole against ``PATH_MAX`` (of its nearest existing folder), then ``lstat`` (a folder on
    the way that is a file, a loop of links, a folder that cannot be searched)."""
    text = os.fspath(path)
    raw = os.fsencode(text)
    if b"\0" in raw:
        return f"{shown(text.replace(chr(0), '<NUL>'))}: a path cannot hold a NUL character"
    p = Path(text)
    base = p.absolute().parent
    while True:
        try:
            if base.is_dir():
                break
        except (OSError, ValueError):
            pass
        if base == base.parent:
            break
        base = base.parent
    name_max = _limit(base, "PC_NAME_MAX", 255)
    long = next((part for part in p.parts if len(os.fsencode(part)) > name_max), None)
    if long is not None:
        return (f"{shown(text)}: a name in it is {len(os.fsencode(long))} bytes long; the file system allows at "
                f"most {name_max}")
    path_max = _limit(base, "PC_PATH_MAX", 4096)
    if len(os.fsencode(os.path.abspath(text))) >= path_max:
        return f"{shown(text)}: {len(os.fsencode(os.path.abspath(text)))} bytes in all; the file system allows " \
               f"at most {path_max - 1}"
    try:
        os.lstat(text)
    except (FileNotFoundError, NotADirectoryError):
        return None  # (missing, or under a file: the caller says which it needs)
    except OSError as exc:
        if exc.errno in (errno.ENOENT, errno.ENOTDIR):
            return None
        return f"{shown(text)}: {exc.strerror or exc}"
    return None
