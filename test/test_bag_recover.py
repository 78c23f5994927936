"""`gyro-sim bag recover`: a recording cut by kill -9, a crash or a power loss, rebuilt into a complete bag.

A complete bag is recorded (a real run, several 1 MiB chunks), then crashes are simulated: metadata.yaml
deleted and the MCAP file truncated at many offsets (landmarks of its layout, and hypothesis over the
offset), a chunk damaged in the middle, and a real ``kill -9`` of a recording process. What is expected
is computed from the complete file with the ``mcap`` library alone (its summary's chunk indexes and its
chunk parser): every message of every chunk that lies wholly before the cut. The recovered bag is read
back by rosbags and by the independent ``mcap`` reader (and ``mcap_ros2``'s decoder), against that.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import textwrap
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Chunk, Footer, Message
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader

import gyro_sim
import gyro_sim.io.messages
from gyro_sim.apps import cli
from gyro_sim.io.bag_repair import NOT_CLOSED, RecoverError, mcap_closed, not_closed, recover_bag
from gyro_sim.io.recording import read_bag, record_result, scene_text

SCENE = "spinup_thin_shell"


# --- the complete bag and its layout, by the mcap library ---------------------------------------------

def mcap_of(bag: Path) -> Path:
    files = sorted(bag.glob("*.mcap"))
    assert len(files) == 1, files
    return files[0]


def layout(path: Path) -> dict:
    """Offsets of a complete MCAP file and its chunks' messages, from its summary (mcap library only)."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
        topics = {cid: ch.topic for cid, ch in summary.channels.items()}
        chunks = []
        for ci in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
            f.seek(ci.chunk_start_offset + 9)
            chunk = Chunk.read(ReadDataStream(f))
            msgs = [(topics[r.channel_id], r.log_time, bytes(r.data))
                    for r in breakup_chunk(chunk, validate_crc=True) if isinstance(r, Message)]
            chunks.append({"start": ci.chunk_start_offset, "end": ci.chunk_start_offset + ci.chunk_length,
                           "messages": msgs})
        meta = summary.metadata_indexes[0] if summary.metadata_indexes else None
        f.seek(size - 37 + 9)
        footer = Footer.read(ReadDataStream(f))
        f.seek(8)
        op, length = struct.unpack("<BQ", f.read(9))
    assert op == 0x01
    # (the recorder's EARLY_METADATA record sits between the header and the first chunk)
    return {"size": size, "header_end": 8 + 9 + length, "chunks": chunks, "early_end": chunks[0]["start"],
            "metadata": (meta.offset, meta.offset + meta.length) if meta else None,
            "data_end": meta.offset + meta.length if meta else None,
            "summary_start": footer.summary_start, "footer_start": size - 37,
            "schemas": {s.name: (s.encoding, bytes(s.data)) for s in summary.schemas.values()}}


def expected_messages(lay: dict, cut: int) -> list:
    """Every message of every chunk that ends at or before byte ``cut``, in file order."""
    return [m for c in lay["chunks"] if c["end"] <= cut for m in c["messages"]]


@pytest.fixture(scope="module")
def complete(tmp_path_factory):
    """A real run recorded by gyro_sim: 60 s of spinup_thin_shell (controller commands included), 4 chunks."""
    d = tmp_path_factory.mktemp("complete")
    scene = gyro_sim.load_scene(SCENE)
    bag = record_result(gyro_sim.run(scene, duration=60.0), d / "run")
    lay = layout(mcap_of(bag))
    assert len(lay["chunks"]) >= 3, "the bag should span several chunks"
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return {"bag": bag, "layout": lay, "meta": meta, "scene_text": scene_text(scene),
            "bytes": mcap_of(bag).read_bytes()}


def crashed_copy(complete, where: Path, cut: int, keep_yaml: bool = False) -> Path:
    """A copy of the complete bag as a crash leaves it: no metadata.yaml, the MCAP file cut at byte ``cut``."""
    bag = where / "run"
    bag.mkdir()
    (bag / "run.mcap").write_bytes(complete["bytes"][:cut])
    if keep_yaml:
        shutil.copy(complete["bag"] / "metadata.yaml", bag / "metadata.yaml")
    return bag


