"""Scene files as text: a size limit, a guarded YAML loader, bounded previews of values.

Every scene text (a file, a bag's embedded scene) is parsed by :func:`parse_scene_text`; a file is read
by :func:`read_scene_file`. A hostile or broken text is refused with one :class:`SceneError` line
before it costs more than the limits below (parsing a 1 MiB scene takes ~1 s, ~100 MB):

- at most :data:`MAX_SCENE_BYTES` bytes, UTF-8 (the refusal names the first bad byte's offset);
- YAML (1.1 as PyYAML reads it, but floats as YAML 1.2: ``2.5e7``, ``1e-3`` and ``.5`` are numbers,
  not texts) with at most :data:`MAX_ALIASES` alias uses, :data:`MAX_NODES` nodes counting every use of
  an alias in full (no "billion laughs"), :data:`MAX_DEPTH` levels of nesting, no recursive alias and no
  key given twice in one mapping (``<<`` merges may still be overridden).

:func:`preview` and :func:`clip` bound what an error message quotes.
"""
from __future__ import annotations

import os
import re
import reprlib
from pathlib import Path
from typing import Any, Union

import yaml
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.events import AliasEvent
from yaml.nodes import ScalarNode
from yaml.resolver import Resolver

__all__ = ["SceneError", "MAX_SCENE_BYTES", "MAX_ALIASES", "MAX_NODES", "MAX_DEPTH", "PREVIEW_CHARS",
           "clip", "preview", "human_bytes", "read_scene_file", "decode_scene_bytes", "parse_scene_text",
           "dump_scene_data"]

MAX_SCENE_BYTES = 1 << 20  # bytes of a scene file (1 MiB: ~25,000 commands written one a line)
MAX_ALIASES = 100  # uses of YAML aliases (*name) in one scene text
MAX_NODES = 250_000  # YAML nodes (scalars, lists, mappings) of one scene, every alias use counted in full
MAX_DEPTH = 50  # levels of nesting of lists and mappings (a scene needs 5)
PREVIEW_CHARS = 80  # characters of a value an error message quotes

_FLOAT_TAG = "tag:yaml.org,2002:float"
_MERGE_TAG = "tag:yaml.org,2002:merge"


class SceneError(ValueError):
    """A scene that cannot be run: the message names the key, the value and what is allowed."""


# --- bounded text -------------------------------------------------------------------------

def clip(text: str, limit: int = PREVIEW_CHARS) -> str:
    """``text`` cut to ``limit`` characters, the cut marked by a final '…'."""
    return text if len(text) <= limit else text[: max(limit - 1, 0)] + "…"


class _Preview(reprlib.Repr):
    """reprlib with small limits; values of other types than YAML's are shown by their type name only
    (their repr may be long or costly)."""

    _PLAIN = (int, float, complex, str, bytes, bool, type(None))

    def __init__(self, limit: int):
        super().__init__()
        self.maxlevel, self.maxdict, self.maxlist, self.maxtuple = 3, 4, 6, 6
        self.maxset = self.maxfrozenset = self.maxdeque = self.maxarray = 6
        self.maxstring = self.maxother = self.maxlong = limit

    def repr_instance(self, x: Any, level: int) -> str:
        import datetime

        if isinstance(x, self._PLAIN + (datetime.date, datetime.time)):
            return super().repr_instance(x, level)
        return f"<{type(x).__name__}>"


def preview(value: Any, limit: int = PREVIEW_CHARS) -> str:
    """A repr of ``value`` of at most ``limit`` characters, made in time bounded by ``limit`` (long lists,
    deep or shared structures and long texts are elided, not walked)."""
    try:
        text = _Preview(limit).repr(value)
    except Exception:  # noqa: BLE001 - a value whose repr fails: its type is still worth naming
        text = f"<{type(value).__name__}>"
    return clip(text, limit)


