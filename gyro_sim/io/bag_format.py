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

_TYPESTORE = None


def _typestore():
    """The rosbags typestore (ROS 2 Humble definitions; identical hashes in Jazzy for our types)."""
    global _TYPESTORE
    if _TYPESTORE is None:
        from rosbags.typesys import Stores, get_typestore

        _TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)
    return _TYPESTORE