def snapshot(d: Path) -> dict:
    """Every path under d (d included in its parent's listing) → sha256 of its bytes (None for directories)."""
    return {str(p.relative_to(d.parent)): (hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else None)
            for p in [d, *sorted(d.rglob("*"))]}


# --- checking a recovered bag ------------------------------------------------------------------------

def mcap_messages(bag: Path) -> list:
    """(topic, log_time, bytes) in file order, by the mcap library's reader (its summary and indexes)."""
    with open(mcap_of(bag), "rb") as f:
        return [(ch.topic, m.log_time, bytes(m.data))
                for _, ch, m in make_reader(f).iter_messages(log_time_order=False)]


def rosbags_messages(bag: Path) -> list:
    with Reader(bag) as r:
        return [(c.topic, t, bytes(raw)) for c, t, raw in r.messages()]


def check_recovered(complete, bag: Path, want: list, cut: int, rep: dict) -> dict:
    """The recovered bag holds exactly ``want`` (read by both readers), metadata.yaml agrees, the
    custom_data says what happened, the damaged original is kept byte for byte, no temp leftovers."""
    lay, orig = complete["layout"], complete["meta"]
    assert rep["messages"] == len(want)
    assert rep["kept_bytes"] + rep["dropped_bytes"] == cut
    assert mcap_messages(bag) == want  # file order: every message of every whole chunk, in order
    assert rosbags_messages(bag) == sorted(want, key=lambda m: m[1])  # rosbags: log-time order (stable)
    assert mcap_closed(mcap_of(bag)) and not_closed(bag) is None
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 8 and meta["storage_identifier"] == "mcap"
    assert meta["message_count"] == len(want)
    counts = Counter(t for t, _, _ in want)
    topics = {x["topic_metadata"]["name"]: x for x in meta["topics_with_message_count"]}
    orig_topics = {x["topic_metadata"]["name"]: x for x in orig["topics_with_message_count"]}
    assert set(topics) == set(orig_topics)  # every channel, also those without a message
    for name, x in topics.items():
        assert x["message_count"] == counts.get(name, 0), name
        assert x["topic_metadata"] == orig_topics[name]["topic_metadata"], name  # type, QoS, hash, format
    with open(mcap_of(bag), "rb") as f:
        s = make_reader(f).get_summary()
    assert s.statistics.message_count == len(want)
    assert {x.name: (x.encoding, bytes(x.data)) for x in s.schemas.values()} == lay["schemas"]
    custom = meta["custom_data"]
    assert custom["gyro_sim.scene"] == complete["scene_text"]
    assert custom["gyro_sim.scene_name"] == SCENE
    if cut >= lay["data_end"] + 13:  # DataEnd read: the data section was whole
        assert custom["gyro_sim.end"].startswith("complete; recovered by gyro-sim bag recover ("), custom
        assert not rep["cut"]
    else:
        assert custom["gyro_sim.end"].startswith("interrupted: recovered by gyro-sim bag recover ("), custom
        assert "the recording was cut" in custom["gyro_sim.end"]
        assert f"the last {cut - rep['kept_bytes']} of {cut} bytes" in custom["gyro_sim.end"]
    if cut >= lay["metadata"][1]:  # the rosbag2 record was written: all of the original custom_data is known
        assert {k: v for k, v in custom.items() if k != "gyro_sim.end"} == {
            k: v for k, v in orig["custom_data"].items() if k != "gyro_sim.end"}
    elif cut >= lay["early_end"]:  # the recorder's start-of-run record: all but what is known at close
        late = ("gyro_sim.end", "gyro_sim.duration")
        assert {k: v for k, v in custom.items() if k not in late} == {
            k: v for k, v in orig["custom_data"].items() if k not in late}
    else:
        assert "gyro_sim.version" not in custom
    damaged = bag / "run.mcap.damaged"
    assert damaged.read_bytes() == complete["bytes"][:cut]
    assert sorted(p.name for p in bag.iterdir()) == ["metadata.yaml", "run.mcap", "run.mcap.damaged"]
    assert [p.name for p in bag.parent.iterdir()] == ["run"]  # no temporary directory left
    return custom