def human_bytes(n: float) -> str:
    """``n`` bytes as '1 MiB', '4.5 GiB' (binary units)."""
    if not n < float("inf"):
        return "unbounded"
    for unit, size in (("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n:.0f} bytes"


# --- reading ------------------------------------------------------------------------------

def _head(where: str, kind: str = "scene") -> str:
    return f"invalid {kind} {where}" if where else f"invalid {kind}"


def read_scene_file(path: Union[str, Path], limit: int = MAX_SCENE_BYTES, *, kind: str = "scene") -> str:
    """The text of a scene file: at most ``limit`` bytes are read (a larger file is refused before parsing,
    naming its size and the limit), decoded as UTF-8 (:func:`decode_scene_bytes`). Raises SceneError whose
    message starts 'invalid {kind} {path}' (``kind``: "scene", "sweep")."""
    p = Path(path)
    try:
        with open(p, "rb") as f:
            data = f.read(limit + 1)
            if len(data) > limit:
                size = os.fstat(f.fileno()).st_size
                said = f"{size} bytes ({human_bytes(size)})" if size > limit else f"more than {limit} bytes"
                raise SceneError(f"{_head(str(p), kind)}: the file is {said}; a {kind} file is at most {limit} bytes "
                                 f"({human_bytes(limit)})")
    except OSError as e:
        raise SceneError(f"{_head(str(p), kind)}: cannot read it: {clip(e.strerror or str(e))}") from None
    return decode_scene_bytes(data, str(p), kind=kind)


def decode_scene_bytes(data: bytes, where: str = "", *, kind: str = "scene") -> str:
    """``data`` as text: UTF-8 (a leading byte-order mark is dropped); else SceneError naming the offset
    (bytes from the start) and the line of the first byte that is not UTF-8."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise SceneError(f"{_head(where, kind)}: byte {e.start} (line {line}) is not UTF-8 "
                         f"(0x{data[e.start]:02x}); a {kind} file is UTF-8 text") from None
    return text[1:] if text.startswith("\ufeff") else text


# --- the YAML loader ----------------------------------------------------------------------

class _SceneResolver(Resolver):
    """PyYAML's resolver with YAML 1.2 floats: ``2.5e7``, ``1e-3``, ``.5``, ``-.5`` are floats (YAML 1.1
    reads the first two as texts, as it wants a '.' and a signed exponent); the 1.1 sexagesimal floats
    (``1:30.0``) are texts. ``.inf`` and ``.nan`` stay floats (the models refuse them where a physical
    quantity is asked for)."""

    yaml_implicit_resolvers = {first: [(tag, rx) for tag, rx in resolvers if tag != _FLOAT_TAG]
                               for first, resolvers in Resolver.yaml_implicit_resolvers.items()}


_SceneResolver.add_implicit_resolver(
    _FLOAT_TAG,
    re.compile(r"""^(?:[-+]?[0-9][0-9_]*\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                                 |[-+]?\.[0-9][0-9_]*(?:[eE][-+]?[0-9]+)?
                                 |[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+
                                 |[-+]?\.(?:inf|Inf|INF)
                                 |\.(?:nan|NaN|NAN))$""", re.X),
    list("-+0123456789."))


class _Refused(Exception):
    """A limit of the loader was hit: the message (one line, without the scene's name) says which."""


class _GuardedComposer(Composer):
    """PyYAML's composer that counts as it goes and stops at the first limit hit (see the module docstring):
    nodes and depth with every alias use expanded (an anchored node's size and height are kept, so an
    alias costs O(1)), alias uses, recursive aliases and keys given twice in a mapping."""

    def __init__(self) -> None:
        super().__init__()
        self._nodes = 0  # nodes so far, aliases expanded
        self._aliases = 0
        self._depth = 0  # depth of the node being composed (the root is 1)
        self._deepest = 0  # the deepest level reached within the node being composed
        self._anchored: dict[int, tuple[int, int]] = {}  # id(node) → (size, height) of a finished anchored node

    def _count(self, n: int, mark) -> None:
        self._nodes += n
        if self._nodes > MAX_NODES:
            raise _Refused(f"{_where(mark)}: the document has more than {MAX_NODES} YAML nodes (each use of an "
                           "alias counted in full); write a smaller scene")

    def _reach(self, depth: int, mark) -> None:
        if depth > MAX_DEPTH:
            raise _Refused(f"{_where(mark)}: lists and mappings nested deeper than {MAX_DEPTH} levels "
                           "(aliases expanded); a scene needs about 5")
        self._deepest = max(self._deepest, depth)

    def compose_node(self, parent, index):
        if self.check_event(AliasEvent):
            mark = self.peek_event().start_mark
            self._aliases += 1
            if self._aliases > MAX_ALIASES:
                raise _Refused(f"{_where(mark)}: more than {MAX_ALIASES} uses of YAML aliases (*name); "
                               "write the values out")
            node = super().compose_node(parent, index)
            size_height = self._anchored.get(id(node))
            if size_height is None:
                raise _Refused(f"{_where(mark)}: the alias is used inside the node it names (a recursive "
                               "structure); a scene is a tree")
            self._count(size_height[0], mark)
            self._reach(self._depth + size_height[1], mark)
            return node
        event = self.peek_event()
        self._count(1, event.start_mark)
        start = self._nodes - 1
        self._depth += 1
        self._reach(self._depth, event.start_mark)
        outer_deepest, self._deepest = self._deepest, self._depth  # the deepest level within this node
        node = super().compose_node(parent, index)
        if event.anchor is not None:
            self._anchored[id(node)] = (self._nodes - start, self._deepest - self._depth + 1)
        self._depth -= 1
        self._deepest = max(outer_deepest, self._deepest)
        return node

    def compose_mapping_node(self, anchor):
        node = super().compose_mapping_node(anchor)
        first: dict[tuple, Any] = {}
        for key, _ in node.value:
            if not isinstance(key, ScalarNode) or key.tag == _MERGE_TAG:
                continue
            seen = first.setdefault((key.tag, key.value), key)
            if seen is not key:
                raise _Refused(f"{_where(key.start_mark)}: key {preview(key.value)} is given twice in one mapping "
                               f"(first at line {seen.start_mark.line + 1}); give each key once")
        return node


def _where(mark) -> str:
    return f"line {mark.line + 1}, column {mark.column + 1}" if mark is not None else "(unknown place)"


if getattr(yaml, "__with_libyaml__", False):
    from yaml._yaml import CParser

    class _SceneLoader(_GuardedComposer, CParser, SafeConstructor, _SceneResolver):
        """libyaml's parser (C, ~3× faster than PyYAML's) with the guarded composer on top: the composer comes
        first in the MRO, so CParser's own composer (C, it counts nothing) is never used."""

        def __init__(self, stream):
            CParser.__init__(self, stream)
            _GuardedComposer.__init__(self)
            SafeConstructor.__init__(self)
            _SceneResolver.__init__(self)
else:  # pragma: no cover - PyYAML without libyaml
    _SceneLoader = None


class _PureSceneLoader(yaml.reader.Reader, yaml.scanner.Scanner, yaml.parser.Parser, _GuardedComposer,
                       SafeConstructor, _SceneResolver):
    """The same loader on PyYAML's pure-Python parser (where libyaml is missing)."""

    def __init__(self, stream):
        yaml.reader.Reader.__init__(self, stream)
        yaml.scanner.Scanner.__init__(self)
        yaml.parser.Parser.__init__(self)
        _GuardedComposer.__init__(self)
        SafeConstructor.__init__(self)
        _SceneResolver.__init__(self)


def _yaml_problem(e: BaseException) -> str:
    """One line of a YAML error: where, and what."""
    if isinstance(e, yaml.MarkedYAMLError):
        mark = e.problem_mark or e.context_mark
        what = "; ".join(clip(str(x), 120) for x in (e.context, e.problem) if x)
        return f"{_where(mark)}: {what}" if mark is not None else what
    return clip(" ".join(str(e).split()), 200)


def parse_scene_text(text: Union[str, bytes], where: str = "", *, kind: str = "scene", pure: bool = False) -> Any:
    """The data of a scene's YAML text (dicts, lists, scalars), read with the limits of the module docstring;
    a refused or invalid text raises one SceneError line 'invalid {kind} {where}: …' (``where``: a file,
    "(embedded scene)"; ``kind``: "scene", or "sweep" for a sweep file). Bytes are decoded as UTF-8 first.
    ``pure``: PyYAML's Python parser even where libyaml is present (tests)."""
    if isinstance(text, (bytes, bytearray)):
        if len(text) > MAX_SCENE_BYTES:
            raise SceneError(f"{_head(where, kind)}: the text is {len(text)} bytes; a {kind} is at most "
                             f"{MAX_SCENE_BYTES} bytes ({human_bytes(MAX_SCENE_BYTES)})")
        text = decode_scene_bytes(bytes(text), where, kind=kind)
    elif len(text) > MAX_SCENE_BYTES:  # characters ≤ UTF-8 bytes: more characters is more bytes
        raise SceneError(f"{_head(where, kind)}: the text is {len(text)} characters; a {kind} is at most "
                         f"{MAX_SCENE_BYTES} bytes ({human_bytes(MAX_SCENE_BYTES)})")
    loader = None
    try:
        # the pure loader's Reader checks the whole text for non-printable characters when made
        loader = (_PureSceneLoader if pure or _SceneLoader is None else _SceneLoader)(text)
        return loader.get_single_data()
    except _Refused as e:
        raise SceneError(f"{_head(where, kind)}: {e}") from None
    except Exception as e:  # noqa: BLE001 - YAMLError, and what the safe constructor's conversions raise on
        # malformed tagged scalars: int('abc') ValueError, datetime(…) ValueError/OverflowError, `!!float ''`
        # IndexError, `!!timestamp ''` AttributeError: all of them an invalid text
        raise SceneError(f"{_head(where, kind)}: not valid YAML: {_yaml_problem(e)}") from None
    finally:
        if loader is not None:
            loader.dispose()


class _SceneDumper(yaml.SafeDumper):
    """SafeDumper that quotes the texts :func:`parse_scene_text` would read as numbers (``"1e3"``)."""

    yaml_implicit_resolvers = _SceneResolver.yaml_implicit_resolvers


def dump_scene_data(data: Any) -> str:
    """YAML text of scene data (a ``Scene.model_dump(mode="json")``) that :func:`parse_scene_text` reads back
    as the same data (block style, keys in order)."""
    return yaml.dump(data, Dumper=_SceneDumper, sort_keys=False, allow_unicode=True)
