"""MCAP writer and salvaging reader: every complete chunk survives a cut anywhere in the file."""
from __future__ import annotations

import json

import pytest
from mcap.reader import make_reader

from ground_station.contract import Out
from ground_station.mcap_io import McapLogWriter, NotAnMcapError, read_log

TOPICS = ("/am/4/controller", "/sim/object/state")


def _outs(n: int):
    for i in range(n):
        topic = TOPICS[i % 2]
        schema = "amstack.ControllerState" if i % 2 == 0 else "amstack.ObjectTruth"
        yield Out(topic, schema, i * 1_000_000, json.dumps({"t": i * 1e-3, "seq": i // 2, "pad": "x" * 50}).encode())


def _write(path, n=2000, flush_every=150, compression="zstd", chunk_size=4096):
    w = McapLogWriter(path, compression=compression, chunk_size=chunk_size)
    w.open()
    for i, o in enumerate(_outs(n)):
        w.write(o)
        if flush_every and i % flush_every == flush_every - 1:
            w.flush()
    w.close()
    return list(_outs(n))


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_round_trip(tmp_path, compression):
    p = tmp_path / "a.mcap"
    outs = _write(p, compression=compression)
    log = read_log(p)
    assert not log.truncated and log.error == ""
    for topic in TOPICS:
        assert log.messages[topic] == [(o.log_time_ns, o.data) for o in outs if o.topic == topic]
    assert log.channels[TOPICS[0]] == "amstack.ControllerState" and "amstack.ObjectTruth" in log.schemas
    with open(p, "rb") as f:  # a standard reader agrees (summary, indexes, compression)
        assert sum(1 for _ in make_reader(f).iter_messages()) == len(outs)


def test_every_cut_keeps_every_complete_chunk(tmp_path):
    p = tmp_path / "a.mcap"
    outs = _write(p, n=1200, flush_every=100)
    full = p.read_bytes()
    with open(p, "rb") as f:
        summary = make_reader(f).get_summary()
    chunk_ends = sorted((ci.chunk_start_offset + ci.chunk_length, ci.message_start_time, ci.message_end_time)
                        for ci in summary.chunk_indexes)
    assert len(chunk_ends) > 10
    all_msgs = [(o.log_time_ns, o.topic) for o in outs]
    cuts = sorted(set(range(0, len(full), max(1, len(full) // 97))) | {e for e, _, _ in chunk_ends} | {len(full) - 1})
    for cut in cuts:
        q = tmp_path / "cut.mcap"
        q.write_bytes(full[:cut])
        if cut < 8:
            with pytest.raises(NotAnMcapError):
                read_log(q)
            continue
        log = read_log(q)
        assert log.truncated
        got = sorted((ns, topic) for topic, msgs in log.messages.items() for ns, _ in msgs)
        complete = [e for e in chunk_ends if e[0] <= cut]
        expected_until = complete[-1][2] if complete else -1
        # exactly the messages of the complete chunks: a prefix of the run
        assert got == [m for m in all_msgs if m[0] <= expected_until], cut


def test_flushed_messages_are_on_disk_while_writing(tmp_path):
    """What a SIGKILL right after a flush leaves behind: everything up to the flush."""
    p = tmp_path / "live.mcap"
    w = McapLogWriter(p, chunk_size=1 << 30)  # only flush() closes chunks
    w.open()
    outs = list(_outs(500))
    for o in outs[:300]:
        w.write(o)
    w.flush()
    for o in outs[300:]:
        w.write(o)  # not flushed
    log = read_log(p)
    assert log.truncated and log.message_count == 300
    w.close()
    assert read_log(p).message_count == 500


def test_not_an_mcap_and_missing(tmp_path):
    bad = tmp_path / "notes.mcap"
    bad.write_text("these are not the logs you are looking for\n" * 10)
    with pytest.raises(NotAnMcapError):
        read_log(bad)
    with pytest.raises(FileNotFoundError):
        read_log(tmp_path / "nope.mcap")


def test_recorder_summary_counts_every_message_and_the_bytes_before_it(tmp_path):
    """The log's recorder_summary metadata: `written` is every message in the file (the final
    /recorder/stats included) and `bytes` the file up to the summary, not 0."""
    import time

    from ground_station.recorder import Recorder
    from telemetry import schema
    from telemetry.session import ZenohOptions

    rec = Recorder(tmp_path / "r.mcap", ZenohOptions(role="recorder"))
    rec.writer.open()  # no zenoh session: samples go straight into the inbox
    rec._t0 = time.monotonic()
    for seq in range(50):
        raw = schema.encode({"t": seq * 0.01, "seq": seq, "p_WO": [0.0, 0.0, 0.6], "q_WO": [1.0, 0.0, 0.0, 0.0],
                             "v_WO": [0.0, 0.0, 0.0]})[0]
        rec._inbox.append((rec.keys.object, raw))
    rec._drain()
    final = rec.close()
    log = read_log(tmp_path / "r.mcap")
    meta = log.metadata["recorder_summary"]
    assert int(meta["written"]) == log.message_count == final.written
    assert 0 < int(meta["bytes"]) < final.bytes == (tmp_path / "r.mcap").stat().st_size


def test_binary_channels_decode_with_the_stored_schema_in_a_ros1_reader(capture, tmp_path):
    """What Foxglove does with the log, done by the ROS 1 reference implementation (genpy, as
    mcap-ros1-support ships it): every ros1 channel decodes with the .msg text stored in the
    file alone, to the values our reader gives."""
    ros1 = pytest.importorskip("mcap_ros1.decoder", reason="mcap-ros1-support (test extra) not installed")
    from .conftest import write_mcap

    p = tmp_path / "run.mcap"
    write_mcap(p, capture.samples)
    ours = read_log(p)
    ros1_topics = {t for t, e in ours.encodings.items() if e == "ros1"}
    assert len(ros1_topics) == 7  # the two controllers, contacts and truths, the object state
    seen: dict[str, int] = {}
    with open(p, "rb") as f:
        for schema, channel, message, msg in make_reader(f, decoder_factories=[ros1.DecoderFactory()]) \
                .iter_decoded_messages(topics=sorted(ros1_topics)):
            assert (schema.encoding, channel.message_encoding) == ("ros1msg", "ros1")
            i = seen[channel.topic] = seen.get(channel.topic, -1) + 1
            expected = ours.decoded(channel.topic)[i][1] if i < 3 or i % 97 == 0 else None
            if expected is None:
                continue
            for name, value in expected.items():
                got = getattr(msg, name)
                if isinstance(value, list):  # AmTruth.p_W_joints: 3-vectors in our view, flat on the wire
                    flat = [x for v in value for x in v] if value and isinstance(value[0], list) else value
                    assert list(got) == flat, (channel.topic, name)
                else:
                    assert got == value, (channel.topic, name)
    assert seen.keys() == ros1_topics and all(n > 100 for n in seen.values())


def test_foxglove_channels_decode_with_the_stored_schema_in_a_protobuf_reader(capture, tmp_path):
    """What Foxglove does with the log's Foxglove channels, done by mcap-protobuf-support's
    reader: every protobuf channel decodes with the FileDescriptorSet stored in the file alone
    (a descriptor pool of the reader's own, not this program's types), and the /tf transforms
    and the object pose decoded that way are the poses of the truth samples in the same log."""
    from mcap_protobuf.decoder import DecoderFactory

    from ground_station import contract as c

    from .conftest import write_mcap

    p = tmp_path / "run.mcap"
    write_mcap(p, capture.samples)
    ours = read_log(p)
    topics = {t for t, e in ours.encodings.items() if e == "protobuf"}
    assert topics == {c.TF_TOPIC, c.OBJECT_POSE_TOPIC, c.SCENE_TOPIC, c.EVENTS_TOPIC}
    got: dict[str, list] = {}
    with open(p, "rb") as f:
        for schema, channel, message, msg in make_reader(f, decoder_factories=[DecoderFactory()]) \
                .iter_decoded_messages(topics=sorted(topics)):
            assert (schema.encoding, channel.message_encoding) == ("protobuf", "protobuf")
            assert schema.name == msg.DESCRIPTOR.full_name == ours.channels[channel.topic]
            assert type(msg) is not c.PROTOBUF_TYPES[schema.name]  # built from the file, not imported
            got.setdefault(channel.topic, []).append((message.log_time, msg))
    for topic in topics:  # our reader (classes from the same stored schema) reads the same messages
        assert [m.SerializeToString() for _, m in got[topic]] == [d for _, d in ours.messages[topic]], topic
        assert [type(m).__name__ for _, m in ours.protobuf(topic)] == [type(m).__name__ for _, m in got[topic]]
    truths = {t: ours.decoded(t) for t in ours.topics("/sim/am/", "/truth")}
    expected = sorted((round(t * 1e9), child, tuple(p), tuple(q)) for topic, msgs in truths.items()
                      for t, s in msgs
                      for child, p, q in ((f"am{s['sysid']}/base", s["p_WB"], s["q_WB"]),
                                          (f"am{s['sysid']}/ee", s["p_WE"], s["q_WE"])))
    tf = sorted((ns, tr.child_frame_id, (tr.translation.x, tr.translation.y, tr.translation.z),
                 (tr.rotation.w, tr.rotation.x, tr.rotation.y, tr.rotation.z))
                for ns, m in got[c.TF_TOPIC] for tr in m.transforms)
    assert len(tf) > 1000 and tf == expected  # exactly: the same doubles
    assert all(tr.parent_frame_id == "world" for _, m in got[c.TF_TOPIC] for tr in m.transforms)
    objects = ours.decoded(c.OBJECT_STATE_TOPIC)
    poses = [(m.pose.position.x, m.pose.position.y, m.pose.position.z, m.pose.orientation.w, m.pose.orientation.x,
              m.pose.orientation.y, m.pose.orientation.z) for _, m in got[c.OBJECT_POSE_TOPIC]]
    assert poses == [tuple(s["p_WO"]) + tuple(s["q_WO"]) for _, s in objects]
    levels = {m.level for _, m in got[c.EVENTS_TOPIC]}
    assert levels and levels <= {1, 2, 3, 4, 5}  # Foxglove's Log.Level: DEBUG..FATAL, never UNKNOWN here
    with open(p, "rb") as f:  # the schema is Foxglove's files and google/protobuf's they import, nothing else
        from google.protobuf.descriptor_pb2 import FileDescriptorSet

        for schema in make_reader(f).get_summary().schemas.values():
            if schema.encoding == "protobuf":
                names = {fd.name for fd in FileDescriptorSet.FromString(schema.data).file}
                assert all(n.startswith(("foxglove/", "google/protobuf/")) for n in names), names
