"""What a gyro_sim bag holds beyond rosbag2's own: the metadata format version, the custom_data keys and the message
typestore, shared by the writer (:mod:`gyro_sim.io.bag_writer`), the reader (:mod:`gyro_sim.io.bag_reader`) and the
repair of a cut recording (:mod:`gyro_sim.io.bag_repair`).
"""
BAG_VERSION = 8  # rosbag2 metadata format version: the newest that ROS 2 Humble reads
_PREFIX = "gyro_sim."
#: custom_data keys written by the recorder
CUSTOM_KEYS = {
    "version": _PREFIX + "version",
    "scene_name": _PREFIX + "scene_name",
    "scene": _PREFIX + "scene",
    "end": _PREFIX + "end",
}

#: name of the MCAP metadata record the recorder writes at the start of the file with its custom_data (all but
#: ``gyro_sim.end``): a recording cut short (kill -9, crash) keeps them for ``gyro-sim bag recover``. Not indexed
#: in the summary (readers of a closed bag see only the ``rosbag2`` record and metadata.yaml).
EARLY_METADATA = "gyro_sim.custom_data"

#: the space reserve a recorder kept in its bag folder before issue 29 (a kill -9 left it there, 4 MiB); today's
#: reserve has no name (gyro_sim.io.bag_writer), and `gyro-sim bag recover` removes an old one
RESERVE_NAME = ".gyro_sim_reserve"

#: where a Chunk record keeps the CRC32 of its uncompressed records: after its opcode (1 byte), its length (8) and
#: its message start time, end time and uncompressed size (8 each)
_CHUNK_CRC_AT = 1 + 8 + 3 * 8


def write_chunk_crcs(storage) -> None:
    """Make rosbags' MCAP storage writer (``Writer(...).storage`` once opened) write each chunk's CRC.

    rosbags writes 0 there, which MCAP readers take as "no CRC": a flipped byte inside a chunk went unnoticed by
    every reader and by ``gyro-sim bag recover``. Each chunk's CRC32 (of its uncompressed records, as the MCAP
    specification says) is computed before the chunk is written and put in its place after: rosbags' reader, the
    ``mcap`` reader and bag_repair check it."""
    import struct
    import zlib

    close_chunk = storage.close_chunk

    def close_with_crc() -> None:
        with storage.chunk.bio.getbuffer() as records:
            crc = zlib.crc32(records)
        start = storage.bio.tell()
        close_chunk()
        end = storage.bio.tell()
        storage.bio.seek(start + _CHUNK_CRC_AT)
        storage.bio.write(struct.pack("<I", crc))
        storage.bio.seek(end)

    storage.close_chunk = close_with_crc


_TYPESTORE = None


def _typestore():
    """The rosbags typestore (ROS 2 Humble definitions; identical hashes in Jazzy for our types)."""
    global _TYPESTORE
    if _TYPESTORE is None:
        from rosbags.typesys import Stores, get_typestore

        _TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)
    return _TYPESTORE


def ros2msg_schema(topic: str) -> tuple[str, str]:
    """(type name, ``ros2msg`` definition text) of a topic's messages, as a bag's MCAP schema record holds them
    (rosbags' writer: the type's .msg text followed by its dependencies') and as the live view advertises them."""
    from gyro_sim.io.messages import TOPICS

    msgtype = TOPICS[topic]
    return msgtype, _typestore().generate_msgdef(msgtype, ros_version=2)[0]


def cdr_message(topic: str, fields: dict) -> memoryview:
    """A topic's message, given as a builder's dict (:mod:`gyro_sim.io.messages`), serialized as CDR (little
    endian, with its 4-byte encapsulation header), byte for byte as a bag stores it and the live view sends it."""
    from gyro_sim.io.messages import TOPICS, to_rosbags

    msgtype = TOPICS[topic]
    ts = _typestore()
    return ts.serialize_cdr(to_rosbags(ts, msgtype, fields), msgtype)
