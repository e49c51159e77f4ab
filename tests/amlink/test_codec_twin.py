"""The codec (amlink.codec) against its twin on pymavlink's message objects
(tests/amlink/codec_reference.py): same bytes, same values, same rejections.

Checked here: the datagrams are bit-identical (signed and unsigned), stock pymavlink
reads what the codec writes and the codec reads what pymavlink writes, and on a fuzz
corpus both decoders count, return and raise exactly the same.
"""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from amlink import codec, wire
from amlink.codec import mav
from amlink.types import AttitudeSetpoint, AttitudeTarget, ScenarioInfo, SensorFrame, StepFlag, TorqueSetpoint
from tests.amlink import codec_reference as ref
from tests.amlink.fuzz import Fuzzer
from tests.amlink.kit import key_for, make_frame
from tests.amlink.test_codec import F32, F64, attitude_setpoints, sensor_frames, setpoints, vec

KEY, OTHER = key_for(2), key_for(9)
BAD = (math.nan, math.inf, -math.inf, 1e300, -1e300)
COUNTERS = ("bad_frames", "unknown_sysid", "unsigned", "bad_signature", "replayed", "ignored")
ARRAYS = {SensorFrame: ("p_WB", "quat_WB_wxyz", "v_B", "w_B", "q", "qdot", "wrench_E"),
          TorqueSetpoint: ("tau_B_nm", "tau_q_nm"), AttitudeTarget: ("quat_wxyz", "rates_rad_s"),
          AttitudeSetpoint: ("tau_q_nm",)}  # fmt: skip


def twins(sysid: int, compid: int, key: bytes | None):
    """Two encoders in the same state: signing clock set ahead so that pack() keeps it."""
    a = codec.Encoder(sysid, compid, signing_key=key, link_id=sysid)
    b = codec.Encoder(sysid, compid, signing_key=key, link_id=sysid)
    if key is not None:
        a.mavlink.signing.timestamp = b.mavlink.signing.timestamp = wire.now_timestamp() + 10**9
    return a, b


def summary(item):
    """Everything observable of a decoded item, exact (float bits, dtype, shape, read-only, flag type)."""
    if isinstance(item, tuple):
        return tuple(summary(x) for x in item)
    if type(item) in ARRAYS:
        arrays = []
        for name in ARRAYS[type(item)]:
            a = getattr(item, name)
            assert a.dtype == np.float64 and a.ndim == 1 and not a.flags.writeable
            arrays.append((name, a.shape, a.tobytes()))
        scalars = {k: ((v.shape, v.tobytes(), v.flags.writeable) if isinstance(v, np.ndarray) else summary(v), type(v))
                   for k, v in vars(item).items() if k not in ARRAYS[type(item)]}  # an array: a frame's effort
        return type(item), scalars, arrays
    return item  # None, codec.Shutdown (a dataclass with ==)


def outcome(fn):
    try:
        return "ok", summary(fn())
    except ValueError as exc:
        return "error", type(exc), str(exc)


# -- encoding: bit for bit ---------------------------------------------------------------------


@pytest.mark.parametrize("key", [None, KEY], ids=["unsigned", "signed"])
@settings(max_examples=100, deadline=None, database=None)
@given(frame=sensor_frames(), scenario_id=st.integers(0, 2**32 - 1))
def test_sensor_batch_bytes_are_pymavlinks(key, frame, scenario_id):
    old, new = twins(1, 1, key)
    for _ in range(2):  # sequence number and signing timestamp advance alike
        assert new.pack_payloads(codec.sensor_frame_payloads(frame, scenario_id)) == old.pack(
            ref.sensor_frame_messages(frame, scenario_id))


@pytest.mark.parametrize("key", [None, KEY], ids=["unsigned", "signed"])
@settings(max_examples=100, deadline=None, database=None)
@given(sp=setpoints(), att=st.none() | st.builds(AttitudeTarget, st.just(0), vec(4, F32 | F64), vec(3, F32), F32),
       time_boot_ms=st.integers(0, 2**40), target=st.integers(0, 255))  # fmt: skip
def test_setpoint_batch_bytes_are_pymavlinks(key, sp, att, time_boot_ms, target):
    old, new = twins(2, 191, key)
    args = (sp, att, time_boot_ms, target, 255 - target)
    try:
        expected = old.pack(ref.setpoint_messages(*args))
    except codec.EncodeError as exc:  # e.g. a double beyond float32 in the attitude
        with pytest.raises(codec.EncodeError) as err:
            new.pack_payloads(codec.setpoint_payloads(*args))
        assert str(err.value) == str(exc)
        return
    assert new.pack_payloads(codec.setpoint_payloads(*args)) == expected


