"""Fuzz: >= 1e5 hostile datagrams at a live SimServer, and at a live CompanionClient, during lockstep.

The honest parties must see exactly the honest run (every step once, the honest
setpoints), nothing may raise, and the counters must show the rejections.
"""

from __future__ import annotations

import math
import random
import socket
import threading
import time

import pytest

from amlink import codec
from amlink.codec import mav
from amlink.errors import SimulatorTimeoutError
from tests.amlink import codec_reference as ref
from tests.amlink.fuzz import Fuzzer, encoder_pool
from tests.amlink.kit import answer, client_for, key_for, make_frame, server_for

BAD = (math.nan, math.inf, -math.inf, 1e300, -1e300)
OTHER = bytes(range(100, 132))


def _capture(into: list[bytes]):
    """Send shim that records every datagram it lets through."""

    def shim(addr, data):
        into.append(data)
        return [(addr, data)]

    return shim


def _honest(client, sysid, seen, errors, buggy_rng=None):
    """Connect, arm, answer until shutdown; ``buggy_rng``: sometimes send a signed NaN/huge setpoint first."""
    try:
        client.connect(5.0)
        client.arm(5.0)
        while (frame := client.recv_frame(5.0)) is not None:
            seen.append(frame.step)
            if buggy_rng is not None and buggy_rng.random() < 0.2:
                bad = buggy_rng.choice(BAD)
                client._send([mav.MAVLink_am_torque_setpoint_message(frame.step, bad, [0.0] * 3, 0, [0.0] * 8, 0)])
            client.send_setpoint(answer(frame, sysid))
    except SimulatorTimeoutError as exc:
        errors.append(exc)
    except BaseException as exc:  # reported by the main thread
        errors.append(exc)


def _server_forge(signing: bool, sysids):
    pool = encoder_pool((*sysids, 9, 200), {"none": None, "other": OTHER, **{s: key_for(s) for s in sysids}}, 191)

    def forge(rng: random.Random, step: int) -> bytes:
        sysid = rng.choice((*sysids, 9, 200))
        key = rng.choice(["none", "other", *[s for s in sysids if s != sysid]])
        enc = pool[(sysid, key)]
        kind = rng.randrange(4)
        if kind == 0 and signing:  # signing off, the first HEARTBEAT claiming a sysid gets it: the known hole
            return enc.pack([mav.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3)])
        if kind == 1:
            return enc.pack([mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0.0,
                                                              0, 0, 0, 0, 0, 0)])  # fmt: skip
        value = rng.choice(BAD) if rng.random() < 0.5 else 50.0
        msgs = [mav.MAVLink_am_torque_setpoint_message(max(0, step + rng.randrange(-1, 2)), value, [value] * 3, sysid,
                                                        [value] * 8, 0)]  # fmt: skip
        if kind == 3:
            msgs.insert(0, mav.MAVLink_set_attitude_target_message(0, 1, 1, 0, [1.0, 0, 0, 0], 0, 0, 0, 0.5))
        return enc.pack(msgs)

    return forge


def _client_forge(signing: bool, sysid: int):
    pool = encoder_pool((1, 9), {"none": None, "other": OTHER, "peer": key_for(sysid + 1)}, 1)

    def forge(rng: random.Random, step: int) -> bytes:
        src = rng.choice((1, 9))
        enc = pool[(src, rng.choice(("none", "other", "peer")))]
        plausible = signing  # signing off, from the sim's address, only invalid content is detectable
        kind = rng.randrange(4) if plausible else rng.choice((0, 2))
        if kind == 0:
            frame = make_frame(sysid, step + 1)
            msgs = ref.sensor_frame_messages(frame, 7)
            if not plausible or rng.random() < 0.5:
                msgs[1].position_rad[0] = rng.choice(BAD)
            return enc.pack(msgs)
        if kind == 1 and plausible:
            return enc.pack([codec.shutdown_message(step + 1, 0.0, 7)])
        if kind == 2:
            return enc.pack([mav.MAVLink_statustext_message(mav.MAV_SEVERITY_CRITICAL, b"forged")])
        return enc.pack([mav.MAVLink_command_ack_message(mav.MAV_CMD_COMPONENT_ARM_DISARM, 4, 0, 0, sysid, 191)])

    return forge


