"""The recorder on binary messages, without zenoh (messages straight into its inbox, as its
callback puts them): garbled and cut batches are counted and never stop it, every sound
sample of them is kept, a topic keeps one form, non-finite numbers are kept as they are."""
from __future__ import annotations

import math
import random
import time

import pytest

from ground_station import contract as c
from ground_station.mcap_io import read_log
from ground_station.recorder import Recorder
from ground_station.review import summarize
from telemetry import binary, wire
from telemetry.schema import Channel, Keys
from telemetry.session import ZenohOptions

from .conftest import as_json, message_of, stamped, wire_form

KEYS = Keys()
STATS = "/recorder/stats"


def _record(path, messages):
    rec = Recorder(path, ZenohOptions(role="recorder"))
    rec.writer.open()
    rec._t0 = time.monotonic()
    rec._inbox.extend(messages)
    rec._drain()
    summary = rec.close()
    return summary, read_log(path)


def _batched(samples, per_message: int = 7):
    """The samples as a publisher sends them: runs of one key batched, seq stamped."""
    out, run = [], []
    for k, p in stamped(samples) + [(None, None)]:
        if run and (k != run[0][0] or len(run) == per_message or isinstance(p, bytes) != isinstance(run[0][1], bytes)):
            data = [wire_form(q)[0] for _, q in run]
            is_binary = isinstance(run[0][1], bytes)
            out.append((run[0][0], wire.binary_message(data) if is_binary else wire.json_message(data)))
            run = []
        if k is not None:
            run.append((k, p))
    return out


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the review of flipped floats (1e300 squared)
def test_garbled_binary_messages_are_counted_and_the_sound_ones_all_kept(capture, tmp_path):
    rng = random.Random(11)
    clean = _batched(capture.samples)
    s0, log0 = _record(tmp_path / "clean.mcap", clean)
    assert s0.malformed == 0 and s0.received == len(capture.samples)
    damaged, hit = [], set()
    for i, (k, m) in enumerate(clean):
        damaged.append((k, m))
        if wire.is_binary(m) and rng.random() < 0.3:  # a copy of it, damaged, under the same key
            hit.add(i)
            b = bytearray(m)
            how = rng.randrange(3)
            if how == 0:
                b = b[:rng.randrange(len(wire.MAGIC), len(b))]  # cut anywhere
            elif how == 1:
                for _ in range(rng.randrange(1, 8)):  # bytes flipped anywhere after the magic
                    b[rng.randrange(len(wire.MAGIC), len(b))] ^= 1 << rng.randrange(8)
            else:
                b += rng.randbytes(rng.randrange(1, 40))  # junk after the last frame
            damaged.append((k, bytes(b)))
    assert len(hit) > 20
    s1, log1 = _record(tmp_path / "damaged.mcap", damaged)
    assert s1.malformed > 0 and not log1.truncated
    for topic in (c.controller_topic(4), c.contact_topic(5), c.OBJECT_STATE_TOPIC):
        sound = {(ns, d) for ns, d in log0.messages[topic]}
        assert sound <= {(ns, d) for ns, d in log1.messages[topic]}, topic  # every sound sample is in
        for _, fields in log1.decoded(topic):  # and whatever else got in decodes
            assert 0.0 <= fields["t"] <= 1e7
    assert summarize(log1)["ams"] == [4, 5]


def test_a_cut_batch_keeps_its_complete_samples(capture, tmp_path):
    ctrl = [(k, p) for k, p in capture.samples if k == KEYS.controller(4)][:5]
    msg = wire.binary_message([wire_form(p)[0] for _, p in stamped(ctrl)])
    cut = len(msg) - len(ctrl[-1][1]) // 2  # inside the last frame
    summary, log = _record(tmp_path / "cut.mcap", [(KEYS.controller(4), msg[:cut])])
    assert summary.malformed == 1 and summary.received == 4
    assert [p["seq"] for _, p in log.decoded(c.controller_topic(4))] == [0, 1, 2, 3]
    assert log.decoded(STATS)[-1][1]["keys"][KEYS.controller(4)]["last_seq"] == 3


