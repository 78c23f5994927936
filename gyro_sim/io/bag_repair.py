"""Recovering a recording that was cut: ``gyro-sim bag recover BAG``.

A bag is closed by its writer: the MCAP file gets its summary (schemas, channels, chunk
indexes, statistics) and footer, then ``metadata.yaml`` is written. A recording killed with
``kill -9``, by a crash or a power loss leaves ``BAG/BAG.mcap`` without summary and footer and no
``metadata.yaml``; rosbags, ``ros2 bag`` and ``gyro-sim info/plot/replay`` refuse it.
:func:`recover_bag` rebuilds such a bag into a complete rosbag2 bag (format version 8, MCAP),
as ``ros2 bag reindex`` and ``mcap recover`` do, and more:

**What is kept.** The MCAP file is read record by record from its start (each record's
opcode and length frame it; its content is parsed with the ``mcap`` library's record classes),
in file order: schemas, channels, the messages of every chunk that is whole and consistent
(decompressed; its CRC checked when it has one; its records parsed to exactly its uncompressed
size; every message on a channel defined before it, within the chunk's time range) and messages
outside chunks. Reading stops at the first record that is cut (where the crash cut the file),
that is malformed (an unknown opcode, a length past the end of the file, a content that does not
parse: garbage after the cut) or at the end of the data section (``DataEnd``: only the summary
was lost). A chunk that is framed right but fails its checks is skipped (reported) and reading
goes on after it. Messages keep their topic, log time and bytes; each channel's topic, message
type, message definition (the schema text), serialization format and ``offered_qos_profiles``
are kept; the ``type_description_hash`` of metadata.yaml is computed from the definition.
Publish times become the log times and sequence numbers 0 (rosbags' writer; gyro_sim writes
them so). Attachments and MCAP metadata records other than ``rosbag2`` are not carried over
(counted in the report).

**custom_data.** Rebuilt from, in this order, the ``rosbag2`` metadata record of the MCAP file
(written at close: present only when the cut came after it), a ``metadata.yaml`` already in the
bag (unused by today's recorder before close), and the messages: ``gyro_sim.scene`` from the
first ``/gyro/scene`` message, ``gyro_sim.scene_name`` from the scene's ``name:`` key (else the
bag's directory name), ``gyro_sim.version`` when one of the first two sources says it (it is not
in the messages). ``gyro_sim.end`` says ``interrupted: recovered (...)``: where the file was cut,
how many bytes and which record at the tail were dropped, how many messages were kept; when the
data section was whole (only the summary, the footer or metadata.yaml were lost) the recorded end
is kept and the recovery appended.

**Complete.** A bag is complete (closed) when its directory holds exactly one ``.mcap`` file
that ends with an MCAP footer and the end magic, and a ``metadata.yaml`` holding
``rosbag2_bagfile_information``; anything else with one ``.mcap`` file is *not closed*
(:func:`not_closed`) and recoverable. A complete bag is refused ("nothing to recover") unless one of its
chunks fails its CRC (gyro_sim writes them: :func:`gyro_sim.io.bag_format.write_chunk_crcs`; readers then say to
recover it, :func:`damaged_message`): it is rebuilt without them, each listed. Refused too are a file that is
not MCAP at all (no magic at its start: :func:`not_mcap_message`, what the readers say of it) and
one whose ``.mcap`` file another process holds an exclusive ``flock`` on (a recorder that locks its
file while recording: recovering under a live writer would race it).

**Safe.** The new bag is written by rosbags' rosbag2 :class:`~rosbags.rosbag2.Writer` into a
temporary directory next to ``BAG`` (``.BAG.recover-*``), read back (rosbags reads every
message; the ``mcap`` reader checks the summary), synced to disk, and only then put in place:
the damaged original stays as ``BAG/<name>.mcap.damaged`` (a hard link made before the new file
replaces it, so that ``BAG/<name>.mcap`` exists at every instant; a rename where hard links are
not supported) and a previous ``metadata.yaml``, if any, as ``metadata.yaml.damaged`` (a free
name ``.damaged-2``, ... if taken). Nothing is deleted: remove the ``.damaged`` files once the
recovered bag is checked. On any failure the bag is left as it was (the moves made are undone)
and the temporary directory is removed (a recover that is itself killed can leave one
``.BAG.recover-*`` directory behind: delete it).
"""
from __future__ import annotations

import os
import shutil
import struct
import tempfile
from collections import Counter
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO, Callable, Iterator, Optional, Union

import yaml

from gyro_sim.io.messages import TOPIC_KINETIC_MOMENT, TOPIC_SCENE
from gyro_sim.io.bag_format import BAG_VERSION, CUSTOM_KEYS, EARLY_METADATA, RESERVE_NAME, write_chunk_crcs