@pytest.mark.parametrize("key", [None, KEY], ids=["unsigned", "signed"])
@settings(max_examples=100, deadline=None, database=None)
@given(sp=attitude_setpoints(), time_boot_ms=st.integers(0, 2**40), target=st.integers(0, 255))
def test_attitude_setpoint_batch_bytes_are_pymavlinks_and_read_back_alike(key, sp, time_boot_ms, target):
    old, new = twins(2, 191, key)
    args = (sp, time_boot_ms, target, 255 - target)
    data = new.pack_payloads(codec.attitude_setpoint_payloads(*args))
    assert data == old.pack(ref.attitude_setpoint_messages(*args))
    assert [m.get_type() for m in stock_messages(data, key)] == ["SET_ATTITUDE_TARGET", "AM_JOINT_TORQUE_SETPOINT"]
    keys = None if key is None else {2: key}
    slow_asm, fast_asm = ref.SetpointAssembler(), codec.SetpointAssembler()
    slow = [slow_asm.push(m) for m in codec.Decoder(keys).feed(data)][-1]
    fast = [fast_asm.push(mid, body) for mid, _, _, body in
            codec.Decoder(keys, readers=codec.READERS).feed_records(data)][-1]  # fmt: skip
    assert isinstance(fast[0], AttitudeSetpoint) and summary(fast) == summary(slow)


def test_attitude_setpoint_errors_are_the_same():
    att = AttitudeTarget(3, [1, 0, 0, 0], [0, 0, 0], 0.5)
    for sp in (AttitudeSetpoint(3, att, [math.inf]), AttitudeSetpoint(3, AttitudeTarget(3, [1, 0, 0, 0], [0, 0, 0], math.nan), []),
               AttitudeSetpoint(3, AttitudeTarget(3, [1, 0, 0, 0], [0, 4e38, 0], 0.5), [])):
        with pytest.raises(codec.EncodeError) as want:
            codec.Encoder(2, 191).pack(ref.attitude_setpoint_messages(sp))
        with pytest.raises(codec.EncodeError) as got:
            codec.attitude_setpoint_payloads(sp)
        assert str(got.value) == str(want.value)
    joint_only = codec.Encoder(2, 191).pack(ref.attitude_setpoint_messages(AttitudeSetpoint(3, att, [0.1]))[1:])
    slow = outcome(lambda: [ref.SetpointAssembler().push(m) for m in codec.Decoder().feed(joint_only)])
    fast = outcome(lambda: [codec.SetpointAssembler().push(mid, body) for mid, _, _, body in
                            codec.Decoder(readers=codec.READERS).feed_records(joint_only)])  # fmt: skip
    assert slow == fast and slow[0] == "error" and "without SET_ATTITUDE_TARGET" in slow[2]


def test_sequence_wraps_and_both_paths_share_one_link_state():
    """Mixed on one encoder (rare messages via pymavlink) equals pymavlink alone, across seq 255 -> 0."""
    old, new = twins(1, 1, KEY)
    heartbeat = mav.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3)
    for k in range(140):
        frame = make_frame(2, k)
        assert new.pack([heartbeat]) == old.pack([heartbeat])
        assert new.pack_payloads(codec.sensor_frame_payloads(frame, 7)) == old.pack(
            ref.sensor_frame_messages(frame, 7))
    assert new.mavlink.seq == old.mavlink.seq == (140 * 5) % 256
    assert new.mavlink.signing.timestamp == old.mavlink.signing.timestamp
    assert (new.mavlink.total_packets_sent, new.mavlink.total_bytes_sent) == (
        old.mavlink.total_packets_sent, old.mavlink.total_bytes_sent)


def test_all_zero_payload_keeps_one_byte():
    old, new = twins(1, 1, None)
    shutdown = codec.shutdown_message(0, 0.0)
    shutdown.flags = 0  # an all-zero AM_SIM_STEP payload: MAVLink 2 keeps one byte
    data = new.pack_payloads([(mav.MAVLINK_MSG_ID_AM_SIM_STEP, bytes(21))])
    assert data == old.pack([shutdown]) and data[1] == 1


