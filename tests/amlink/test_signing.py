"""MAVLink 2 signing: key handling, pymavlink's behaviour checked, our decoder, the signed link."""

from __future__ import annotations

import socket
import threading

import pytest

from amlink import codec, signing, wire
from amlink.codec import mav
from amlink.errors import PeerMissingError, PeerTimeoutError, SimulatorUnreachableError
from amlink.lockstep import CompanionClient
from amlink.types import TorqueSetpoint
from tests.amlink import codec_reference as ref
from tests.amlink.kit import SCENARIO, answer, client_for, key_for, linked, make_frame, server_for

KEY, OTHER = key_for(2), key_for(9)


def setpoint_datagram(enc: codec.Encoder, step: int = 1, thrust: float = 5.0) -> bytes:
    return enc.pack(ref.setpoint_messages(TorqueSetpoint(step, thrust, [0, 0, 0], [])))


def stock_parser(key: bytes):
    """pymavlink's own receive path with signing on (no amstack code involved)."""
    p = mav.MAVLink(None)
    p.robust_parsing = True
    p.signing.secret_key = key
    p.signing.timestamp = wire.now_timestamp()
    return p


def good_messages(parser, data: bytes) -> list:
    return [m for m in parser.parse_buffer(data) or [] if not isinstance(m, mav.MAVLink_bad_data)]


# -- keys ------------------------------------------------------------------------


def test_key_formats_and_resolution(tmp_path):
    hexkey = KEY.hex()
    assert signing.key_from_hex(f"  {hexkey}\n") == KEY
    for bad in ("zz" * 32, "ab" * 31, "ab" * 33):
        with pytest.raises(signing.SigningKeyError):
            signing.key_from_hex(bad)
    f = tmp_path / "link.key"
    f.write_text(hexkey + "\n")
    assert signing.read_key_file(f) == KEY
    with pytest.raises(signing.SigningKeyError, match="missing.key"):
        signing.read_key_file(tmp_path / "missing.key")
    assert signing.resolve_key(4, key_hex=OTHER.hex(), master_key=KEY) == (OTHER, "vehicle")
    k4, src = signing.resolve_key(4, master_key=KEY)
    assert src == "master" and k4 == signing.derive_vehicle_key(KEY, 4) != signing.derive_vehicle_key(KEY, 5)
    d4, src = signing.resolve_key(4, scenario_name="two_am_comp")
    assert src == "development" and len(d4) == 32
    assert d4 != signing.resolve_key(5, scenario_name="two_am_comp")[0]
    assert d4 == signing.resolve_key(4, scenario_name="other")[0]  # so a wrong-scenario companion is told so


def test_encoder_timestamp_follows_the_wall_clock_and_grows_per_frame():
    enc = codec.Encoder(2, 191, signing_key=KEY, link_id=2)
    enc.mavlink.signing.timestamp = 0  # e.g. a long-running process whose counter fell behind
    before = wire.now_timestamp()
    data = enc.pack(ref.setpoint_messages(TorqueSetpoint(1, 5.0, [0, 0, 0], []), None) * 2)
    stamps, i = [], 0
    while i < len(data):
        end = i + 12 + data[i + 1] + 13
        assert data[i + 2] & 1 and data[end - 13] == 2  # signed, link id 2
        stamps.append(int.from_bytes(data[end - 12 : end - 6], "little"))
        i = end
    assert before <= stamps[0] < stamps[1]


# -- what pymavlink itself does (facts our design relies on or works around) ---------


def test_pymavlink_rejects_a_wrong_key_and_an_exact_replay():
    data = setpoint_datagram(codec.Encoder(2, 191, signing_key=KEY, link_id=2))
    assert good_messages(stock_parser(OTHER), data) == []
    p = stock_parser(KEY)
    assert len(good_messages(p, data)) == 1
    assert good_messages(p, data) == []  # the same datagram again: old timestamp
    assert p.signing.badsig_count == 1


def test_pymavlink_records_the_timestamp_before_checking_the_signature():
    """One forged packet with a far-future timestamp silences a genuine stream in stock pymavlink."""
    genuine = codec.Encoder(2, 191, signing_key=KEY, link_id=2)
    forger = codec.Encoder(2, 191, signing_key=OTHER, link_id=2)  # same stream id, wrong key
    forger.mavlink.signing.timestamp = wire.now_timestamp() + 10**11  # ~11 days ahead
    forged, real = setpoint_datagram(forger), setpoint_datagram(genuine)
    p = stock_parser(KEY)
    assert good_messages(p, forged) == []
    assert good_messages(p, real) == []  # pymavlink: the genuine packet is now "old"
    dec = codec.Decoder({2: KEY})
    assert dec.feed(forged) == [] and dec.bad_signature == 1
    assert len(dec.feed(real)) == 1 and dec.replayed == 0  # ours: unaffected


# -- our decoder -------------------------------------------------------------------------