if TYPE_CHECKING:  # pragma: no cover
    from mcap.records import Chunk, McapRecord

__all__ = ["recover_bag", "RecoverError", "not_closed", "not_closed_message", "mcap_closed", "NOT_CLOSED",
           "damaged_chunks", "damaged_message", "not_mcap_message"]

#: the one line readers print for a bag that was not closed (``{bag}``: the path as given)
NOT_CLOSED = ("{bag} was not closed (the recording was cut: kill -9, crash or power loss); "
              "run: gyro-sim bag recover {bag}")

MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEAD = 9  # opcode (1) + length (8)
_FOOTER_BYTES = _RECORD_HEAD + 20 + len(MAGIC)  # footer record + end magic
_METADATA_YAML = "metadata.yaml"
_DAMAGED = ".damaged"


class RecoverError(Exception):
    """The path cannot be recovered, or need not be; the message names it and says why."""


class _Unusable(Exception):
    """The damaged file cannot give a bag (not an MCAP file, nothing whole in it, a channel that cannot
    be rebuilt); the message says why, without the path."""


class _Cut(Exception):
    """The file ends inside a record."""


class _Malformed(Exception):
    """A record whose framing or content is wrong (garbage, or a damaged record)."""


# --- is a bag closed? -----------------------------------------------------------------------------

def mcap_closed(path: Union[str, os.PathLike]) -> bool:
    """True if the MCAP file starts with the magic and ends with a footer record and the end magic
    (its summary offset, if any, inside the file): its writer closed it."""
    try:
        with open(path, "rb") as f:
            size = f.seek(0, os.SEEK_END)
            if size < len(MAGIC) + _FOOTER_BYTES:
                return False
            f.seek(0)
            if f.read(len(MAGIC)) != MAGIC:
                return False
            f.seek(size - _FOOTER_BYTES)
            tail = f.read(_FOOTER_BYTES)
    except OSError:
        return False
    op, length, summary_start = struct.unpack_from("<BQQ", tail)
    return (tail[-len(MAGIC):] == MAGIC and op == 0x02 and length == 20
            and (summary_start == 0 or len(MAGIC) <= summary_start <= size - _FOOTER_BYTES))