@pytest.mark.parametrize("signing,steps,per_step", [(True, 500, 200), (False, 100, 200)], ids=["signed", "unsigned"])
def test_fuzz_simserver_while_honest_companions_keep_lockstep(signing, steps, per_step):
    sysids = (2, 3)
    server = server_for(sysids, timeout_s=5.0, signing=signing)
    server.open()
    captured: list[bytes] = []
    seen = {s: [] for s in sysids}
    errors: list[BaseException] = []
    clients = {s: client_for(server, s, signing, shim=_capture(captured)) for s in sysids}
    threads = [threading.Thread(target=_honest, args=(clients[s], s, seen[s], errors, random.Random(s)))
               for s in sysids]  # fmt: skip
    rng = random.Random(12345)
    forge = _server_forge(signing, sysids)
    fuzzer = Fuzzer(rng, [forge(rng, 0) for _ in range(20)], forge, tamper_steps=True)
    sent = refused_answers = 0
    t0 = time.monotonic()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as attacker:
        try:
            for d in fuzzer.batch(per_step, 0):  # during the handshake too
                attacker.sendto(d, server.address)
                sent += 1
            for t in threads:
                t.start()
            server.wait_for_peers(5.0)
            server.wait_for_armed(5.0)
            homes = {s: ("127.0.0.1", clients[s].local_address[1]) for s in sysids}
            fuzzer.captured = captured  # from now on, mutate genuine traffic
            for k in range(steps):
                for d in fuzzer.batch(per_step, k):
                    attacker.sendto(d, server.address)
                sent += per_step
                frames = {s: make_frame(s, k) for s in sysids}
                got = server.exchange(frames)
                refused = {s for s, _ in server.last_rejected}  # a buggy companion's first answer: refused
                assert set(got) | refused == set(sysids) and not set(got) & refused
                refused_answers += len(refused)
                for s, sp in got.items():  # exactly what the honest companion sent
                    honest = answer(frames[s], s)
                    assert sp.step == k and sp.thrust_n == honest.thrust_n
                    assert sp.tau_B_nm.tobytes() == honest.tau_B_nm.tobytes()
                    assert sp.tau_q_nm.tobytes() == honest.tau_q_nm.tobytes()
        finally:
            server.close("done")
            for t in threads:
                if t.ident is not None:
                    t.join(5.0)
            for c in clients.values():
                c.close()
    elapsed = time.monotonic() - t0
    assert not errors, errors
    assert seen == {s: list(range(steps)) for s in sysids}
    st = server.stats
    print(f"\nserver fuzz ({'signed' if signing else 'unsigned'}): {sent} datagrams in {elapsed:.2f} s "
          f"({sent / elapsed:.0f}/s); {st}")  # fmt: skip
    assert sent >= (100_000 if signing else 20_000)
    assert st.datagrams_rx >= sent  # every one was read and judged (plus the honest traffic)
    assert st.bad_frames > 0 and st.unknown_sysid > 0
    assert st.rejected_setpoints > 0  # the buggy-but-authentic NaN / 1e300 setpoints
    assert 0 < refused_answers < 0.4 * steps * len(sysids)  # those of the honest companions (20 % of steps)
    assert st.address_changes == 0 and all(server.armed(s) for s in sysids)
    assert {s: server.peer_address(s) for s in sysids} == homes
    if signing:
        assert st.unsigned > 0 and st.bad_signature > 0 and st.replayed > 0
    else:
        assert st.wrong_address > 0 and st.nonfinite_values > 0


@pytest.mark.parametrize("signing,steps,per_step", [(True, 500, 200), (False, 100, 200)], ids=["signed", "unsigned"])
def test_fuzz_companion_while_it_keeps_lockstep(signing, steps, per_step):
    sysid = 2
    captured: list[bytes] = []
    server = server_for([sysid], timeout_s=5.0, signing=signing, shim=_capture(captured))
    server.open()
    client = client_for(server, sysid, signing)
    seen: list[int] = []
    errors: list[BaseException] = []
    thread = threading.Thread(target=_honest, args=(client, sysid, seen, errors))
    rng = random.Random(54321)
    forge = _client_forge(signing, sysid)
    fuzzer = Fuzzer(rng, [forge(rng, 0) for _ in range(20)], forge, tamper_steps=signing)
    sent = 0
    t0 = time.monotonic()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as own:
        # signing on: from anywhere; off: from the simulator's own address (the client reads nothing else)
        try:
            thread.start()
            server.wait_for_peers(5.0)
            attacker = own if signing else server._link.transports[0].sock
            target = client.local_address
            for d in fuzzer.batch(per_step, 0):  # while it arms
                attacker.sendto(d, target)
                sent += 1
            server.wait_for_armed(5.0)
            fuzzer.captured = captured
            for k in range(steps):
                for d in fuzzer.batch(per_step, k):
                    attacker.sendto(d, target)
                sent += per_step
                frame = make_frame(sysid, k)
                got = server.exchange({sysid: frame})
                honest = answer(frame, sysid)
                assert got[sysid].thrust_n == honest.thrust_n
                assert got[sysid].tau_q_nm.tobytes() == honest.tau_q_nm.tobytes()
        finally:
            server.close("done")
            thread.join(5.0)
            client.close()
    elapsed = time.monotonic() - t0
    assert not errors, errors
    assert seen == list(range(steps))  # the controller saw every step once, no forged one
    st = client.stats
    print(f"\ncompanion fuzz ({'signed' if signing else 'unsigned'}): {sent} datagrams in {elapsed:.2f} s "
          f"({sent / elapsed:.0f}/s); {st}")  # fmt: skip
    assert sent >= (100_000 if signing else 20_000)
    assert st.datagrams_rx >= sent
    assert st.bad_frames > 0 and st.unknown_sysid > 0
    assert client.status_texts[-1][1] == "done"  # the genuine SHUTDOWN ended the run
    if signing:
        assert st.unsigned > 0 and st.bad_signature > 0 and st.replayed > 0
        assert all(t[1] != "forged" for t in client.status_texts)
    else:  # from the simulator's address nothing is authenticated, but invalid content still is caught
        assert st.rejected_frames > 0 and st.nonfinite_values > 0 and st.duplicate_frames > 0