def landmark(lay: dict, name: str) -> int:
    c0, c1 = lay["chunks"][0], lay["chunks"][1]
    return {
        "inside_magic": 5,
        "inside_header": lay["header_end"] - 3,
        "after_header": lay["header_end"],
        "inside_first_chunk": c0["start"] + 1000,
        "first_chunk_header_cut": c0["start"] + 5,
        "at_chunk_boundary": c0["end"],
        "inside_message_indexes": c0["end"] + 20,
        "next_chunk_start": c1["start"],
        "inside_second_chunk": c1["start"] + (c1["end"] - c1["start"]) // 2,
        "after_last_chunk": lay["chunks"][-1]["end"],
        "inside_metadata_record": lay["metadata"][0] + 40,
        "after_metadata_record": lay["metadata"][1],
        "after_data_end": lay["data_end"] + 13,
        "inside_summary": lay["summary_start"] + 100,
        "just_before_footer": lay["footer_start"],
        "inside_footer": lay["footer_start"] + 20,
        "last_byte_missing": lay["size"] - 1,
    }[name]


LANDMARKS = ["inside_magic", "inside_header", "after_header", "first_chunk_header_cut", "inside_first_chunk",
             "at_chunk_boundary", "inside_message_indexes", "next_chunk_start", "inside_second_chunk",
             "after_last_chunk", "inside_metadata_record", "after_metadata_record", "after_data_end",
             "inside_summary", "just_before_footer", "inside_footer", "last_byte_missing"]


def recover_and_check(complete, where: Path, cut: int) -> None:
    bag = crashed_copy(complete, where, cut)
    want = expected_messages(complete["layout"], cut)
    if not want:  # cut before the first chunk was whole: refused, the bag left as it was
        before = snapshot(bag)
        with pytest.raises(RecoverError, match=r"^.*run: run\.mcap: .*the bag is left as it was$"):
            recover_bag(bag)
        assert snapshot(bag) == before
        assert [p.name for p in where.iterdir()] == ["run"]
        return
    rep = recover_bag(bag)
    check_recovered(complete, bag, want, cut, rep)


@pytest.mark.parametrize("where", LANDMARKS)
def test_truncated_at_landmarks(complete, tmp_path, where):
    recover_and_check(complete, tmp_path, landmark(complete["layout"], where))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(frac=st.floats(min_value=0.0, max_value=1.0, exclude_max=True))
def test_truncated_anywhere(complete, frac):
    cut = int(frac * complete["layout"]["size"])
    with tempfile.TemporaryDirectory() as d:
        recover_and_check(complete, Path(d), cut)


def test_only_metadata_yaml_missing(complete, tmp_path):
    """A crash between the MCAP file's close and metadata.yaml: the data is all there; the recorded end is kept."""
    bag = crashed_copy(complete, tmp_path, complete["layout"]["size"])
    assert not_closed(bag) == bag
    rep = recover_bag(bag)
    all_msgs = expected_messages(complete["layout"], complete["layout"]["size"])
    custom = check_recovered(complete, bag, all_msgs, complete["layout"]["size"], rep)
    assert custom["gyro_sim.end"].startswith(complete["meta"]["custom_data"]["gyro_sim.end"] + "; recovered")


def test_metadata_yaml_present_but_mcap_cut(complete, tmp_path, capsys):
    """A metadata.yaml written early (not closed yet) with a cut MCAP file: readers say so; recover keeps
    the old metadata.yaml as metadata.yaml.damaged."""
    lay = complete["layout"]
    cut = lay["chunks"][1]["end"] + 7
    bag = crashed_copy(complete, tmp_path, cut, keep_yaml=True)
    old_yaml = (bag / "metadata.yaml").read_bytes()
    assert cli.main(["info", str(bag)]) == 2
    assert capsys.readouterr().err == "error: " + NOT_CLOSED.format(bag=bag) + "\n"
    rep = recover_bag(bag)
    assert rep["set_aside"] == {"run.mcap": str(bag / "run.mcap.damaged"),
                                "metadata.yaml": str(bag / "metadata.yaml.damaged")}
    assert (bag / "metadata.yaml.damaged").read_bytes() == old_yaml
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == len(expected_messages(lay, cut))
    # the early metadata.yaml's custom_data is used (version, duration, ...), the end is the recovery's
    assert meta["custom_data"]["gyro_sim.version"] == complete["meta"]["custom_data"]["gyro_sim.version"]
    assert meta["custom_data"]["gyro_sim.end"].startswith("interrupted: recovered")