def _metadata_ok(bag: Path) -> bool:
    """True if ``bag/metadata.yaml`` parses and holds ``rosbag2_bagfile_information``."""
    try:
        info = yaml.safe_load((bag / _METADATA_YAML).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return False
    return isinstance(info, dict) and isinstance(info.get("rosbag2_bagfile_information"), dict)


def _mcap_files(bag: Path) -> list[Path]:
    return sorted(p for p in bag.glob("*.mcap") if p.is_file())


def _bag_dir_of(path: Path) -> Optional[Path]:
    """The bag directory ``path`` names: itself, or the directory of its ``NAME/NAME.mcap`` file."""
    if path.is_dir():
        return path
    if path.suffix == ".mcap" and path.parent.name == path.stem and path.is_file():
        return path.parent
    return None


def not_closed(path: Union[str, os.PathLike]) -> Optional[Path]:
    """The bag directory if ``path`` (a bag directory or its ``NAME/NAME.mcap``) is a bag whose
    recording was not closed (its one .mcap file without footer, or no valid metadata.yaml); else
    None (a complete bag, or not a bag at all)."""
    bag = _bag_dir_of(Path(path))
    if bag is None:
        return None
    files = _mcap_files(bag)
    if len(files) != 1:
        return None
    return None if _metadata_ok(bag) and mcap_closed(files[0]) else bag


def not_closed_message(path: Union[str, os.PathLike]) -> Optional[str]:
    """:data:`NOT_CLOSED` for ``path`` (shown as given, or as its bag directory when a file was
    given) if it is a bag that was not closed, else None."""
    bag = not_closed(path)
    if bag is None:
        return None
    return not_mcap_message(path) or NOT_CLOSED.format(bag=path if Path(path).is_dir() else bag)


def _starts_as_mcap(mcap: Path) -> bool:
    """True unless the file's first bytes are not the MCAP magic (an empty file, or one cut inside the magic, is a
    recording cut at its start: True)."""
    try:
        with open(mcap, "rb") as f:
            head = f.read(len(MAGIC))
    except OSError:
        return True
    return MAGIC.startswith(head)


def not_mcap_message(path: Union[str, os.PathLike]) -> Optional[str]:
    """The one line for a bag directory (or its ``NAME/NAME.mcap``) whose one .mcap file is not an MCAP file at all
    (no MCAP magic at its start: random bytes, another format), or None."""
    bag = _bag_dir_of(Path(path))
    files = _mcap_files(bag) if bag is not None else []
    if len(files) != 1 or _starts_as_mcap(files[0]):
        return None
    return (f"{path}: {files[0].name} is not an MCAP file (no MCAP magic at its start): not a bag; gyro-sim bag "
            "recover cannot rebuild it either")


def damaged_chunks(mcap: Union[str, os.PathLike]) -> list[str]:
    """The chunks of an MCAP file's data section whose records do not match their CRC (or do not decompress),
    each as 'the chunk at byte N (M bytes): why'; [] for a sound file. Reads the whole data section (decompressing
    and checksumming each chunk, not parsing its messages); stops at its end or at a record that is cut."""
    from mcap.opcode import Opcode
    from mcap.records import Chunk

    bad: list[str] = []
    with open(mcap, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        if f.read(len(MAGIC)) != MAGIC:
            return bad
        pos = len(MAGIC)
        while pos < size:
            try:
                op, content = _read_frame(f, pos, size)
            except (_Cut, _Malformed):
                break
            if op in (Opcode.DATA_END, Opcode.FOOTER):
                break
            if op == Opcode.CHUNK:
                try:
                    chunk = _parse(op, content)
                    assert isinstance(chunk, Chunk)
                    _check_chunk(chunk)
                except _Malformed as exc:
                    bad.append(f"the chunk at byte {pos} ({len(content)} bytes): {exc}")
            pos += _RECORD_HEAD + len(content)
    return bad


def damaged_message(path: Union[str, os.PathLike]) -> Optional[str]:
    """The one line for a closed bag (directory or ``NAME/NAME.mcap``) with damaged chunks (:func:`damaged_chunks`),
    saying what to run, or None."""
    bag = _bag_dir_of(Path(path))
    files = _mcap_files(bag) if bag is not None else []
    if len(files) != 1:
        return None
    bad = damaged_chunks(files[0])
    if not bad:
        return None
    return (f"{len(bad)} damaged chunk(s) in {files[0].name} ({bad[0]}{'; ...' if len(bad) > 1 else ''}); "
            f"run: gyro-sim bag recover {path} (it keeps every sound chunk and says which it dropped)")


# --- reading the damaged file ----------------------------------------------------------------------

def _record_name(op: int) -> str:
    from mcap.opcode import Opcode

    try:
        return Opcode(op).name.title().replace("_", "")
    except ValueError:
        return f"0x{op:02x}"


def _read_frame(f: BinaryIO, pos: int, size: int) -> tuple[int, bytes]:
    """(opcode, content) of the record at ``pos`` (the file positioned there, ``size`` bytes long).

    Raises _Cut if the file ends inside it, _Malformed for an opcode MCAP does not define (0x80 and
    up are private records, accepted)."""
    from mcap.opcode import Opcode

    left = size - pos
    if left < _RECORD_HEAD:
        raise _Cut(f"a record header cut after {left} of {_RECORD_HEAD} bytes")
    op, length = struct.unpack("<BQ", f.read(_RECORD_HEAD))
    if op < 0x80 and op not in {o.value for o in Opcode}:
        raise _Malformed(f"not an MCAP record (opcode 0x{op:02x})")
    if length > left - _RECORD_HEAD:
        raise _Cut(f"a {_record_name(op)} record cut after {left - _RECORD_HEAD} of {length} bytes")
    return op, f.read(length)


def _parse(op: int, content: bytes) -> "McapRecord":
    """A record's content parsed by the ``mcap`` library; _Malformed if it does not parse."""
    from mcap.data_stream import ReadDataStream
    from mcap.exceptions import McapError
    from mcap.opcode import Opcode
    from mcap.records import Channel, Chunk, Header, Message, Metadata, Schema

    readers: dict[int, Callable] = {
        Opcode.HEADER: Header.read, Opcode.SCHEMA: Schema.read, Opcode.CHANNEL: Channel.read,
        Opcode.CHUNK: Chunk.read, Opcode.METADATA: Metadata.read,
        Opcode.MESSAGE: lambda s: Message.read(s, len(content)),
    }
    stream = ReadDataStream(BytesIO(content))
    try:
        rec = readers[op](stream)
    except (McapError, struct.error, UnicodeDecodeError, ValueError) as exc:
        raise _Malformed(f"a {_record_name(op)} record that does not parse ({type(exc).__name__})") from None
    return rec


@dataclass
class _Scan:
    """What reading the damaged file found (filled while its records are read)."""

    size: int  # bytes in the file
    kept_end: int = 0  # offset just past the last record read whole (kept or skipped)
    stop: str = ""  # why reading stopped
    data_end: bool = False  # the data section's end was reached: no message was cut off
    chunks: int = 0  # chunks kept
    bad_chunks: list[str] = field(default_factory=list)  # chunks skipped: where and why
    not_copied: Counter = field(default_factory=Counter)  # records not carried over, by kind
    schemas: dict[int, Any] = field(default_factory=dict)
    channels: dict[int, Any] = field(default_factory=dict)
    rosbag2: Optional[dict] = None  # the rosbag2 metadata record (written at close), parsed
    early: Optional[dict] = None  # the recorder's custom_data written at the start (EARLY_METADATA record)


def _define(rec: "McapRecord", schemas: dict, channels: dict) -> None:
    """Enter a Schema or Channel record; _Malformed if it redefines an id differently or a channel's
    schema is unknown."""
    from mcap.records import Schema

    table = schemas if isinstance(rec, Schema) else channels
    kind = "schema" if isinstance(rec, Schema) else "channel"
    if rec.id in table and table[rec.id] != rec:
        raise _Malformed(f"{kind} {rec.id} defined twice, differently")
    if kind == "channel" and rec.schema_id not in schemas:
        raise _Malformed(f"channel {rec.id} ({rec.topic}) on an undefined schema {rec.schema_id}")
    table[rec.id] = rec


def _check_chunk(chunk: "Chunk") -> bytes:
    """A chunk's records, decompressed and checked against its CRC (where it has one) and its declared size;
    _Malformed if it fails."""
    from mcap.stream_reader import CRCValidationError, get_chunk_data_stream

    try:
        stream, n = get_chunk_data_stream(chunk, validate_crc=True)
        raw = stream.read(n)
    except CRCValidationError as exc:
        raise _Malformed(f"its CRC does not match ({exc})") from None
    except Exception as exc:  # unknown compression, a damaged compressed stream
        raise _Malformed(f"cannot decompress it ({chunk.compression or 'none'}): {exc}") from None
    if n != chunk.uncompressed_size or len(raw) != n:
        raise _Malformed(f"{len(raw)} bytes, {chunk.uncompressed_size} declared")
    return raw


def _chunk_records(chunk: "Chunk", scan: _Scan) -> list:
    """The schema, channel and message records of a chunk, checked (see the module docstring);
    _Malformed if the chunk fails a check. Its definitions enter ``scan`` only if it passes."""
    from mcap.opcode import Opcode
    from mcap.records import Message

    raw = _check_chunk(chunk)
    n = len(raw)
    schemas, channels = dict(scan.schemas), dict(scan.channels)
    out, pos, f = [], 0, BytesIO(raw)
    while pos < n:
        try:
            op, content = _read_frame(f, pos, n)
        except _Cut as exc:
            raise _Malformed(f"its records overrun it ({exc})") from None
        pos += _RECORD_HEAD + len(content)
        if op not in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE):
            continue  # private records: not ours
        rec = _parse(op, content)
        if isinstance(rec, Message):
            if rec.channel_id not in channels:
                raise _Malformed(f"a message on an undefined channel {rec.channel_id}")
            if not chunk.message_start_time <= rec.log_time <= chunk.message_end_time:
                raise _Malformed(f"a message logged at {rec.log_time} ns, outside the chunk's time range")
        else:
            _define(rec, schemas, channels)
        out.append(rec)
    scan.schemas, scan.channels = schemas, channels
    return out


def _rosbag2_metadata(rec) -> Optional[dict]:
    """The rosbag2 bag information in a ``rosbag2`` metadata record, or None."""
    try:
        info = yaml.safe_load(rec.metadata.get("serialized_metadata", ""))
    except yaml.YAMLError:
        return None
    return info if isinstance(info, dict) else None


def _data_records(f: BinaryIO, scan: _Scan) -> Iterator["McapRecord"]:
    """Schema, Channel and Message records of an MCAP data section, in file order (those of a
    chunk in place), as far as the file can be read; ``scan`` says how far and why it stopped.

    _Unusable if the file is not an MCAP file or is cut inside its header."""
    from mcap.opcode import Opcode
    from mcap.records import Message

    magic = f.read(len(MAGIC))
    if magic != MAGIC:
        if len(magic) < len(MAGIC) and MAGIC.startswith(magic):
            raise _Unusable(f"the file holds only {len(magic)} bytes: the recording ended before anything "
                            "was written to it")
        raise _Unusable("not an MCAP file (no MCAP magic at its start)")
    try:
        op, content = _read_frame(f, len(MAGIC), scan.size)
        if op != Opcode.HEADER:
            raise _Malformed(f"its first record is a {_record_name(op)}, not a Header")
        _parse(op, content)
    except (_Cut, _Malformed) as exc:
        raise _Unusable(f"cut or damaged inside its MCAP header ({exc}; {scan.size} bytes in all): the "
                        "recording ended before any message was written") from None
    pos = scan.kept_end = len(MAGIC) + _RECORD_HEAD + len(content)
    while pos < scan.size:
        try:
            op, content = _read_frame(f, pos, scan.size)
            if op in (Opcode.DATA_END, Opcode.FOOTER):
                scan.data_end = True
            elif op == Opcode.CHUNK:
                yield from _kept_chunk(content, pos, scan)
            elif op in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE, Opcode.METADATA):
                rec = _parse(op, content)
                if isinstance(rec, Message):
                    if rec.channel_id not in scan.channels:
                        raise _Malformed(f"a Message on an undefined channel {rec.channel_id}")
                    yield rec
                elif op == Opcode.METADATA:
                    _metadata(rec, scan)
                else:
                    _define(rec, scan.schemas, scan.channels)
                    yield rec
            elif op == Opcode.HEADER:
                raise _Malformed("a second Header record")
            elif op == Opcode.ATTACHMENT:
                scan.not_copied["attachment"] += 1
        except _Cut as exc:
            scan.stop = str(exc)
            return
        except _Malformed as exc:
            scan.stop = f"unreadable from byte {pos}: {exc}"
            return
        pos = scan.kept_end = pos + _RECORD_HEAD + len(content)
        if scan.data_end:
            scan.stop = f"the end of the data section ({_record_name(op)})"
            return
    scan.stop = "the file ends after a whole record"  # (cut between two records)


