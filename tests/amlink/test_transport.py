"""The lockstep over every transport: TCP on loopback, serial through a pty pair, UDP either way
round, several at once; byte streams cut anywhere or with noise in them; a far end that never reads."""

from __future__ import annotations

import os
import random
import socket
import threading
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from amlink.lockstep import CompanionClient, SimServer
from amlink.stream import MAX_BACKLOG, _socket_stream, resolve
from amlink.types import AttitudeTarget
from amlink.protocol import LinkStats
from amlink.wire import SIGNATURE_LEN, Encoder, StreamFramer, split_frames
from tests.amlink import codec_reference as ref
from tests.amlink.kit import SCENARIO, answer, key_for, make_frame
from tests.amlink.ptys import pty_pair


def _genuine_frames(n: int, signed: bool) -> list[bytes]:
    """Sensor batches and setpoints as they go on the wire, cut into single frames."""
    enc = Encoder(1, 1, signing_key=key_for(2) if signed else None, link_id=2)
    out = []
    for k in range(n):
        out += split_frames(enc.pack(ref.sensor_frame_messages(make_frame(2, k), 7)))
        out += split_frames(enc.pack(ref.setpoint_messages(answer(make_frame(2, k), 2))))
    return out


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), signed=st.booleans())
def test_a_stream_cut_anywhere_with_noise_between_frames_gives_back_every_frame(seed, signed):
    rng = random.Random(seed)
    frames = _genuine_frames(4, signed)
    stream, junk = bytearray(), 0
    for f in frames:
        if rng.random() < 0.3:  # line noise, with the magic byte and cut-off frames in it
            # a frame cut off after its CRC (inside the signature) passes as whole and takes the next
            # frame's first bytes with it; the decoder rejects it, and both are lost (not tested here)
            cut = rng.randrange(1, len(f) - (SIGNATURE_LEN if signed else 0) - 2)
            noise = rng.choice([rng.randbytes(rng.randrange(1, 40)), b"\xfd" + rng.randbytes(rng.randrange(0, 30)),
                                f[:cut]])
            stream += noise
            junk += len(noise)
        stream += f
    # the line goes on after the last frame: noise that starts like a frame (0xfd and a large
    # length) holds the frames after it until enough bytes came to refute it, at most a whole
    # MAVLink 2 frame's worth (280 bytes); the quiet line's bytes are junk too
    tail = b"\x00" * 280
    stream += tail
    junk += len(tail)
    framer, out, i = StreamFramer(), b"", 0
    while i < len(stream):
        n = rng.randrange(1, 200)
        out += framer.feed(bytes(stream[i : i + n]))
        i += n
    assert split_frames(out) == frames
    assert framer.junk_bytes == junk


@pytest.fixture
def tcp_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _run_lockstep(binds, sims: dict[int, str], steps: int, signing: bool = False, before=None):
    """A SimServer on ``binds`` and one CompanionClient per sysid on ``sims[sysid]`` (threads),
    ``steps`` exchanges with attitude targets; returns (server stats, {sysid: steps seen})."""
    sysids = sorted(sims)
    keys = {s: key_for(s) for s in sysids} if signing else None
    server = SimServer(binds, sysids=sysids, scenario=SCENARIO, timeout_s=5.0, signing_keys=keys)
    server.open()
    seen = {s: [] for s in sysids}
    errors: list[BaseException] = []

    def companion(sysid: int) -> None:
        try:
            with CompanionClient(sysid, sim=sims[sysid], signing_key=keys[sysid] if keys else None) as c:
                c.connect(10.0)
                c.arm(5.0)
                while (frame := c.recv_frame(10.0)) is not None:
                    seen[sysid].append(frame.step)
                    c.send_setpoint(answer(frame, sysid), AttitudeTarget(frame.step, [1, 0, 0, 0], [0, 0, sysid], 0.5))
                assert c.status_texts[-1][1] == "done"
        except BaseException as exc:
            errors.append(exc)

    threads = [threading.Thread(target=companion, args=(s,)) for s in sysids]
    for t in threads:
        t.start()
    try:
        server.wait_for_peers(10.0)
        server.wait_for_armed(10.0)
        if before is not None:
            before(server)
        for k in range(steps):
            frames = {s: make_frame(s, k) for s in sysids}
            sps = server.exchange(frames)
            for s, sp in sps.items():
                assert sp.step == k and sp.thrust_n == 100.0 * s + k
                np.testing.assert_array_equal(sp.tau_q_nm, answer(frames[s], s).tau_q_nm)
                assert server.attitude_targets[s].step == k
    finally:
        server.close("done")
        for t in threads:
            t.join(10.0)
    assert not errors, errors
    return server.stats, seen