def test_encode_errors_are_the_same():
    frame = make_frame(2, 1)
    cases = [
        (SensorFrame(**{**vars(frame), "p_WB": [0, 0, math.nan]}), 0),
        (SensorFrame(**{**vars(frame), "time_s": -1e-3}), 0),
        (SensorFrame(**{**vars(frame), "v_B": [1e39, 0, 0]}), 0),  # beyond float32 (ODOMETRY)
        (SensorFrame(**{**vars(frame), "time_s": 2e13}), 0),  # beyond uint64 microseconds
        (frame, 2**32),  # scenario id beyond uint32
    ]
    for f, scenario_id in cases:
        with pytest.raises(codec.EncodeError) as want:
            codec.Encoder(1, 1).pack(ref.sensor_frame_messages(f, scenario_id))
        with pytest.raises(codec.EncodeError) as got:
            codec.sensor_frame_payloads(f, scenario_id)
        assert str(got.value) == str(want.value)
    sp = TorqueSetpoint(3, 1.0, [0, 0, 0], [0.5])
    for args in [
        (TorqueSetpoint(3, math.inf, [0, 0, 0], []),),
        (sp, AttitudeTarget(3, [1, 0, 0, 0], [0, 0, 0], math.nan)),
        (sp, AttitudeTarget(3, [1, 0, 0, 0], [0, 4e38, 0], 0.5)),  # beyond float32
        (sp, AttitudeTarget(3, [1, 0, 0, 0], [0, 0, 0], 0.5), 0, 256),  # target_system beyond uint8
    ]:
        with pytest.raises(codec.EncodeError) as want:
            codec.Encoder(2, 191).pack(ref.setpoint_messages(*args))
        with pytest.raises(codec.EncodeError) as got:
            codec.setpoint_payloads(*args)
        assert str(got.value) == str(want.value)


# -- decoding: pymavlink reads ours, we read pymavlink's -----------------------------------------


def stock_messages(data: bytes, key: bytes | None) -> list:
    """pymavlink's own receive path (as MAVProxy uses it); with ``key`` it verifies signatures."""
    p = mav.MAVLink(None)
    p.robust_parsing = True
    if key is not None:
        p.signing.secret_key = key
        p.signing.timestamp = wire.now_timestamp()
    msgs = [m for m in p.parse_buffer(data) or [] if not isinstance(m, mav.MAVLink_bad_data)]
    if key is not None:
        assert p.signing.goodsig_count == len(msgs) and p.signing.badsig_count == 0
    return msgs


@pytest.mark.parametrize("key", [None, KEY], ids=["unsigned", "signed"])
@settings(max_examples=30, deadline=None, database=None)
@given(frame=sensor_frames(), sp=setpoints(), quat=vec(4, st.floats(-1, 1)), rates=vec(3, st.floats(-50, 50)))
def test_stock_pymavlink_reads_the_codec_and_the_codec_reads_pymavlink(key, frame, sp, quat, rates):
    att = AttitudeTarget(sp.step, quat, rates, 0.5)
    batches = [
        (1, 1, lambda e: e.pack_payloads(codec.sensor_frame_payloads(frame, 7)),
         lambda e: e.pack(ref.sensor_frame_messages(frame, 7)),
         ref.SensorFrameAssembler, codec.SensorFrameAssembler),
        (2, 191, lambda e: e.pack_payloads(codec.setpoint_payloads(sp, att, 5)),
         lambda e: e.pack(ref.setpoint_messages(sp, att, 5)),
         ref.SetpointAssembler, codec.SetpointAssembler),
    ]  # fmt: skip
    for sysid, compid, fast_enc, slow_enc, Slow, Fast in batches:
        enc = codec.Encoder(sysid, compid, signing_key=key, link_id=sysid)
        fast_bytes, slow_bytes = fast_enc(enc), slow_enc(enc)
        # pymavlink decodes the codec's bytes into the messages the twin would have sent
        got, want = stock_messages(fast_bytes, key), stock_messages(slow_bytes, key)
        parts = 4 + (frame.attitude_target is not None) if sysid == 1 else 2
        assert [str(m) for m in got] == [str(m) for m in want] and len(got) == parts  # NaN-safe
        assert all(m.get_srcSystem() == sysid and m.get_signed() == (key is not None) for m in got)
        # the codec reads pymavlink-encoded bytes into what the twin assembles
        keys = None if key is None else {sysid: key}
        slow_asm, fast_asm = Slow(), Fast()
        slow = [slow_asm.push(m) for m in codec.Decoder(keys).feed(slow_bytes)][-1]
        fast = [fast_asm.push(mid, body) for mid, _, _, body in
                codec.Decoder(keys, readers=codec.READERS).feed_records(slow_bytes)][-1]  # fmt: skip
        assert slow is not None and summary(fast) == summary(slow)