def test_a_topic_keeps_the_form_of_its_first_sample(capture, tmp_path):
    ctrl = stamped([(k, p) for k, p in capture.samples if k == KEYS.controller(4)][:6])
    as_dicts = [d for _, d in as_json(ctrl)]
    for first in ("binary", "json"):
        msgs = []
        for i, (k, p) in enumerate(ctrl):
            use_binary = (i < 3) == (first == "binary")
            msgs.append((k, message_of(p if use_binary else as_dicts[i])))
        summary, log = _record(tmp_path / f"{first}.mcap", msgs)
        topic = c.controller_topic(4)
        assert summary.malformed == 0 and log.encodings[topic] == ("ros1" if first == "binary" else "json")
        assert [p for _, p in log.decoded(topic)] == as_dicts


def test_non_finite_numbers_are_kept_and_a_non_finite_time_is_refused(tmp_path):
    ctrl = {"t": 0.5, "seq": 0, "sysid": 4, "phase": "grasp", **{k: [0.0] * 3 for k in (
        "r_c", "r_c_d", "r_c_err", "e_w", "y", "y_d", "y_err", "F_y", "f_W", "tau_B_nm", "tau_q_nm")},
        "e_R": [math.nan, math.inf, 0.0], "q_WB": [1.0, 0.0, 0.0, 0.0], "q_WB_d": [1.0, 0.0, 0.0, 0.0],
        "wrench_W": [0.0] * 6, "wrench_E": [0.0] * 6, "thrust_n": 17.0, "sigma_min_J3": 0.5, "damping": math.nan,
        "com_err_saturated": False, "y_err_saturated": False}
    truth = {"t": 0.5, "seq": 0, "sysid": 4, "p_WB": [math.nan, 0.0, 1.0], "q_WB": [1.0, 0.0, 0.0, 0.0],
             "p_WE": [0.0, 0.0, 1.0], "q_WE": [1.0, 0.0, 0.0, 0.0]}
    msgs = [(KEYS.controller(4), message_of(binary.from_dict(Channel.CONTROLLER, ctrl))),
            (KEYS.am_truth(4), message_of(binary.from_dict(Channel.AM_TRUTH, truth))),
            (KEYS.controller(4), message_of(binary.from_dict(Channel.CONTROLLER, {**ctrl, "t": math.nan, "seq": 1})))]
    summary, log = _record(tmp_path / "nan.mcap", msgs)
    assert summary.malformed == 1  # the sample without a time
    (_, got), = log.decoded(c.controller_topic(4))
    assert math.isnan(got["e_R"][0]) and got["e_R"][1] == math.inf and math.isnan(got["damping"])
    (_, tf), = log.protobuf(c.TF_TOPIC)  # a protobuf double carries NaN as it is
    assert math.isnan(tf.transforms[0].translation.x) and tf.transforms[1].translation.z == 1.0


def test_binary_samples_on_other_keys_are_counted_not_written(capture, tmp_path):
    obj = next(p for k, p in capture.samples if k == KEYS.object)
    msgs = [(KEYS.sim_event, message_of(obj)),  # binary on a JSON-only channel
            (f"{KEYS.prefix}/lab/thermometer", message_of(obj))]  # and on a key outside the contract
    summary, log = _record(tmp_path / "other.mcap", msgs)
    assert (summary.malformed, summary.unknown) == (1, 1)
    assert set(log.messages) == {STATS}


def test_binary_tf_and_pose_equal_the_json_ones(capture):
    """The Foxglove messages derived from binary samples (from the unpacked floats) are the
    ones derived from JSON samples (from the parsed text), byte for byte."""
    from ground_station.contract import Translator

    outs = {}
    for form, samples in (("binary", capture.samples), ("json", as_json(capture.samples))):
        tr = Translator(KEYS)
        outs[form] = [o for k, p in stamped(samples) for o in tr.translate(k, *wire_form(p))
                      if o.topic in (c.TF_TOPIC, c.OBJECT_POSE_TOPIC, c.SCENE_TOPIC, c.EVENTS_TOPIC)]
    assert len(outs["binary"]) > 1000 and outs["binary"] == outs["json"]
