"""End to end: a simulated run published through zenoh to `ground-station record` (a
subprocess), then the MCAP it wrote read back and reviewed against the ground truth."""
from __future__ import annotations

import json
import signal
import time

import numpy as np
import pytest

from ground_station import contract as c
from ground_station.cli import main as cli_main
from ground_station.mcap_io import read_log
from ground_station.review import summarize
from telemetry import binary
from telemetry.publisher import TelemetryPublisher
from telemetry.schema import Channel, Keys
from telemetry.session import ZenohOptions
from telemetry.validate import errors
from tests.telemetry.zenoh_testing import free_endpoint

from .conftest import sample_time
from .proc import RecorderProcess

KEYS = Keys()


def _publisher(ep, n):
    pub = TelemetryPublisher(ZenohOptions(connect=(ep,)), name="simrun", queue_size=n + 100)
    pub.open()
    assert pub.wait_for_subscriber(KEYS.sim_event, 15.0), "recorder not reachable"
    return pub


@pytest.fixture(scope="module")
def recorded(capture, tmp_path_factory):
    """The capture published at full speed; the recorder stops by itself at run_end."""
    path = tmp_path_factory.mktemp("rt") / "run.mcap"
    ep = free_endpoint()
    with RecorderProcess(path, ep) as rec:
        pub = _publisher(ep, len(capture.samples))
        for k, p in capture.samples:
            pub.publish(k, _copy(p))
        pst = pub.close(timeout_s=20.0)
        code, out = rec.wait(timeout_s=30.0)
    assert code == 0, rec.stderr_lines
    return path, pst, json.loads(out), rec.stderr_lines


def _copy(payload):
    return payload if isinstance(payload, bytes) else dict(payload)


def test_recorder_got_everything_and_stopped_at_run_end(recorded, capture):
    path, pst, summary, _ = recorded
    assert pst.dropped == 0 and pst.sent == len(capture.samples)
    assert summary["stop_reason"] == "run_end"
    n_stats = len(read_log(path).messages[c.publisher_topic("simrun")])  # the publisher's own accounting
    assert n_stats >= 1
    assert summary["received"] == len(capture.samples) + n_stats and summary["missing"] == 0
    assert summary["inbox_overflow"] == summary["malformed"] == summary["unknown"] == 0


