"""The recorder with a run key: forged samples and a forged run_end change nothing in the MCAP
(and are counted); without a key the same attack does (the test's control)."""
from __future__ import annotations

import time

from ground_station import contract as c
from ground_station.mcap_io import read_log
from ground_station.recorder import Recorder
from telemetry import binary, wire
from telemetry.auth import publisher_key, publisher_of, seal
from telemetry.schema import Channel, Keys, encode, event, run_end_event
from telemetry.session import ZenohOptions

from .conftest import message_of, stamped

KEYS = Keys()
MASTER = bytes(range(1, 33))
STATS = "/recorder/stats"


def _authentic(capture):
    """The capture's samples as the run's publishers send them: each sealed with its own key."""
    return [(k, seal(publisher_key(MASTER, publisher_of(KEYS, k)), k, message_of(p)))
            for k, p in stamped(capture.samples)]


def _forged():
    """What a local process without the run's simulator key sends: a run_end at t = 0.5 s (unsealed,
    sealed with a companion's key, or with another run's key), and an object 1 km up (JSON and
    binary, alone or two in a message), and an authentic binary message altered after sealing."""
    end = encode(run_end_event(0.5))[0]
    up = {"t": 0.6, "seq": 999, "p_WO": [0.0, 0.0, 1000.0], "q_WO": [1.0, 0.0, 0.0, 0.0],
          "v_WO": [0.0, 0.0, 0.0], "w_WO": [0.0, 0.0, 0.0], "touching": []}
    obj, obj_bin = encode(up)[0], binary.from_dict(Channel.OBJECT, up)
    note = encode(event(0.7, "fault", "forged", "simulator", level="fatal"))[0]
    sim = publisher_key(MASTER, "simulator")
    sealed = bytearray(seal(sim, KEYS.object, wire.binary_message([binary.with_seq(obj_bin, 3)])))
    sealed[len(wire.MAGIC) + 4 + 16 + 16] ^= 0x40  # z of p_WO, after sealing
    return [(KEYS.sim_event, end),
            (KEYS.sim_event, seal(publisher_key(MASTER, "am4"), KEYS.sim_event, end)),
            (KEYS.object, seal(publisher_key(bytes(32), "simulator"), KEYS.object, obj)),
            (KEYS.object, obj + b"\n" + obj),
            (KEYS.sim_event, note),
            (KEYS.object, wire.binary_message([obj_bin, obj_bin])),
            (KEYS.object, seal(publisher_key(MASTER, "am4"), KEYS.object, wire.binary_message([obj_bin]))),
            (KEYS.object, bytes(sealed))]


def _record(path, messages, master):
    rec = Recorder(path, ZenohOptions(role="recorder", auth_key=master))
    rec.writer.open()  # no zenoh session: the messages go straight into the inbox, as its callback puts them
    rec._t0 = time.monotonic()
    rec._inbox.extend(messages)
    rec._drain()
    run_end = rec.translator.run_end
    summary = rec.close()
    log = read_log(path)
    return {t: m for t, m in log.messages.items() if t != STATS}, run_end, summary, log


def test_forged_samples_and_run_end_change_nothing_in_the_log(capture, tmp_path):
    authentic = _authentic(capture)
    half = len(authentic) // 2
    attacked = authentic[:half] + _forged() + authentic[half:]
    clean, end0, s0, _ = _record(tmp_path / "clean.mcap", authentic, MASTER)
    got, end1, s1, log = _record(tmp_path / "attacked.mcap", attacked, MASTER)
    assert got == clean  # every topic, message for message
    assert end1 == end0 and end1["t"] > 1.0  # the simulator's own run_end, at the end of the 1.3 s run
    assert s0.rejected == 0 and s1.rejected == 10  # every forged sample, counted
    assert log.metadata["recorder_summary"]["rejected"] == "10"
    assert log.decoded(STATS)[-1][1]["rejected"] == 10


def test_without_a_key_the_same_attack_lands(capture, tmp_path):
    """The control: a recorder without the run key (or a run without one) takes the forgeries."""
    authentic = _authentic(capture)
    half = len(authentic) // 2
    got, _, summary, log = _record(tmp_path / "open.mcap", authentic[:half] + _forged() + authentic[half:], None)
    clean, _, _, _ = _record(tmp_path / "clean.mcap", authentic, MASTER)
    assert got != clean and summary.rejected == 0
    ends = [p["t"] for _, p in log.decoded(c.SIM_EVENT_TOPIC) if p["kind"] == "run_end"]
    assert 0.5 in ends  # the forged run_end is in the log (the live recorder would stop on it)
    assert max(p["p_WO"][2] for _, p in log.decoded(c.OBJECT_STATE_TOPIC)) >= 1000.0


def test_a_batch_keeps_only_the_samples_its_publisher_may_write(capture, tmp_path):
    """A batch on <p>/batch/<name> is sealed with <name>'s key; every sample in it must be of a
    key <name> may write: a companion cannot slip a run_end or an object into its batch."""
    ctrl = [(k, p) for k, p in stamped(capture.samples) if k == KEYS.controller(4)][:5]
    up = {"t": 0.6, "seq": 0, "p_WO": [0.0, 0.0, 1000.0], "q_WO": [1.0, 0.0, 0.0, 0.0],
          "v_WO": [0.0, 0.0, 0.0], "w_WO": [0.0, 0.0, 0.0], "touching": []}
    keys = [k for k, _ in ctrl] + [KEYS.object]
    samples = [p for _, p in ctrl] + [binary.from_dict(Channel.OBJECT, up)]
    seqs = [binary.header(p)[1] for p in samples]
    am4 = publisher_key(MASTER, "am4")
    messages = [(KEYS.batch("am4"), seal(am4, KEYS.batch("am4"), wire.batch_message(keys, samples, seqs))),
                (KEYS.batch("simulator"), seal(am4, KEYS.batch("simulator"), wire.batch_message(keys, samples, seqs))),
                (KEYS.controller(4), seal(am4, KEYS.controller(4), wire.batch_message(keys, samples, seqs)))]
    got, _, summary, log = _record(tmp_path / "batch.mcap", messages, MASTER)
    assert [p["seq"] for _, p in log.decoded(c.controller_topic(4))] == [0, 1, 2, 3, 4]  # am4's own
    assert c.OBJECT_STATE_TOPIC not in got
    assert summary.rejected == 1 + 6  # the object in am4's batch; the batch sealed by the wrong publisher
    assert summary.malformed == 6  # a batch on a key that is not a batch key