@pytest.mark.parametrize("damage", ["inner_opcode", "size_field", "time_range"])
def test_damaged_chunk_in_the_middle_is_skipped(complete, tmp_path, damage):
    """A whole chunk that fails its checks (a record inside that is not an MCAP record; an uncompressed
    size that disagrees with its data; messages outside its time range) is skipped; the chunks after it
    are kept."""
    lay = complete["layout"]
    data = bytearray(complete["bytes"])
    bad = lay["chunks"][1]
    if damage == "inner_opcode":
        data[bad["start"] + 9 + 40] = 0x00  # its first inner record's opcode
    elif damage == "size_field":
        data[bad["start"] + 9 + 16] ^= 0x01  # its uncompressed_size field
    else:  # its message_end_time := its message_start_time
        s = bad["start"] + 9
        data[s + 8:s + 16] = data[s:s + 8]
    bag = tmp_path / "run"
    bag.mkdir()
    (bag / "run.mcap").write_bytes(bytes(data[:lay["footer_start"]]))  # cut just before the footer
    rep = recover_bag(bag)
    want = [m for c in lay["chunks"] if c is not bad for m in c["messages"]]
    assert len(rep["bad_chunks"]) == 1 and f"at byte {bad['start']}" in rep["bad_chunks"][0]
    assert mcap_messages(bag) == want
    assert rosbags_messages(bag) == sorted(want, key=lambda m: m[1])
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == len(want)
    assert "1 damaged chunk(s) skipped" in meta["custom_data"]["gyro_sim.end"]


def test_garbage_after_the_cut_stops_cleanly(complete, tmp_path):
    """Zeros after the last whole chunk (a file system that extended the file but lost the data)."""
    lay = complete["layout"]
    cut = lay["chunks"][1]["end"]
    bag = tmp_path / "run"
    bag.mkdir()
    (bag / "run.mcap").write_bytes(complete["bytes"][:cut] + bytes(4096))
    rep = recover_bag(bag)
    assert rep["kept_bytes"] == cut and rep["dropped_bytes"] == 4096
    assert "not an MCAP record (opcode 0x00)" in rep["stop"]
    assert mcap_messages(bag) == expected_messages(lay, cut)


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_compressed_chunks_with_crcs_from_another_writer(complete, tmp_path, compression):
    """The same messages written by the mcap library's writer (compressed 256 KiB chunks with CRCs): one
    chunk's compressed bytes damaged (its CRC or its decompression fails: skipped), the file cut later."""
    from mcap.writer import CompressionType, Writer

    bag = tmp_path / "run"
    bag.mkdir()
    path = bag / "run.mcap"
    with open(mcap_of(complete["bag"]), "rb") as f, open(path, "wb") as out:
        reader = make_reader(f)
        summary = reader.get_summary()
        w = Writer(out, chunk_size=256 * 1024, compression=CompressionType[compression.upper()], enable_crcs=True)
        w.start(profile="ros2", library="another writer")
        sid = {i: w.register_schema(s.name, s.encoding, s.data) for i, s in summary.schemas.items()}
        cid = {i: w.register_channel(c.topic, c.message_encoding, sid[c.schema_id], c.metadata)
               for i, c in summary.channels.items()}
        for _, ch, m in reader.iter_messages(log_time_order=False):
            w.add_message(cid[ch.id], m.log_time, m.data, m.publish_time)
        w.finish()
    lay = layout(path)
    assert len(lay["chunks"]) >= 6
    bad, cut = lay["chunks"][2], lay["chunks"][5]["start"] + 77
    data = bytearray(path.read_bytes()[:cut])
    data[bad["start"] + 9 + 32 + len(compression) + 8 + 100] ^= 0xFF  # inside its compressed records
    path.write_bytes(bytes(data))
    rep = recover_bag(bag)
    want = [m for c in lay["chunks"][:5] if c is not bad for m in c["messages"]]
    assert len(rep["bad_chunks"]) == 1, rep["bad_chunks"]
    assert ("its CRC does not match" in rep["bad_chunks"][0]) or ("cannot decompress it" in rep["bad_chunks"][0])
    assert mcap_messages(bag) == want
    assert rosbags_messages(bag) == sorted(want, key=lambda m: m[1])
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    orig = {x["topic_metadata"]["name"]: x["topic_metadata"] for x in complete["meta"]["topics_with_message_count"]}
    assert {x["topic_metadata"]["name"]: x["topic_metadata"] for x in meta["topics_with_message_count"]} == orig
    assert meta["custom_data"]["gyro_sim.scene"] == complete["scene_text"]