def test_decoder_counts_each_kind_of_rejection():
    enc = codec.Encoder(2, 191, signing_key=KEY, link_id=2)
    dec = codec.Decoder({2: KEY})
    first = setpoint_datagram(enc, 1)
    assert [m.step for m in dec.feed(first)] == [1]
    assert dec.feed(first) == [] and dec.replayed == 1  # exact replay
    assert dec.feed(setpoint_datagram(codec.Encoder(2, 191), 2)) == [] and dec.unsigned == 1
    assert dec.feed(setpoint_datagram(codec.Encoder(2, 191, signing_key=OTHER, link_id=2), 3)) == []
    assert dec.bad_signature == 1
    assert dec.feed(setpoint_datagram(codec.Encoder(9, 191, signing_key=OTHER, link_id=9), 4)) == []
    assert dec.unknown_sysid == 1  # no key for sysid 9
    # alter a signed frame and fix its CRC: only the signature can tell
    tampered = bytearray(setpoint_datagram(enc, 5, thrust=5.0))
    tampered[18] ^= 0x01  # a payload byte (the step is at 10..17)
    crc = codec.wire._mcrf4xx(bytes((mav.MAVLink_am_torque_setpoint_message.crc_extra,)),
                             codec.wire._mcrf4xx(bytes(tampered[1 : len(tampered) - 15])))  # fmt: skip
    tampered[-15:-13] = crc.to_bytes(2, "little")
    assert dec.feed(bytes(tampered)) == [] and dec.bad_signature == 2 and dec.bad_frames == 0
    assert [m.step for m in dec.feed(setpoint_datagram(enc, 6))] == [6]  # the stream goes on


def test_decoder_rejects_a_new_stream_older_than_a_minute():
    """A recording from an earlier run (two minutes old) is a new stream too old to trust."""
    old = codec.Encoder(2, 191, signing_key=KEY, link_id=2)
    old.mavlink.signing.timestamp = wire.now_timestamp() - 2 * wire.NEW_STREAM_WINDOW
    old.mavlink.send(mav.MAVLink_am_torque_setpoint_message(1, 1.0, [0.0] * 3, 0, [0.0] * 8, 0))  # bypass pack()
    recorded = b"".join(old._sink.parts)
    dec = codec.Decoder({2: KEY})
    assert dec.feed(recorded) == [] and dec.replayed == 1
    assert len(dec.feed(setpoint_datagram(codec.Encoder(2, 191, signing_key=KEY, link_id=2)))) == 1


# -- the signed link ---------------------------------------------------------------------


def test_signed_lockstep_runs_and_rejects_replays_and_strangers():
    with linked([2, 3], timeout_s=1.0, signing=True) as (server, clients):
        assert server.signing and all(c.signing for c in clients.values())
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as spy:
            for k in range(30):
                frames = {s: make_frame(s, k) for s in clients}
                for s, c in clients.items():
                    c.send_setpoint(answer(frames[s], s))
                if k == 10:  # a replay of an earlier genuine answer, and a forged one
                    spy.sendto(codec.Encoder(2, 191).pack(ref.setpoint_messages(answer(frames[2], 2))),
                               server.address)  # fmt: skip
                    forged = codec.Encoder(2, 191, signing_key=OTHER, link_id=2)
                    spy.sendto(setpoint_datagram(forged, k, 1e3), server.address)
                got = server.exchange(frames)
                for s in clients:
                    assert got[s].thrust_n == 100.0 * s + k
                    assert clients[s].recv_frame(1.0).step == k
        st = server.stats
        assert (st.unsigned, st.bad_signature, st.bad_frames) == (1, 1, 0)
        assert server.peer_address(2) == ("127.0.0.1", clients[2].local_address[1])  # not moved


def test_captured_datagram_replayed_is_rejected_by_the_server():
    with linked([2], timeout_s=0.3, signing=True) as (server, clients):
        c = clients[2]
        captured: list[bytes] = []
        c._link.shim = lambda addr, data: captured.append(data) or [(addr, data)]
        c.send_setpoint(answer(make_frame(2, 0), 2))
        assert server.exchange({2: make_frame(2, 0)})[2].step == 0
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as spy:
            spy.sendto(captured[-1], server.address)  # exact replay, from elsewhere
            with pytest.raises(PeerTimeoutError):
                server.exchange({2: make_frame(2, 1)})
        assert server.stats.replayed >= 1 and server.stats.stale_setpoints == 0


def test_unsigned_or_wrong_key_companion_never_gets_in():
    server = server_for([2], signing=True)
    server.open()
    try:
        plain = client_for(server, 2, signing=False)
        wrong = CompanionClient(2, sim=plain.sim, signing_key=OTHER)
        for c in (plain, wrong):
            errors: list[BaseException] = []
            t = threading.Thread(target=lambda c=c: errors.append(pytest.raises(SimulatorUnreachableError, c.connect, 0.6)))
            t.start()
            with pytest.raises(PeerMissingError):
                server.wait_for_peers(0.8)
            t.join(2.0)
            assert errors and c.scenario is None
            c.close()
        assert server.peer_address(2) is None
        assert server.stats.unsigned >= 1 and server.stats.bad_signature >= 1
    finally:
        server.close()


def test_signing_server_and_client_agree_on_scenario():
    with linked([2], signing=True) as (_server, clients):
        assert clients[2].scenario == SCENARIO