def test_log_holds_every_documented_topic_with_valid_schemas_and_monotonic_time(recorded, capture):
    path = recorded[0]
    log = read_log(path)
    assert not log.truncated
    sysids = [a.sysid for a in capture.spec.ams]
    documented = {c.TF_TOPIC, c.SCENE_TOPIC, c.STATS_TOPIC, c.OBJECT_POSE_TOPIC, c.OBJECT_STATE_TOPIC,
                  c.SIM_EVENT_TOPIC, c.EVENTS_TOPIC, c.publisher_topic("simrun")}
    documented |= {c.controller_topic(s) for s in sysids} | {c.contact_topic(s) for s in sysids}
    documented |= {c.truth_topic(s) for s in sysids}
    assert set(log.messages) == documented
    hot = {c.controller_topic(s) for s in sysids} | {c.contact_topic(s) for s in sysids} | {c.OBJECT_STATE_TOPIC}
    hot |= {c.truth_topic(s) for s in sysids}
    assert {t for t, e in log.encodings.items() if e == c.ROS1} == hot  # the binary channels, with their .msg
    foxglove = {c.TF_TOPIC, c.SCENE_TOPIC, c.OBJECT_POSE_TOPIC, c.EVENTS_TOPIC}
    assert {t for t, e in log.encodings.items() if e == c.PROTOBUF} == foxglove
    for topic, msgs in log.messages.items():
        times = [ns for ns, _ in msgs]
        assert times == sorted(times), topic
        if topic in foxglove:  # every message decodes with the FileDescriptorSet stored in the file
            assert len(log.protobuf(topic)) == len(msgs), topic
            continue
        # the JSON Schema as stored in the file, or the payload's for a ros1 channel (decoded with the stored .msg)
        schema = log.schemas.get(log.channels[topic]) or c.json_schema(log.channels[topic])
        for _, fields in log.decoded(topic)[:: max(1, len(msgs) // 200)]:
            assert errors(fields, schema) == [], topic
    counts = {}
    for k, _ in capture.samples:
        counts[k] = counts.get(k, 0) + 1
    for s in sysids:
        assert len(log.messages[c.controller_topic(s)]) == counts[KEYS.controller(s)]
        assert len(log.messages[c.contact_topic(s)]) == counts[KEYS.contact(s)]
        assert len(log.messages[c.truth_topic(s)]) == counts[KEYS.am_truth(s)]
    assert len(log.messages[c.TF_TOPIC]) == sum(counts[KEYS.am_truth(s)] for s in sysids)
    assert len(log.messages[c.OBJECT_POSE_TOPIC]) == counts[KEYS.object]
    # log time is simulation time
    ts = [g.time_s for g in capture.truths]
    assert log.messages[c.OBJECT_POSE_TOPIC][0][0] == round(ts[0] * 1e9)
    assert log.messages[c.OBJECT_POSE_TOPIC][-1][0] == round(ts[-1] * 1e9)


def test_review_agrees_with_the_published_ground_truth(recorded, capture):
    s = summarize(read_log(recorded[0]))
    m = capture.spec.mission
    assert s["phase_ends_s"] == [m.approach_end_s, m.grasp_end_s, m.hover_end_s]
    t = np.array([g.time_s for g in capture.truths])
    z = np.array([g.object.p_WO[2] for g in capture.truths])
    assert s["object_start_z_m"] == z[0]
    windows = {"approach": (0.0, m.approach_end_s), "grasp": (m.approach_end_s, m.grasp_end_s),
               "hover": (m.grasp_end_s, np.inf)}
    saw_contact = False
    for name, (a, b) in windows.items():
        w = (t >= a) & (t < b)
        p = s["phases"][name]
        assert p["object_lift_m"]["final"] == pytest.approx(z[w][-1] - z[0], abs=1e-12)
        assert p["object_lift_m"]["max"] == pytest.approx((z[w] - z[0]).max(), abs=1e-12)
        for sysid in (a_.sysid for a_ in capture.spec.ams):
            n = np.array([g.ams[sysid].pad_object_contact.normal_force_n for g in capture.truths])[w]
            tang = np.array([np.linalg.norm(g.ams[sysid].pad_object_contact.tangential_force_W)
                             for g in capture.truths])[w]
            got = p["ams"][str(sysid)]
            assert got["contact_normal_n"] == pytest.approx({"final": n[-1], "mean": n.mean(), "max": n.max()},
                                                            rel=1e-12, abs=1e-12)
            assert got["contact_tangential_n"] == pytest.approx({"final": tang[-1], "max": tang.max()},
                                                                rel=1e-12, abs=1e-12)
            saw_contact |= n.max() > 0
    assert saw_contact, "the run never touched the object: the comparison above proves little"


def test_sigkill_loses_at_most_the_last_flush_period_and_review_salvages(capture, tmp_path, capsys):
    """Publish at half real time, SIGKILL the recorder mid-run: the salvaged file holds,
    per key, an unbroken run of samples from the first one up to at most ~1 s (the flush
    period) before the kill."""
    path = tmp_path / "killed.mcap"
    ep = free_endpoint()
    flush_s, slack_s = 1.0, 0.4
    sent_at: dict[str, list[float]] = {}
    with RecorderProcess(path, ep, "--flush-period", str(flush_s)) as rec:
        pub = _publisher(ep, len(capture.samples))
        t0 = time.monotonic()
        for k, p in capture.samples:
            lag = 2.0 * sample_time(p) - (time.monotonic() - t0)  # 2 s of wall time per simulated second
            if lag > 0:
                time.sleep(lag)
            if time.monotonic() - t0 >= 2.2:
                break
            pub.publish(k, _copy(p))
            sent_at.setdefault(k, []).append(time.monotonic())
        rec.proc.send_signal(signal.SIGKILL)
        killed_at = time.monotonic()
        rec.proc.wait(10)
        pub.close(timeout_s=5.0)
    log = read_log(path)
    assert log.truncated
    topic_of = {KEYS.controller(s): c.controller_topic(s) for s in (4, 5)}
    topic_of.update({KEYS.contact(s): c.contact_topic(s) for s in (4, 5)})
    topic_of[KEYS.object] = c.OBJECT_STATE_TOPIC
    for key, topic in topic_of.items():
        seqs = [p["seq"] for _, p in log.decoded(topic)]
        assert seqs == list(range(len(seqs))), f"{topic}: salvaged samples are not a gap-free prefix"
        must_have = sum(1 for w in sent_at[key] if w < killed_at - flush_s - slack_s)
        assert must_have > 0 and len(seqs) >= must_have, (topic, len(seqs), must_have, len(sent_at[key]))
    assert cli_main(["review", str(path)]) == 0
    out = capsys.readouterr().out
    assert "SALVAGED" in out
    assert cli_main(["review", str(path), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["log"]["salvaged"] is True and s["log"]["complete_chunks"] >= 1


def test_a_keyed_recorder_ignores_a_forged_run_end_and_forged_samples_over_zenoh(capture, tmp_path):
    """Through zenoh and `ground-station record --telemetry-key-file`: a process without the run's
    simulator key publishes a run_end at t = 0.2 s and an object 1 km up before the run's own
    samples; the recorder neither stops nor records them, and counts them as rejected."""
    from telemetry.auth import publisher_key

    master = bytes(range(7, 39))
    (tmp_path / "telemetry.key").write_text(master.hex())
    path = tmp_path / "run.mcap"
    ep = free_endpoint()
    with RecorderProcess(path, ep, "--telemetry-key-file", str(tmp_path / "telemetry.key")) as rec:
        forger = TelemetryPublisher(ZenohOptions(connect=(ep,), auth_key=publisher_key(master, "am4")), name="am4")
        forger.open()
        assert forger.wait_for_subscriber(KEYS.sim_event, 15.0)
        forger.publish(KEYS.sim_event, {"t": 0.2, "seq": 0, "source": "simulator", "kind": "run_end",
                                        "level": "info", "text": "forged"})
        up = {"t": 0.2, "seq": 0, "p_WO": [0.0, 0.0, 1000.0], "q_WO": [1.0, 0.0, 0.0, 0.0],
              "v_WO": [0.0, 0.0, 0.0], "w_WO": [0.0, 0.0, 0.0], "touching": []}
        forger.publish(KEYS.object, dict(up))
        forger.publish(KEYS.sim_event, {"t": 0.2, "seq": 0, "source": "simulator", "kind": "info",
                                        "level": "info", "text": "between the two objects"})
        forger.publish(KEYS.object, binary.from_dict(Channel.OBJECT, up))  # binary, in a message of its own
        forger.close(timeout_s=10.0)
        time.sleep(1.0)  # past the recorder's linger, had it taken the forged run_end
        pub = TelemetryPublisher(ZenohOptions(connect=(ep,), auth_key=publisher_key(master, "simulator")),
                                 name="simulator", queue_size=len(capture.samples) + 100)
        pub.open()
        assert pub.wait_for_subscriber(KEYS.sim_event, 15.0)
        for k, p in capture.samples:
            if k.startswith(f"{KEYS.prefix}/sim/"):  # the simulator's own keys
                pub.publish(k, _copy(p))
        pub.close(timeout_s=20.0)
        code, out = rec.wait(timeout_s=30.0)
    assert code == 0, rec.stderr_lines
    summary = json.loads(out)
    assert summary["stop_reason"] == "run_end" and summary["rejected"] >= 4  # the four forged samples (+ am4's stats)
    log = read_log(path)
    ends = [p["t"] for _, p in log.decoded(c.SIM_EVENT_TOPIC) if p["kind"] == "run_end"]
    assert len(ends) == 1 and ends[0] > 1.0  # the run's own, at the end of the 1.3 s capture
    assert max(p["p_WO"][2] for _, p in log.decoded(c.OBJECT_STATE_TOPIC)) < 2.0