def test_bag_directory_renamed_since_it_was_recorded(complete, tmp_path):
    """BAG/old.mcap in a directory now called BAG: the recovered file is BAG/BAG.mcap, old.mcap is set aside."""
    lay = complete["layout"]
    cut = lay["chunks"][1]["end"]
    crashed_copy(complete, tmp_path, cut)
    bag = tmp_path / "renamed"
    (tmp_path / "run").rename(bag)
    rep = recover_bag(bag)
    assert sorted(p.name for p in bag.iterdir()) == ["metadata.yaml", "renamed.mcap", "run.mcap.damaged"]
    assert rep["set_aside"] == {"run.mcap": str(bag / "run.mcap.damaged")}
    assert (bag / "run.mcap.damaged").read_bytes() == complete["bytes"][:cut]
    assert rosbags_messages(bag) == sorted(expected_messages(lay, cut), key=lambda m: m[1])
    assert [p.name for p in tmp_path.iterdir()] == ["renamed"]


def test_the_bag_file_exists_at_every_instant(complete, tmp_path, monkeypatch):
    """While the recovered file is put in place, BAG/run.mcap always exists (the old one, then the new one)."""
    from gyro_sim.io import bag_repair

    bag = crashed_copy(complete, tmp_path, complete["layout"]["chunks"][1]["end"])
    seen = []
    real_replace, real_rename = os.replace, os.rename

    def watch(real):
        def f(src, dst):
            seen.append((Path(dst).name, (bag / "run.mcap").exists()))
            return real(src, dst)
        return f
    monkeypatch.setattr(bag_repair.os, "replace", watch(real_replace))
    monkeypatch.setattr(bag_repair.os, "rename", watch(real_rename))
    recover_bag(bag)
    assert ("run.mcap", True) in seen and all(there for _, there in seen), seen


def test_without_hard_links_the_original_is_renamed(complete, tmp_path, monkeypatch):
    """A file system without hard links: the damaged original is renamed aside instead (same result)."""
    from gyro_sim.io import bag_repair

    def no_link(src, dst):
        raise OSError(1, "Operation not permitted (simulated: no hard links here)")
    monkeypatch.setattr(bag_repair.os, "link", no_link)
    lay = complete["layout"]
    cut = lay["chunks"][1]["end"] + 1
    bag = crashed_copy(complete, tmp_path, cut)
    recover_bag(bag)
    assert sorted(p.name for p in bag.iterdir()) == ["metadata.yaml", "run.mcap", "run.mcap.damaged"]
    assert (bag / "run.mcap.damaged").read_bytes() == complete["bytes"][:cut]
    assert mcap_messages(bag) == expected_messages(lay, cut)


def test_a_bag_still_being_recorded_is_refused(complete, tmp_path, capsys):
    """A recorder holding an exclusive flock on its file (still writing it): recover changes nothing."""
    fcntl = pytest.importorskip("fcntl")
    bag = crashed_copy(complete, tmp_path, complete["layout"]["chunks"][1]["end"])
    before = snapshot(bag)
    with open(bag / "run.mcap", "rb+") as live:
        fcntl.flock(live.fileno(), fcntl.LOCK_EX)
        assert cli.main(["bag", "recover", str(bag)]) == 2
    assert capsys.readouterr().err == (f"error: {bag}: run.mcap is locked by a process that is still recording it; "
                                       "recover it once that recording has ended (nothing was changed)\n")
    assert snapshot(bag) == before
    assert cli.main(["bag", "recover", str(bag)]) == 0  # once it is released