def test_records_carry_ids_and_rare_messages_stay_pymavlink_objects():
    enc = codec.Encoder(1, 1)
    data = enc.pack([mav.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3)]) + enc.pack_payloads(
        codec.sensor_frame_payloads(make_frame(2, 4), 7))
    recs = codec.Decoder(readers=codec.READERS).feed_records(data)
    assert [(r[0], r[1], r[2]) for r in recs] == [(mid, 1, 1) for mid in (
        mav.MAVLINK_MSG_ID_HEARTBEAT, mav.MAVLINK_MSG_ID_ODOMETRY, mav.MAVLINK_MSG_ID_AM_JOINT_STATE,
        mav.MAVLINK_MSG_ID_AM_WRENCH, mav.MAVLINK_MSG_ID_AM_SIM_STEP)]  # fmt: skip
    assert recs[0][3].get_type() == "HEARTBEAT" and all(isinstance(r[3], tuple) for r in recs[1:])
    assert recs[-1][3] == (4, 4000, 7, 0)  # step, time_usec, scenario_id, flags


def test_a_payload_longer_than_the_message_is_read_as_pymavlink_reads_it():
    """MAVLink 2 receivers ignore payload bytes past the message's size (newer extensions)."""
    enc = codec.Encoder(2, 191)
    [(mid, payload)] = codec.setpoint_payloads(TorqueSetpoint(8, 3.0, [1, 2, 3], [4.0]))
    long = payload + b"\x5a" * 7
    data = bytearray(enc.pack_payloads([(mid, long)]))
    assert data[1] == len(long)
    slow = ref.SetpointAssembler().push(codec.Decoder().feed(bytes(data))[0])
    [(_, _, _, body)] = codec.Decoder(readers=codec.READERS).feed_records(bytes(data))
    assert summary(codec.SetpointAssembler().push(mid, body)) == summary(slow)


def test_frames_from_the_wire_are_read_only_and_cannot_be_made_writable():
    data = codec.Encoder(1, 1).pack_payloads(codec.sensor_frame_payloads(make_frame(3, 2), 7))
    asm = codec.SensorFrameAssembler()
    [frame] = [x for mid, _, _, b in codec.Decoder(readers=codec.READERS).feed_records(data)
               if (x := asm.push(mid, b)) is not None]  # fmt: skip
    assert frame.n_joints == 3 and frame.flags is StepFlag.NONE
    for name in ARRAYS[SensorFrame]:
        arr = getattr(frame, name)
        with pytest.raises(ValueError):
            arr[0] = 1.0
        with pytest.raises(ValueError):
            arr.setflags(write=True)
    # and it is usable as any SensorFrame (e.g. copied with changes)
    assert SensorFrame(**{**vars(frame), "q": [0.0, 0.0, 1.0]}).q[2] == 1.0


# -- rejections: the same, counted the same --------------------------------------------------


def _sensor_forge(encoders):
    def forge(rng: random.Random, step: int) -> bytes:
        enc = rng.choice(encoders)
        msgs = ref.sensor_frame_messages(make_frame(rng.choice((2, 3)), max(0, step + rng.randrange(-1, 2))), 7)
        kind = rng.randrange(9)
        if kind == 0:
            target = rng.choice((msgs[1].position_rad, msgs[1].velocity_rad_s, msgs[2].force_n))
            target[rng.randrange(3)] = rng.choice(BAD)
        elif kind == 1:
            msgs[0].q = [rng.choice(BAD[:3]), 0.0, 0.0, 0.0]  # float32: NaN and infinities only
        elif kind == 2:
            msgs[1].n_joints = rng.randrange(9, 256)
        elif kind == 3:
            msgs[0].frame_id, msgs[0].child_frame_id = rng.choice(((1, 13), (4, 12), (4, 13)))
        elif kind == 4:
            del msgs[rng.randrange(4)]
        elif kind == 5:
            msgs[rng.randrange(1, 4)].step += 1
        elif kind == 6:
            msgs = [codec.shutdown_message(step, 0.5, 7), mav.MAVLink_statustext_message(4, b"bye")]
        elif kind == 7:
            msgs.insert(rng.randrange(4), codec.scenario_message(ScenarioInfo(7, 2, "x", 1, 1000.0)))
        return enc.pack(msgs)

    return forge