def _kept_chunk(content: bytes, pos: int, scan: _Scan) -> list:
    """The records of the chunk whose content is given (at ``pos``), or [] after noting it as
    skipped if it fails its checks (it is framed right: reading goes on after it)."""
    from mcap.opcode import Opcode

    chunk = _parse(Opcode.CHUNK, content)
    try:
        records = _chunk_records(chunk, scan)
    except _Malformed as exc:
        scan.bad_chunks.append(f"the chunk at byte {pos} ({len(content)} bytes): {exc}")
        return []
    scan.chunks += 1
    return records


def _metadata(rec, scan: _Scan) -> None:
    """Note an MCAP metadata record: the ``rosbag2`` one is parsed, others are not carried over."""
    if rec.name == "rosbag2" and (info := _rosbag2_metadata(rec)) is not None:
        scan.rosbag2 = info
    elif rec.name == EARLY_METADATA and isinstance(rec.metadata, dict):
        scan.early = {"custom_data": dict(rec.metadata)}
    else:
        scan.not_copied["metadata"] += 1


# --- writing the recovered bag ---------------------------------------------------------------------

def _schema_types(schema) -> tuple[str, Any]:
    """(message definition text, a rosbags typestore holding its types) of a ROS 2 schema."""
    from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

    text = schema.data.decode("utf-8")
    if schema.encoding == "ros2msg":
        types = get_types_from_msg(text, schema.name)
    elif schema.encoding == "ros2idl":
        types = get_types_from_idl(text)
    else:
        raise ValueError(f"schema encoding {schema.encoding!r} is not a ROS 2 one (ros2msg, ros2idl)")
    store = get_typestore(Stores.EMPTY)
    store.register(types)
    return text, store