# --- the readers and the command ---------------------------------------------------------------------

def test_readers_name_a_crashed_bag_and_the_command(complete, tmp_path, capsys):
    lay = complete["layout"]
    bag = crashed_copy(complete, tmp_path, lay["chunks"][2]["start"] + 500)
    line = "error: " + NOT_CLOSED.format(bag=bag) + "\n"
    for argv in (["info", str(bag)], ["plot", str(bag)], ["replay", "--check", str(bag)]):
        assert cli.main(argv) == 2, argv
        assert capsys.readouterr().err == line, argv
    assert cli._summarise_bag(bag, tmp_path / "x.png") == 2  # the summary after `run --ros`
    assert capsys.readouterr().err == line
    # the .mcap file given instead of the directory: the suggestion names the directory
    assert cli.main(["info", str(bag / "run.mcap")]) == 2
    assert capsys.readouterr().err == "error: " + NOT_CLOSED.format(bag=bag) + "\n"
    # a bag that is not there is still an ordinary error
    assert cli.main(["info", str(tmp_path / "nope")]) == 2
    assert "cannot read the bag" in capsys.readouterr().err


def test_recover_command_then_info_and_plot(complete, tmp_path, capsys):
    lay = complete["layout"]
    cut = lay["chunks"][2]["start"] + 500
    bag = crashed_copy(complete, tmp_path, cut)
    want = expected_messages(lay, cut)
    assert cli.main(["bag", "recover", str(bag)]) == 0
    out = capsys.readouterr().out
    t0, t1 = want[0][1] / 1e9, want[-1][1] / 1e9
    assert out.startswith(f"recovered {bag}: {len(want)} messages on ")
    assert f"t = {t0:.6g} to {t1:.6g} s" in out
    assert f"dropped   the last 500 of {cut} bytes: a Chunk record cut after 491 of " in out
    assert f"kept      the damaged run.mcap as {bag / 'run.mcap.damaged'}" in out
    assert f"scene     {SCENE}\n" in out
    # info and plot read it
    assert cli.main(["info", str(bag)]) == 0
    info = capsys.readouterr().out
    assert f"messages          {len(want)}\n" in info and "interrupted: recovered by gyro-sim bag recover" in info
    assert f"scene             {SCENE}" in info
    png = tmp_path / "p.png"
    assert cli.main(["plot", str(bag), "--out", str(png)]) == 0
    assert png.stat().st_size > 0
    # read_bag: the samples of the whole chunks, the scene from the /gyro/scene message
    d = read_bag(bag)
    assert d.scene_text == complete["scene_text"] and d.scene_name == SCENE
    assert d.custom["gyro_sim.end"].startswith("interrupted: recovered")
    # the independent decoder reads the scene message
    with open(mcap_of(bag), "rb") as f:
        scenes = [dec.data for _, ch, _, dec in make_reader(f, decoder_factories=[DecoderFactory()])
                  .iter_decoded_messages(topics=["/gyro/scene"])]
    assert scenes == [complete["scene_text"]]
    # recovered once: a second recover refuses, and leaves it alone
    before = snapshot(bag)
    assert cli.main(["bag", "recover", str(bag)]) == 2
    err = capsys.readouterr().err
    assert err == (f"error: {bag}: nothing to recover: the bag is complete "
                   "(run.mcap is closed and metadata.yaml is there)\n")
    assert snapshot(bag) == before