def _setpoint_forge(encoders):
    def forge(rng: random.Random, step: int) -> bytes:
        enc = rng.choice(encoders)
        n = rng.randrange(0, 9)
        sp = TorqueSetpoint(step, rng.uniform(-50, 50), [rng.uniform(-1, 1)] * 3, [rng.uniform(-1, 1)] * n)
        att = AttitudeTarget(step, [1, 0, 0, 0], [0.1, 0.2, 0.3], 0.5) if rng.random() < 0.5 else None
        msgs = ref.setpoint_messages(sp, att)
        kind = rng.randrange(7)
        last = msgs[-1]
        if kind == 0:
            last.thrust_n = rng.choice(BAD)
        elif kind == 1:
            rng.choice((last.body_torque_nm, last.joint_torque_nm))[rng.randrange(3)] = rng.choice(BAD)
        elif kind == 2:
            last.n_joints = rng.randrange(9, 256)
        elif kind == 3 and att is not None:
            msgs[0].body_yaw_rate = rng.choice(BAD[:3])
        elif kind == 4:
            msgs = msgs[:-1] or [mav.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3)]
        elif kind == 5:
            msgs.append(mav.MAVLink_command_long_message(1, 1, 400, 0, 1.0, 0, 0, 0, 0, 0, 0))
        return enc.pack(msgs)

    return forge


def _run(decoder, assembler, data: bytes, fast: bool) -> list:
    """What one datagram yields, per message: ids, and the assembler's item or error."""
    assembler.reset()  # a batch is one datagram
    out = []
    records = decoder.feed_records(data) if fast else [
        (m.get_msgId(), m.get_srcSystem(), m.get_srcComponent(), m) for m in decoder.feed(data)]  # fmt: skip
    for mid, sysid, compid, body in records:
        item = outcome(lambda: assembler.push(mid, body) if fast else assembler.push(body))  # noqa: B023
        rare = None if isinstance(body, tuple) or mid in codec.READERS else bytes(body.get_msgbuf())
        out.append((mid, sysid, compid, item, rare))
    return out


@pytest.mark.parametrize("direction", ["sensor", "setpoint"])
@pytest.mark.parametrize("signed", [True, False], ids=["signed", "unsigned"])
def test_fuzz_both_decoders_accept_reject_and_count_the_same(direction, signed):
    if direction == "sensor":  # simulator -> companion
        sysid, compid, make = 1, 1, _sensor_forge
        Slow, Fast = ref.SensorFrameAssembler, codec.SensorFrameAssembler
    else:  # companion -> simulator
        sysid, compid, make = 2, 191, _setpoint_forge
        Slow, Fast = ref.SetpointAssembler, codec.SetpointAssembler
    keys = {sysid: KEY} if signed else None
    # the right key, none, a wrong one, an unknown sysid; and the right key on another link id
    encoders = [codec.Encoder(s, compid, signing_key=k, link_id=s) for s in (sysid, 9) for k in (None, KEY, OTHER)]
    encoders.append(codec.Encoder(sysid, compid, signing_key=KEY))
    rng = random.Random(2024 + signed + 2 * (direction == "sensor"))
    forge = make(encoders)
    fuzzer = Fuzzer(rng, [forge(rng, 0) for _ in range(50)], forge, tamper_steps=True)
    slow_dec, fast_dec = codec.Decoder(keys), codec.Decoder(keys, readers=codec.READERS)
    slow_asm, fast_asm = Slow(), Fast()
    seen = {"ok": 0, "error": 0}
    for step in range(100):
        for data in fuzzer.batch(100, step):
            want = _run(slow_dec, slow_asm, data, fast=False)
            got = _run(fast_dec, fast_asm, data, fast=True)
            assert got == want, data.hex()
            for *_, item, _ in want:
                if item[0] == "error":
                    seen["error"] += 1
                elif item[1] is not None:
                    seen["ok"] += 1
        fuzzer.captured.append(forge(rng, step))
    assert {c: getattr(fast_dec, c) for c in COUNTERS} == {c: getattr(slow_dec, c) for c in COUNTERS}
    assert seen["ok"] > 20 and seen["error"] > 20, seen  # both outcomes were exercised
    print(f"\n{direction} ({'signed' if signed else 'unsigned'}): {seen}, "
          f"{ {c: getattr(fast_dec, c) for c in COUNTERS} }")  # fmt: skip
    assert fast_dec.bad_frames > 100 and (not signed or (fast_dec.bad_signature > 0 and fast_dec.replayed > 0))