class _Rebuilt:
    """The recovered bag being written by rosbags' rosbag2 Writer (MCAP storage) at ``path``."""

    def __init__(self, path: Path):
        from rosbags.rosbag2 import StoragePlugin, Writer

        self.writer = Writer(path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        write_chunk_crcs(self.writer.storage)
        self.path = path
        self.conns: dict[int, Any] = {}  # MCAP channel id → rosbags connection
        self.by_key: dict[tuple, Any] = {}  # (topic, type, format, QoS) → connection: equal channels merged
        self.stores: dict[int, Any] = {}  # channel id → typestore of its schema
        self.counts: Counter = Counter()  # topic → messages written
        self.topics: dict[str, str] = {}  # topic → message type, every channel
        self.messages = 0
        self.start_ns: Optional[int] = None
        self.end_ns: Optional[int] = None
        self.scene_text: Optional[str] = None
        self.last_sample_ns: Optional[int] = None

    def channel(self, ch, schema) -> None:
        """Add a connection for an MCAP channel (its schema's definition, its QoS profiles)."""
        from rosbags.rosbag2.metadata import parse_qos

        try:
            msgdef, store = _schema_types(schema)
            qos = parse_qos(ch.metadata.get("offered_qos_profiles", ""))
        except Exception as exc:
            raise _Unusable(f"channel {ch.id} ({ch.topic}, {schema.name}): cannot rebuild its message "
                            f"definition or QoS: {exc}") from None
        key = (ch.topic, schema.name, ch.message_encoding, repr(qos))
        if key not in self.by_key:
            self.by_key[key] = self.writer.add_connection(
                ch.topic, schema.name, msgdef=msgdef, rihs01=store.hash_rihs01(schema.name),
                serialization_format=ch.message_encoding, offered_qos_profiles=qos)
        self.conns[ch.id] = self.by_key[key]
        self.stores[ch.id] = store
        self.topics.setdefault(ch.topic, schema.name)

    def message(self, msg) -> None:
        """Write one message (its log time and bytes)."""
        conn = self.conns[msg.channel_id]
        self.writer.write(conn, msg.log_time, msg.data)
        self.counts[conn.topic] += 1
        self.messages += 1
        self.start_ns = msg.log_time if self.start_ns is None else min(self.start_ns, msg.log_time)
        self.end_ns = msg.log_time if self.end_ns is None else max(self.end_ns, msg.log_time)
        if conn.topic == TOPIC_KINETIC_MOMENT:  # the state samples' last time: gyro_sim.duration
            self.last_sample_ns = max(self.last_sample_ns or 0, msg.log_time)
        if self.scene_text is None and conn.topic == TOPIC_SCENE and conn.msgtype == "std_msgs/msg/String":
            try:
                self.scene_text = self.stores[msg.channel_id].deserialize_cdr(msg.data, conn.msgtype).data
            except Exception:  # not a string after all: the scene stays unknown
                pass


def _copy_records(mcap: Path, out: _Rebuilt) -> _Scan:
    """Read the damaged file's records into the new bag; returns what reading found."""
    from mcap.records import Channel, Message

    with open(mcap, "rb") as f:
        scan = _Scan(size=os.fstat(f.fileno()).st_size)
        for rec in _data_records(f, scan):
            if isinstance(rec, Message):
                out.message(rec)
            elif isinstance(rec, Channel) and rec.id not in out.conns:  # its schema is defined (_define)
                out.channel(rec, scan.schemas[rec.schema_id])
    return scan


def _describe(scan: _Scan, out: _Rebuilt, mcap_name: str) -> str:
    """What was dropped and kept, in words (custom_data ``gyro_sim.end`` and the report)."""
    dropped = scan.size - scan.kept_end
    if scan.data_end:
        text = f"the data section of {mcap_name} is whole; the {dropped} bytes after it (summary, footer) rebuilt"
    else:
        text = f"the recording was cut: the last {dropped} of {scan.size} bytes of {mcap_name} dropped: {scan.stop}"
    text += f"; {out.messages} messages in {scan.chunks} whole chunk(s) kept"
    if scan.bad_chunks:
        text += f"; {len(scan.bad_chunks)} damaged chunk(s) skipped: " + "; ".join(scan.bad_chunks)
    return text


def _custom_data(scan: _Scan, out: _Rebuilt, bag: Path, what: str) -> dict[str, str]:
    """custom_data of the recovered bag (see the module docstring)."""
    custom: dict[str, str] = {}
    # the recorder's start-of-run record, then a metadata.yaml, then the rosbag2 record (written at close) wins
    for source in (scan.early, _old_yaml_info(bag), scan.rosbag2):
        if source and isinstance(source.get("custom_data"), dict):
            custom.update({str(k): str(v) for k, v in source["custom_data"].items() if v is not None})
    scene = out.scene_text if out.scene_text is not None else custom.get(CUSTOM_KEYS["scene"])
    if scene is not None:
        custom[CUSTOM_KEYS["scene"]] = scene
    if CUSTOM_KEYS["scene_name"] not in custom:
        custom[CUSTOM_KEYS["scene_name"]] = _scene_name(scene) or bag.name
    if out.last_sample_ns is not None and not (scan.data_end and "gyro_sim.duration" in custom):
        custom["gyro_sim.duration"] = repr(out.last_sample_ns / 1e9)  # the time the recovered samples reach, s
    recorded_end = custom.get(CUSTOM_KEYS["end"])
    if scan.data_end and recorded_end:
        custom[CUSTOM_KEYS["end"]] = f"{recorded_end}; recovered by gyro-sim bag recover ({what})"
    else:
        custom[CUSTOM_KEYS["end"]] = f"interrupted: recovered by gyro-sim bag recover ({what})"
    return custom


def _scene_name(scene: Optional[str]) -> Optional[str]:
    """The ``name:`` of a scene file text, if it has one."""
    from gyro_sim.scenes.scene_text import SceneError, parse_scene_text

    try:
        data = parse_scene_text(scene) if scene else None
    except SceneError:  # (a hostile or broken text: the name stays unknown)
        return None
    name = data.get("name") if isinstance(data, dict) else None
    return str(name) if name not in (None, "") else None


def _old_yaml_info(bag: Path) -> Optional[dict]:
    """The rosbag2_bagfile_information of a metadata.yaml already in the bag, if it parses."""
    if not _metadata_ok(bag):
        return None
    return yaml.safe_load((bag / _METADATA_YAML).read_text(encoding="utf-8"))["rosbag2_bagfile_information"]


def _verify(path: Path, out: _Rebuilt) -> None:
    """Read the new bag back (rosbags: metadata and every message; mcap: the summary); _Unusable
    if it does not say what was written."""
    from mcap.reader import make_reader
    from rosbags.rosbag2 import Reader

    try:
        with Reader(path) as reader:
            counts = {t: int(ti.msgcount) for t, ti in reader.topics.items()}
            read = sum(1 for _ in reader.messages())
        custom = (_old_yaml_info(path) or {}).get("custom_data") or {}
        custom_ok = CUSTOM_KEYS["end"] in custom
        with open(path / f"{path.name}.mcap", "rb") as f:
            summary = make_reader(f).get_summary()
        stats = summary.statistics.message_count if summary and summary.statistics else None
    except Exception as exc:
        raise _Unusable(f"the rebuilt bag does not read back: {exc}") from None
    want = {t: out.counts.get(t, 0) for t in out.topics}
    if counts != want or read != out.messages or stats != out.messages or not custom_ok:
        raise _Unusable(f"the rebuilt bag does not read back as written ({read} messages read, "
                           f"{stats} in its summary, {out.messages} written)")


# --- putting it in place ---------------------------------------------------------------------------

def _fsync(path: Path) -> None:
    """Flush a file's or a directory's data to disk (where the system allows it)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _free_name(path: Path) -> Path:
    """``path`` + ``.damaged``, or ``.damaged-2``, ``-3``, ... : a name not taken."""
    cand = path.with_name(path.name + _DAMAGED)
    n = 2
    while cand.exists() or cand.is_symlink():
        cand = path.with_name(f"{path.name}{_DAMAGED}-{n}")
        n += 1
    return cand


def _set_aside(old: Path, undo: list) -> Path:
    """Give ``old`` a ``.damaged`` name: a hard link (``old`` stays until replaced) or, where links
    are not supported, a rename. Appends the step's undo to ``undo``; returns the new name."""
    aside = _free_name(old)
    try:
        os.link(old, aside)
    except OSError:
        os.rename(old, aside)
        undo.append(lambda: os.replace(aside, old))
    else:
        # linked: old is either still the same file (drop the link) or replaced (put it back)
        undo.append(lambda: os.replace(aside, old) if not _same_file(aside, old) else os.unlink(aside))
    return aside


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _install(new: Path, bag: Path, old_mcap: Path) -> dict[str, str]:
    """Put the new bag's .mcap and metadata.yaml into ``bag``, the old ones set aside; all or nothing.

    The new .mcap goes first (metadata.yaml last: until it is there the bag still reads as not
    closed). Returns the set-aside names."""
    new_mcap = new / f"{new.name}.mcap"
    targets = [(old_mcap, new_mcap, bag / new_mcap.name), (bag / _METADATA_YAML, new / _METADATA_YAML,
                                                          bag / _METADATA_YAML)]
    undo: list[Callable[[], Any]] = []
    aside: dict[str, str] = {}
    try:
        shutil.copymode(old_mcap, new_mcap)
        for old, src, dst in targets:
            if old.exists():
                aside[old.name] = str(_set_aside(old, undo))
                if old != dst and old.exists():  # a bag directory renamed since it was recorded
                    os.unlink(old)  # (its data is at the .damaged name)
                    undo.append(lambda old=old, a=Path(aside[old.name]): os.link(a, old))
            os.replace(src, dst)
            undo.append(lambda src=src, dst=dst: os.replace(dst, src))
        _fsync(bag)
    except BaseException:
        for step in reversed(undo):
            try:
                step()
            except OSError:
                pass
        raise
    return aside


# --- the whole ---------------------------------------------------------------------------------------

def _locked(mcap: Path) -> bool:
    """True if a process holds an exclusive ``flock`` on the file: a recorder still writing it (a
    recorder that takes one; always False where ``fcntl`` is missing)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        return False
    try:
        with open(mcap, "rb") as f:
            try:
                fcntl.flock(f.fileno(), fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                return True
            except OSError:  # a file system without flock: cannot tell
                return False
            fcntl.flock(f.fileno(), fcntl.LOCK_UN)
    except OSError:
        return False
    return False


def _bag_and_mcap(path: Path) -> tuple[Path, Path]:
    """The bag directory and its one .mcap file; RecoverError if ``path`` is not such a bag or is
    complete."""
    if not path.exists():
        raise RecoverError(f"{path}: no such bag directory")
    if not path.is_dir():
        hint = f": give its directory, {path.parent}" if path.suffix == ".mcap" else ""
        raise RecoverError(f"{path}: not a bag directory (a bag is the directory that holds the .mcap file){hint}")
    files = _mcap_files(path)
    if not files:
        raise RecoverError(f"{path}: not a bag: no .mcap file in it")
    if len(files) > 1:
        raise RecoverError(f"{path}: holds {len(files)} .mcap files ({', '.join(p.name for p in files)}); "
                           "recover handles a one-file bag, as gyro_sim records")
    if not _starts_as_mcap(files[0]):
        raise RecoverError(f"{path}: {files[0].name}: not an MCAP file (no MCAP magic at its start); the bag is "
                           "left as it was")
    if _metadata_ok(path) and mcap_closed(files[0]) and not damaged_chunks(files[0]):
        raise RecoverError(f"{path}: nothing to recover: the bag is complete "
                           f"({files[0].name} is closed and metadata.yaml is there)")
    if _locked(files[0]):
        raise RecoverError(f"{path}: {files[0].name} is locked by a process that is still recording it; "
                           "recover it once that recording has ended (nothing was changed)")
    return path, files[0]


def recover_bag(path: Union[str, os.PathLike]) -> dict[str, Any]:
    """Rebuild a bag whose recording was cut (see the module docstring) and put it in place.

    Returns a report: ``path`` (the bag), ``mcap`` (the recovered file), ``set_aside`` (old name →
    ``.damaged`` name), ``messages``, ``topics`` (topic → [type, count], every channel),
    ``start_ns``/``end_ns`` (log times), ``chunks``, ``bad_chunks``, ``size``/``kept_bytes``/
    ``dropped_bytes`` (of the damaged file), ``cut`` (False when only the summary was missing),
    ``stop`` (why reading stopped), ``not_copied`` (attachments, metadata records), ``end`` and
    ``scene_name`` (custom_data). RecoverError (one line naming the path) if the path is not a
    bag, is complete, holds no whole message, or cannot be rebuilt; the bag is then left as it was.
    """
    given = Path(path)
    bag, mcap = _bag_and_mcap(given)
    bag = bag.resolve()  # the temporary directory on the bag's file system (a rename cannot cross one)
    mcap = bag / mcap.name
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{bag.name}.recover-", dir=bag.parent))
    except OSError as exc:
        raise RecoverError(f"{given}: cannot make a temporary directory next to it in {bag.parent}: "
                           f"{exc.strerror or exc}") from None
    try:
        new = tmp / bag.name
        out, scan, custom = _rebuild(mcap, new, bag, given)
        try:
            _verify(new, out)
        except _Unusable as exc:
            raise RecoverError(f"{given}: {exc}; the bag is left as it was") from None
        for p in (new / f"{new.name}.mcap", new / _METADATA_YAML, new):
            _fsync(p)
        try:
            aside = _install(new, bag, mcap)
        except OSError as exc:
            raise RecoverError(f"{given}: cannot put the recovered bag in place: {exc}; the bag is left as it "
                               "was") from None
        try:  # the space reserve an older recorder left in the folder when it was killed (4 MiB)
            (bag / RESERVE_NAME).unlink()
        except OSError:
            pass
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {
        "path": str(given), "mcap": str(given / f"{bag.name}.mcap"),
        "set_aside": {old: str(given / Path(a).name) for old, a in aside.items()},
        "messages": out.messages, "topics": {t: [ty, out.counts.get(t, 0)] for t, ty in out.topics.items()},
        "start_ns": out.start_ns, "end_ns": out.end_ns, "chunks": scan.chunks, "bad_chunks": list(scan.bad_chunks),
        "size": scan.size, "kept_bytes": scan.kept_end, "dropped_bytes": scan.size - scan.kept_end,
        "cut": not scan.data_end, "stop": scan.stop, "not_copied": dict(scan.not_copied),
        "end": custom[CUSTOM_KEYS["end"]], "scene_name": custom.get(CUSTOM_KEYS["scene_name"]),
        "scene_found": CUSTOM_KEYS["scene"] in custom, "version": custom.get(CUSTOM_KEYS["version"]),
    }


def _rebuild(mcap: Path, new: Path, bag: Path, given: Path) -> tuple[_Rebuilt, _Scan, dict]:
    """Write the recovered bag at ``new`` (closed, complete); RecoverError if nothing is recoverable
    or it cannot be written."""
    from rosbags.rosbag2 import WriterError

    try:
        out = _Rebuilt(new)
    except (OSError, WriterError) as exc:
        raise RecoverError(f"{given}: cannot write the recovered bag in {new.parent}: {exc}") from None
    try:
        scan = _copy_records(mcap, out)
        if out.messages == 0:
            raise _Unusable(f"nothing to recover: no whole message in it ({scan.size} bytes; read up to byte "
                            f"{scan.kept_end}: {scan.stop})")
        custom = _custom_data(scan, out, bag, _describe(scan, out, mcap.name))
        for k, v in custom.items():
            out.writer.set_custom_data(k, v)
        out.writer.close()
    except BaseException as exc:
        out.writer.abort()
        if isinstance(exc, _Unusable):
            raise RecoverError(f"{given}: {mcap.name}: {exc}; the bag is left as it was") from None
        if isinstance(exc, (OSError, WriterError)):
            raise RecoverError(f"{given}: cannot write the recovered bag: {exc}; the bag is left as it was") from None
        raise
    return out, scan, custom