def test_recovered_run_re_simulates_bit_for_bit(complete, tmp_path, capsys):
    """`gyro-sim replay --check` on a recovered real run (cut after a chunk that ends on a whole sample):
    the embedded scene and the recorded commands give the recorded states to the bit."""
    lay = complete["layout"]

    def ends_on_a_whole_sample(cut):
        msgs = expected_messages(lay, cut)
        return set(gyro_sim.io.messages.STATE_TOPICS) <= {t for t, ns, _ in msgs if ns == msgs[-1][1]}
    # (the recorder writes its first chunk out with the first sample, at t = 0: a chunk after it)
    whole = [c["end"] for c in lay["chunks"][:-1]
             if ends_on_a_whole_sample(c["end"]) and expected_messages(lay, c["end"])[-1][1] > 0]
    assert whole, "no chunk of the fixture ends on a whole sample"
    bag = crashed_copy(complete, tmp_path, whole[0] + 100)
    assert cli.main(["replay", "--check", str(bag)]) == 2
    assert "was not closed" in capsys.readouterr().err
    assert cli.main(["bag", "recover", str(bag)]) == 0
    capsys.readouterr()
    assert cli.main(["replay", "--check", str(bag)]) == 0
    assert "identical to the bit" in capsys.readouterr().out


def test_recover_refuses_a_complete_bag(complete, tmp_path, capsys):
    bag = tmp_path / "run"
    shutil.copytree(complete["bag"], bag)
    before = snapshot(bag)
    assert cli.main(["bag", "recover", str(bag)]) == 2
    assert capsys.readouterr().err.startswith(f"error: {bag}: nothing to recover: the bag is complete")
    assert snapshot(bag) == before and [p.name for p in tmp_path.iterdir()] == ["run"]


@pytest.mark.parametrize("case", ["missing", "file", "mcap_file", "empty_dir", "two_mcaps", "not_mcap",
                                  "empty_mcap"])