@pytest.mark.parametrize("signing", [False, True])
def test_lockstep_over_tcp_on_loopback(tcp_port, signing):
    stats, seen = _run_lockstep(f"tcpin:127.0.0.1:{tcp_port}", {2: f"tcp:127.0.0.1:{tcp_port}",
                                                                3: f"tcp:127.0.0.1:{tcp_port}"}, 200, signing)
    assert seen == {2: list(range(200)), 3: list(range(200))}
    assert stats.junk_bytes == 0 and stats.retransmits == 0


def test_lockstep_over_a_serial_line():
    with pty_pair() as (fc, companion):
        stats, seen = _run_lockstep(f"{fc}:921600", {2: f"{companion},921600"}, 200, signing=True)
    assert seen == {2: list(range(200))} and stats.junk_bytes == 0


def test_noise_on_the_serial_line_costs_retries_not_the_run():
    """Bytes injected into the simulator's side of the line mid-run are skipped and counted."""
    with pty_pair() as (fc, companion):
        def inject(server):
            fd = os.open(companion, os.O_WRONLY | os.O_NOCTTY)  # the companion's end: it arrives at the simulator
            try:
                os.write(fd, b"\xfd\x09\x00" + bytes(range(40)) + b"noise")
            finally:
                os.close(fd)

        stats, seen = _run_lockstep(fc, {2: companion}, 100, signing=True, before=inject)
    assert seen == {2: list(range(100))}
    assert stats.junk_bytes >= 48


def test_one_simulator_serves_udp_tcp_serial_and_a_listening_companion_at_once(tcp_port):
    with pty_pair() as (fc, companion), socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        listen_port = s.getsockname()[1]
        s.close()  # the companion binds it
        server_udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        server_udp.bind(("127.0.0.1", 0))
        udp_port = server_udp.getsockname()[1]
        server_udp.close()
        binds = [f"udpin:127.0.0.1:{udp_port}", f"tcpin:127.0.0.1:{tcp_port}", fc,
                 f"udpout:127.0.0.1:{listen_port}"]
        sims = {2: f"udpout:127.0.0.1:{udp_port}", 3: f"tcp:127.0.0.1:{tcp_port}", 4: companion,
                5: f"udpin:127.0.0.1:{listen_port}"}
        stats, seen = _run_lockstep(binds, sims, 100, signing=True)
    assert seen == {s: list(range(100)) for s in (2, 3, 4, 5)}


def test_a_stream_far_end_that_never_reads_never_blocks_the_sender():
    a, b = socket.socketpair()  # b is never read
    try:
        stats = LinkStats()
        conn = _socket_stream(a, stats)
        chunk = bytes(1000)
        t0 = time.monotonic()
        for _ in range(3 * MAX_BACKLOG // len(chunk)):
            conn.write(chunk)
        assert time.monotonic() - t0 < 2.0
        assert stats.send_drops > 0 and len(conn._out) <= MAX_BACKLOG
    finally:
        a.close()
        b.close()


def test_companion_told_to_reach_a_missing_device_fails_fast():
    c = CompanionClient(2, sim="/dev/does-not-exist:57600")
    with pytest.raises(Exception) as err:
        c.connect(5.0)
    assert "/dev/does-not-exist" in str(err.value)


def _ipv6_loopback() -> bool:
    try:
        with socket.socket(socket.AF_INET6, socket.SOCK_DGRAM) as s:
            s.bind(("::1", 0))
        return True
    except OSError:
        return False


@pytest.mark.skipif(not _ipv6_loopback(), reason="no IPv6 loopback")
def test_lockstep_over_ipv6_udp_and_tcp():
    with socket.socket(socket.AF_INET6, socket.SOCK_DGRAM) as u, socket.socket(socket.AF_INET6) as t:
        u.bind(("::1", 0))
        t.bind(("::1", 0))
        udp, tcp = u.getsockname()[1], t.getsockname()[1]
    stats, seen = _run_lockstep([f"udpin:[::1]:{udp}", f"tcpin:[::1]:{tcp}"],
                                {2: f"udpout:[::1]:{udp}", 3: f"tcp:[::1]:{tcp}"}, 50)
    assert seen == {2: list(range(50)), 3: list(range(50))}


def test_a_name_resolves_to_ipv4_first_as_mavutil_does():
    assert resolve("localhost", 14550, socket.SOCK_DGRAM)[0] == socket.AF_INET
    assert resolve("::1", 14550, socket.SOCK_DGRAM)[0] == socket.AF_INET6