def test_recover_refuses_what_is_not_a_cut_bag(tmp_path, capsys, case):
    bag = tmp_path / "bag"
    expect = {
        "missing": "no such bag directory",
        "file": "not a bag directory",
        "mcap_file": f"not a bag directory (a bag is the directory that holds the .mcap file): give its "
                     f"directory, {bag}",
        "empty_dir": "not a bag: no .mcap file in it",
        "two_mcaps": "holds 2 .mcap files (a.mcap, b.mcap)",
        "not_mcap": "bag.mcap: not an MCAP file (no MCAP magic at its start); the bag is left as it was",
        "empty_mcap": "bag.mcap: the file holds only 0 bytes: the recording ended before anything was written to it",
    }[case]
    target = bag
    if case == "file":
        bag.write_text("x")
    elif case != "missing":
        bag.mkdir()
    if case == "mcap_file":
        target = bag / "bag.mcap"
        target.write_bytes(b"\x89MCAP0\r\n")
    elif case == "two_mcaps":
        (bag / "a.mcap").write_bytes(b"")
        (bag / "b.mcap").write_bytes(b"")
    elif case == "not_mcap":
        (bag / "bag.mcap").write_bytes(b"PK\x03\x04 not an mcap file at all")
    elif case == "empty_mcap":
        (bag / "bag.mcap").write_bytes(b"")
    before = sorted(p.name for p in tmp_path.rglob("*"))
    assert cli.main(["bag", "recover", str(target)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {target}: ") and err.count("\n") == 1, err
    assert expect in err
    assert sorted(p.name for p in tmp_path.rglob("*")) == before  # nothing made, nothing left


def test_bag_command_needs_a_tool(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["bag"])
    assert exc.value.code == 2
    with pytest.raises(SystemExit) as exc:
        cli.main(["bag", "recover", "--help"])
    assert exc.value.code == 0
    assert ".damaged" in capsys.readouterr().out


# --- failures leave the bag as it was and no temporary directory ------------------------------------

@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0,
                    reason="running as root: a read-only directory is still writable (chmod has no effect)")
def test_read_only_parent_leaves_everything(complete, tmp_path, capsys):
    bag = crashed_copy(complete, tmp_path, complete["layout"]["chunks"][1]["end"])
    before = snapshot(bag)
    tmp_path.chmod(0o555)
    try:
        assert cli.main(["bag", "recover", str(bag)]) == 2
        assert "cannot make a temporary directory next to it" in capsys.readouterr().err
        assert snapshot(bag) == before and [p.name for p in tmp_path.iterdir()] == ["run"]
    finally:
        tmp_path.chmod(0o755)


@pytest.mark.parametrize("step", ["verify", "install_mcap", "install_yaml"])
def test_a_failure_at_any_step_leaves_the_bag_as_it_was(complete, tmp_path, monkeypatch, capsys, step):
    """A failure while checking the new bag or while putting it in place: every move undone, no temp left."""
    from gyro_sim.io import bag_repair

    bag = crashed_copy(complete, tmp_path, complete["layout"]["chunks"][1]["end"] + 3, keep_yaml=True)
    (bag / "metadata.yaml").write_text("an early, half-written metadata.yaml\n")
    before = snapshot(bag)
    if step == "verify":
        def broken(path, out):
            raise bag_repair._Unusable("the rebuilt bag does not read back: simulated")
        monkeypatch.setattr(bag_repair, "_verify", broken)
    else:
        real = os.replace
        fail_on = "run.mcap" if step == "install_mcap" else "metadata.yaml"

        def replace(src, dst):
            if Path(dst).name == fail_on and Path(dst).parent == bag.resolve() and ".recover-" in str(src):
                raise OSError(28, "No space left on device (simulated)")
            return real(src, dst)
        monkeypatch.setattr(bag_repair.os, "replace", replace)
    assert cli.main(["bag", "recover", str(bag)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {bag}: ") and err.rstrip().endswith("the bag is left as it was"), err
    assert snapshot(bag) == before
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


# --- a real kill -9 ------------------------------------------------------------------------------------

CHILD = """
import sys
from gyro_sim.io.recording import BagRecorder
names = ["z1", "z2", "z3"]
with BagRecorder(sys.argv[1], "name: killed\\nx: 1\\n", "killed") as rec:
    i = 0
    while True:
        t = i * 1e-3
        v = [float(i), 2.0 * i, -1.0 * i]
        rec.write_sample(t, v, [1.0, 0.0, 0.0, 0.0], v, v, v, names, v, v, v)
        i += 1
        if i % 200 == 0:
            print(i, flush=True)
"""


def whole_chunk_messages(path: Path) -> int:
    """Messages in the whole chunks of a cut MCAP file, by the mcap stream reader (stopped at the cut)."""
    n = 0
    with open(path, "rb") as f:
        try:
            for rec in StreamReader(f, emit_chunks=True).records:
                if isinstance(rec, Chunk) and len(rec.data) == rec.uncompressed_size:  # (uncompressed chunks)
                    n += sum(isinstance(r, Message) for r in breakup_chunk(rec))
        except Exception:  # the cut tail
            pass
    return n


def test_kill_9_mid_recording(tmp_path, capsys):
    bag = tmp_path / "killed"
    script = tmp_path / "child.py"
    script.write_text(textwrap.dedent(CHILD))
    proc = subprocess.Popen([sys.executable, str(script), str(bag)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        mcap = bag / "killed.mcap"
        while not (mcap.exists() and mcap.stat().st_size > int(2.5 * 2**20)):  # two chunks or more
            assert proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < deadline, "the child wrote too little"
            time.sleep(0.05)
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert not (bag / "metadata.yaml").exists() and not mcap_closed(mcap)
    damaged = mcap.read_bytes()
    n_whole = whole_chunk_messages(mcap)
    assert n_whole > 0
    assert cli.main(["info", str(bag)]) == 2
    assert capsys.readouterr().err == "error: " + NOT_CLOSED.format(bag=bag) + "\n"
    assert cli.main(["bag", "recover", str(bag)]) == 0
    capsys.readouterr()
    assert (bag / "killed.mcap.damaged").read_bytes() == damaged
    d = read_bag(bag)
    msgs = mcap_messages(bag)
    assert len(msgs) == n_whole == len(rosbags_messages(bag))
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == n_whole
    # the samples 0, 1, 2, ... with their values, none missing before the cut (the last one may be partial)
    n = len(d)
    assert n > 0 and (d.t_ns == np.arange(n) * 1_000_000).all()
    i = np.arange(n - 1, dtype=float)
    assert (d.L[:n - 1, 0] == i).all() and (d.L[:n - 1, 1] == 2 * i).all() and (d.L[:n - 1, 2] == -i).all()
    assert d.scene_text == "name: killed\nx: 1\n" and d.scene_name == "killed"
    assert d.custom["gyro_sim.end"].startswith("interrupted: recovered")
    assert cli.main(["info", str(bag)]) == 0
