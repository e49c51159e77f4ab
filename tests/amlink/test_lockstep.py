"""Lockstep transport over loopback UDP: handshake, matching, timeouts, shutdown."""

from __future__ import annotations

import contextlib
import socket
import threading
import time

import numpy as np
import pytest

from amlink import codec
from amlink.codec import mav
from amlink.errors import (
    PeerMissingError,
    PeerTimeoutError,
    SimulatorTimeoutError,
    SimulatorUnreachableError,
)
from amlink.lockstep import CompanionClient, SimServer
from amlink.types import AttitudeSetpoint, AttitudeTarget, SensorFrame, StepFlag, TorqueSetpoint
from tests.amlink import codec_reference as ref
from tests.amlink.kit import SCENARIO, answer, key_for, linked, make_frame, server_for, url


def test_constructors_do_no_io():
    server = server_for([2, 3])
    with pytest.raises(RuntimeError):
        server.address
    client = CompanionClient(2, sim="udp:127.0.0.1:9")
    with pytest.raises(RuntimeError):
        client.recv_frame(0.0)
    with pytest.raises(ValueError):
        server_for([1, 2])  # sysid 1 is the simulator


def test_bind_all_interfaces_and_ephemeral_port():
    server = SimServer(bind="udpin:0.0.0.0:0", sysids=[2], scenario=SCENARIO)
    host, port = server.open()
    try:
        assert host == "0.0.0.0" and port > 0
        client = CompanionClient(2, sim=f"udp:127.0.0.1:{port}")
        t = threading.Thread(target=client.connect, args=(5.0,))
        t.start()
        server.wait_for_peers(5.0)
        t.join(5.0)
        assert client.scenario == SCENARIO
        client.close()
    finally:
        server.close()


@contextlib.contextmanager
def _armed_companions(server, on_frame):
    """Companions 2 and 3 in threads: each connects, arms and calls on_frame(client, frame,
    sysid) for every frame until the server ends the run. Yields a dict sysid -> (the
    scenario connect returned, the last STATUSTEXT) once both are armed (filled when they
    end); on leaving, closes the server with "done", joins them and re-raises their errors."""
    errors: list[BaseException] = []
    ends: dict[int, tuple] = {}

    def companion(sysid: int) -> None:
        try:
            with CompanionClient(sysid, sim=url(server)) as c:
                scenario = c.connect(5.0)
                c.arm(2.0)
                while (frame := c.recv_frame(5.0)) is not None:
                    on_frame(c, frame, sysid)
                ends[sysid] = (scenario, c.status_texts[-1][1] if c.status_texts else None)
        except BaseException as exc:  # reported by the main thread
            errors.append(exc)

    threads = [threading.Thread(target=companion, args=(s,)) for s in (2, 3)]
    for t in threads:
        t.start()
    try:
        server.wait_for_peers(5.0)
        server.wait_for_armed(5.0)
        yield ends
    finally:
        server.close("done")
        for t in threads:
            t.join(5.0)
    assert not errors, errors


def test_two_companions_200_lockstep_steps_matched_by_sysid_and_step():
    server = server_for([2, 3], timeout_s=2.0)
    server.open()
    received: dict[int, list[int]] = {2: [], 3: []}

    def on_frame(c, frame, sysid):
        received[sysid].append(frame.step)
        att = AttitudeTarget(frame.step, frame.quat_WB_wxyz, [0.0, 0.0, sysid], 0.5)
        c.send_setpoint(answer(frame, sysid), att)

    with _armed_companions(server, on_frame) as ends:
        assert server.armed(2) and server.armed(3)
        for k in range(200):
            frames = {s: make_frame(s, k) for s in (2, 3)}
            sps = server.exchange(frames)
            assert set(sps) == {2, 3}
            for s, sp in sps.items():
                expect = answer(frames[s], s)
                assert sp.step == k and sp.thrust_n == 100.0 * s + k
                np.testing.assert_array_equal(sp.tau_q_nm, expect.tau_q_nm)  # float64: exact
                np.testing.assert_array_equal(sp.tau_B_nm, expect.tau_B_nm)
                assert server.attitude_targets[s].step == k
                assert server.attitude_targets[s].rates_rad_s[2] == pytest.approx(s)
    assert ends == {2: (SCENARIO, "done"), 3: (SCENARIO, "done")}
    assert received == {2: list(range(200)), 3: list(range(200))}
    assert server.stats.stale_setpoints == server.stats.unknown_sysid == server.stats.bad_frames == 0


def test_attitude_mode_setpoints_travel_as_attitude_target_and_joint_torques():
    """Attitude mode: SET_ATTITUDE_TARGET + AM_JOINT_TORQUE_SETPOINT in one datagram, read as
    one AttitudeSetpoint; a joint message alone is rejected and the step keeps waiting."""
    server = server_for([2, 3], timeout_s=2.0)
    server.open()

    def attitude_answer(frame, sysid):
        att = AttitudeTarget(frame.step, [np.cos(0.1 * sysid), 0.0, np.sin(0.1 * sysid), 0.0], [0.1, -0.2, sysid], 0.25)
        return AttitudeSetpoint(frame.step, att, frame.q * 3.0)

    with _armed_companions(server, lambda c, frame, sysid: c.send_setpoint(attitude_answer(frame, sysid))):
        for k in range(50):
            frames = {s: make_frame(s, k) for s in (2, 3)}
            for s, sp in server.exchange(frames).items():
                want = attitude_answer(frames[s], s)
                assert isinstance(sp, AttitudeSetpoint) and sp.step == sp.attitude.step == k
                np.testing.assert_array_equal(sp.tau_q_nm, want.tau_q_nm)  # float64: exact
                np.testing.assert_allclose(sp.attitude.quat_wxyz, want.attitude.quat_wxyz, atol=1e-7)  # float32
                np.testing.assert_allclose(sp.attitude.rates_rad_s, want.attitude.rates_rad_s, rtol=1e-7)
                assert sp.attitude.thrust_normalized == 0.25 and server.attitude_targets[s] is sp.attitude
    with linked([2], timeout_s=0.3) as (server, clients):
        joints_only = mav.MAVLink_am_joint_torque_setpoint_message(0, 2, [0.1, 0.2] + [0.0] * 6, 0)
        clients[2]._send([joints_only])
        assert server.exchange({2: make_frame(2, 0)}) == {}  # answered, as rejected
        assert server.stats.rejected_setpoints == 1 and "without SET_ATTITUDE_TARGET" in server.last_rejected[0][1]


def test_lazy_frames_leave_one_by_one_and_each_setpoint_is_handed_on_as_it_arrives():
    server = server_for([2, 3], timeout_s=2.0)
    server.open()
    with _armed_companions(server, lambda c, frame, sysid: c.send_setpoint(answer(frame, sysid))):
        for k in range(50):
            sent_before: list[int] = []

            def lazily():
                for s in (2, 3):
                    sent_before.append(server.stats.datagrams_tx)
                    yield s, make_frame(s, k)

            arrived: list[tuple[int, TorqueSetpoint]] = []
            sps = server.exchange(lazily(), partial=True, on_setpoint=lambda s, sp: arrived.append((s, sp)))
            assert sent_before[1] == sent_before[0] + 1  # frame 2 was out before frame 3 was produced
            assert sorted(s for s, _ in arrived) == [2, 3] and all(sps[s] is sp for s, sp in arrived)
            assert all(sp.step == k for sp in sps.values())


def test_missing_peer_raises_naming_it_within_timeout():
    server = server_for([2, 3, 4])
    server.open()
    client = CompanionClient(3, sim=url(server))
    t = threading.Thread(target=client.connect, args=(5.0,))
    t.start()
    t0 = time.monotonic()
    try:
        with pytest.raises(PeerMissingError) as err:
            server.wait_for_peers(0.5)
        assert time.monotonic() - t0 < 2.0
        assert err.value.sysids == (2, 4)
        assert "sysid 2" in str(err.value) and "sysid 4" in str(err.value) and "sysid 3" not in str(err.value)
    finally:
        t.join(5.0)
        server.close()
        client.close()


def test_simulator_unreachable_names_address():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:  # bound, never answers
        silent.bind(("127.0.0.1", 0))
        address = f"udp:127.0.0.1:{silent.getsockname()[1]}"
        client = CompanionClient(2, sim=address)
        t0 = time.monotonic()
        with pytest.raises(SimulatorUnreachableError) as err:
            client.connect(0.6)
        assert 0.5 < time.monotonic() - t0 < 2.0
        assert address in str(err.value)
        assert len(_drain(silent)) >= 2  # it kept saying HEARTBEAT at ~2 Hz
        client.close()


def test_an_endpoint_that_cannot_be_opened_says_so_at_once_not_that_heartbeat_went_unanswered(tmp_path):
    """No such serial device: the reason is the OS's, given at once, and nothing about a
    HEARTBEAT (none was sent) or a timeout."""
    from amlink.client import EndpointOpenError

    device = f"{tmp_path / 'no_such_tty'}:115200"
    client = CompanionClient(2, sim=device)
    t0 = time.monotonic()
    with pytest.raises(EndpointOpenError) as err:
        client.connect(5.0)
    assert time.monotonic() - t0 < 1.0
    assert str(err.value) == f"cannot open {device}: No such file or directory"
    assert err.value.address == device and err.value.timeout_s is None
    assert isinstance(err.value, SimulatorUnreachableError)  # what callers of connect() catch


def test_a_tcp_simulator_never_connected_to_is_a_connection_failure_not_an_unanswered_heartbeat():
    with socket.socket() as s:  # a free port nobody listens on
        s.bind(("127.0.0.1", 0))
        address = f"tcp:127.0.0.1:{s.getsockname()[1]}"
    from amlink.client import EndpointOpenError

    client = CompanionClient(2, sim=address)
    with pytest.raises(EndpointOpenError) as err:
        client.connect(0.5)
    assert str(err.value) == f"cannot connect to {address} within 0.5 s: Connection refused"
    assert err.value.timeout_s == 0.5


@pytest.mark.parametrize("form", ["udpin", "tcpin"])
def test_a_listening_companion_nobody_reaches_says_so_not_that_heartbeat_went_unanswered(form):
    """Listening, it sends nothing until the simulator speaks: the error says nobody came."""
    client = CompanionClient(2, sim=f"{form}:127.0.0.1:0")
    with pytest.raises(SimulatorUnreachableError) as err:
        client.connect(0.3)
    assert err.value.listening and "HEARTBEAT" not in str(err.value)
    assert str(err.value).startswith(f"no simulator reached {form}:127.0.0.1:0 within 0.3 s")


def _drain(sock):
    sock.setblocking(False)
    out = []
    with contextlib.suppress(BlockingIOError):
        while True:
            out.append(sock.recv(65535))
    return out


def test_companion_that_stops_answering_raises_peer_timeout():
    with linked([2, 3], timeout_s=0.3) as (server, clients):
        for s, c in clients.items():  # both answer step 0 (pre-queued in the socket)
            c.send_setpoint(answer(make_frame(s, 0), s))
        assert set(server.exchange({s: make_frame(s, 0) for s in clients})) == {2, 3}
        clients[2].send_setpoint(answer(make_frame(2, 1), 2))  # sysid 3 goes silent
        t0 = time.monotonic()
        with pytest.raises(PeerTimeoutError) as err:
            server.exchange({s: make_frame(s, 1) for s in clients})
        assert 0.25 < time.monotonic() - t0 < 1.5
        assert (err.value.sysid, err.value.step, err.value.missing) == (3, 1, (3,))


def test_stale_duplicate_wrong_step_and_unknown_sysid_are_ignored_and_counted():
    with linked([2]) as (server, clients):
        c = clients[2]
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
            enc9 = codec.Encoder(9, 191)
            sp = lambda step, thrust: TorqueSetpoint(step, thrust, [0, 0, 0], [])  # noqa: E731
            c.send_setpoint(sp(4, -1.0))  # stale
            c.send_setpoint(sp(6, -2.0))  # a step not sent yet
            raw.sendto(enc9.pack(ref.setpoint_messages(sp(5, -3.0))), server.address)  # sysid 9: unknown
            c.send_setpoint(sp(5, 55.0))  # the real answer
            c.send_setpoint(sp(5, -4.0))  # duplicate
            got = server.exchange({2: make_frame(2, 5)})
        assert got[2].step == 5 and got[2].thrust_n == 55.0
        st = server.stats
        assert (st.stale_setpoints, st.wrong_step_setpoints, st.duplicate_setpoints, st.unknown_sysid) == (1, 1, 1, 1)
        assert server.peer_address(2) == ("127.0.0.1", c.local_address[1])
        assert c.recv_frame(1.0).step == 5


def test_unknown_sysid_does_not_steal_a_peer_address():
    with linked([2]) as (server, clients):
        before = server.peer_address(2)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
            raw.sendto(codec.Encoder(9, 191).pack([mav.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3)]), server.address)
            clients[2].send_setpoint(TorqueSetpoint(0, 1.0, [0, 0, 0], []))
            server.exchange({2: make_frame(2, 0)})
        assert server.peer_address(2) == before and server.stats.unknown_sysid == 1


def test_non_finite_or_implausible_setpoint_answers_the_step_at_once_as_rejected():
    """Changed behaviour: a refused answer used to leave the step waiting for the timeout
    (a stalled lockstep); now it answers the step, is not returned, and is reported in
    last_rejected for the caller's policy (hold the last command, failsafe after K in a row)."""
    with linked([2, 3], timeout_s=2.0) as (server, clients):
        nan = mav.MAVLink_am_torque_setpoint_message(0, float("nan"), [0.0] * 3, 0, [0.0] * 8, 0)
        huge = mav.MAVLink_am_torque_setpoint_message(0, 1e300, [0.0] * 3, 0, [0.0] * 8, 0)
        clients[3]._send([huge])
        clients[2]._send([nan])  # bypass the encoder's own finite check
        clients[2]._send([huge])  # a second answer to the same step: a duplicate
        t0 = time.monotonic()
        got = server.exchange({2: make_frame(2, 0), 3: make_frame(3, 0)}, partial=True)
        assert time.monotonic() - t0 < 1.0  # no wait for the 2 s timeout
        assert got == {} and server.last_missing == (2, 3) and not server.lost_peers
        assert [s for s, _ in server.last_rejected] == [2, 3]  # in the order of the frames, not of arrival
        assert "thrust_n" in server.last_rejected[0][1] and "thrust_n" in server.last_rejected[1][1]
        assert (server.stats.rejected_setpoints, server.stats.nonfinite_values) == (3, 1)
        assert server.stats.duplicate_setpoints == 1
        clients[2].send_setpoint(answer(make_frame(2, 1), 2))
        clients[3].send_setpoint(answer(make_frame(3, 1), 3))
        got = server.exchange({2: make_frame(2, 1), 3: make_frame(3, 1)})
        assert got[2].thrust_n == 201.0 and server.last_rejected == ()


def test_a_nan_setpoint_from_another_address_with_the_key_does_not_divert_frames():
    """Signing on: a key holder sending NaN (or implausible) setpoints from elsewhere is refused
    before the address policy acts: the peer keeps its address, its frames keep reaching it, the
    forged packet answers no step, and the real companion's answer is taken."""
    with linked([2], timeout_s=1.0, signing=True) as (server, clients):
        real = clients[2]
        before = server.peer_address(2)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other:
            other.bind(("127.0.0.1", 0))
            enc = codec.Encoder(2, 191, signing_key=key_for(2), link_id=2)
            for step in range(3):
                nan = mav.MAVLink_am_torque_setpoint_message(step, float("nan"), [0.0] * 3, 0, [0.0] * 8, 0)
                huge = mav.MAVLink_am_torque_setpoint_message(step, 1e300, [0.0] * 3, 0, [0.0] * 8, 0)
                other.sendto(enc.pack([nan]), server.address)
                other.sendto(enc.pack([huge]), server.address)
                frame = make_frame(2, step)
                t = threading.Timer(0.05, real.send_setpoint, args=(answer(frame, 2),))
                t.start()
                got = server.exchange({2: frame})
                t.join()
                assert got[2].thrust_n == 200.0 + step and server.last_rejected == ()
                assert server.peer_address(2) == before
                assert real.recv_frame(1.0).step == step  # the frame went to the real companion
            assert server.stats.address_changes == 0 and server.stats.rejected_setpoints == 6
            assert server.stats.wrong_address == 6
            other.settimeout(0.2)
            with pytest.raises(socket.timeout):
                other.recv(65535)  # nothing was diverted to the forger


def test_shutdown_flag_makes_recv_frame_return_none():
    with linked([2]) as (server, clients):
        c = clients[2]
        c.send_setpoint(answer(make_frame(2, 0), 2))
        server.exchange({2: make_frame(2, 0)})
        assert c.recv_frame(1.0).step == 0
        server.close("scenario finished", error=False)
        assert c.recv_frame(1.0) is None
        assert c.recv_frame(0.0) is None  # stays ended, no timeout
        assert c.status_texts[-1] == (mav.MAV_SEVERITY_NOTICE, "scenario finished")


def test_recv_frame_times_out_when_simulator_is_silent():
    with linked([2]) as (_server, clients):
        t0 = time.monotonic()
        with pytest.raises(SimulatorTimeoutError):
            clients[2].recv_frame(0.2)
        assert time.monotonic() - t0 < 1.0


def test_failsafe_flag_reaches_the_companion():
    with linked([2]) as (server, clients):
        frame = make_frame(2, 0)
        frame = SensorFrame(**{**frame.__dict__, "flags": StepFlag.FAILSAFE})
        clients[2].send_setpoint(answer(frame, 2))
        server.exchange({2: frame})
        assert clients[2].recv_frame(1.0).flags == StepFlag.FAILSAFE


def test_server_follows_a_peer_to_its_latest_address():
    """Signing on: a companion whose source address changes (restart, NAT rebinding) is followed.

    Changed behaviour: this used to hold with signing off too; see the next test.
    """
    with linked([2], signing=True) as (server, clients):
        old = clients[2]
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as moved:
            moved.bind(("127.0.0.1", 0))
            moved.settimeout(1.0)
            enc = codec.Encoder(2, 191, signing_key=key_for(2), link_id=2)
            moved.sendto(enc.pack(ref.setpoint_messages(answer(make_frame(2, 0), 2))), server.address)
            server.exchange({2: make_frame(2, 0)})  # step 0 went out to the old address
            assert old.recv_frame(1.0).step == 0
            assert server.peer_address(2) == moved.getsockname()
            moved.sendto(enc.pack(ref.setpoint_messages(answer(make_frame(2, 1), 2))), server.address)
            server.exchange({2: make_frame(2, 1)})  # step 1 goes to the new address
            msgs = codec.Decoder({1: key_for(2)}).feed(moved.recv(65535))
            assert [m.get_type() for m in msgs][-1] == "AM_SIM_STEP" and msgs[-1].step == 1


def test_signing_off_only_heartbeat_from_a_silent_peer_moves_it_and_a_rejoin_disarms(monkeypatch):
    monkeypatch.setattr("amlink.server.REJOIN_QUIET_S", 0.2)
    with linked([2], timeout_s=0.3) as (server, clients):
        t = threading.Thread(target=clients[2].arm, args=(2.0,))
        t.start()
        server.wait_for_armed(2.0)
        t.join(2.0)
        assert server.armed(2)
        before = server.peer_address(2)
        heartbeat = mav.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as moved:
            moved.bind(("127.0.0.1", 0))
            enc = codec.Encoder(2, 191)
            moved.sendto(enc.pack([heartbeat]), server.address)  # the peer was heard just now: refused
            moved.sendto(enc.pack(ref.setpoint_messages(answer(make_frame(2, 0), 2))), server.address)
            with pytest.raises(PeerTimeoutError):
                server.exchange({2: make_frame(2, 0)})
            assert server.peer_address(2) == before and server.stats.wrong_address == 2
            time.sleep(0.25)  # silent long enough: a restarted companion may take its sysid
            moved.sendto(enc.pack([heartbeat]), server.address)
            moved.sendto(enc.pack(ref.setpoint_messages(answer(make_frame(2, 1), 2))), server.address)
            assert server.exchange({2: make_frame(2, 1)})[2].step == 1
            assert server.peer_address(2) == moved.getsockname()
            assert (server.stats.rejoins, server.stats.address_changes) == (1, 1)
            assert not server.armed(2)  # a restarted companion arms again


def test_a_companion_waits_while_its_simulator_gathers_the_others_and_hears_whom_it_waits_for(monkeypatch):
    """Companion 3 is armed, sysid 2 never shows up: the simulator tells 3 whom it waits for
    every notice period, and 3's first-frame wait (0.5 s here, shorter than the simulator's
    1.6 s) lasts as long as the notices come; the simulator then gives up and ends the run,
    and 3 hears that instead of timing out."""
    import amlink.server

    monkeypatch.setattr(amlink.server, "WAITING_NOTICE_PERIOD_S", 0.2)
    server = server_for([2, 3])
    server.open()
    client = CompanionClient(3, sim=url(server))
    heard: list[str] = []
    outcome: list = []

    def companion():
        try:
            client.connect(5.0)
            client.arm(2.0)
            outcome.append(client.recv_frame(0.5, on_waiting=heard.append))
        except BaseException as exc:  # noqa: BLE001 - reported by the assertion below
            outcome.append(exc)

    t = threading.Thread(target=companion)
    t.start()
    said: list[str] = []
    try:
        with pytest.raises(PeerMissingError):
            server.wait_for_peers(1.6, on_waiting=said.append)
        server.close("no HEARTBEAT from sysid 2", error=True)
    finally:
        t.join(5.0)
        client.close()
    assert outcome == [None], outcome  # the run's end, not a SimulatorTimeoutError
    assert len(heard) >= 4 and heard == said[:len(heard)]
    assert heard[0].startswith("waiting ") and heard[0].endswith("s more for HEARTBEAT from sysid 2")
    assert client.status_texts[-1] == (mav.MAV_SEVERITY_ERROR, "no HEARTBEAT from sysid 2")


def test_a_simulator_that_goes_silent_after_its_notices_times_the_companion_out(monkeypatch):
    import amlink.server

    monkeypatch.setattr(amlink.server, "WAITING_NOTICE_PERIOD_S", 0.1)
    server = server_for([2, 3])
    server.open()
    client = CompanionClient(3, sim=url(server))
    t = threading.Thread(target=lambda: (client.connect(5.0), client.arm(2.0)))
    t.start()
    try:
        with pytest.raises(PeerMissingError):
            server.wait_for_peers(0.5)
        t.join(5.0)
        t0 = time.monotonic()
        with pytest.raises(SimulatorTimeoutError, match="its last: 'waiting .* for HEARTBEAT from sysid 2'"):
            client.recv_frame(0.4)
        assert 0.3 < time.monotonic() - t0 < 1.5
    finally:
        server.close()
        client.close()


def test_set_message_interval_is_recorded_for_the_sensor_batch_and_denied_for_the_rest():
    """A companion asks for the batch's messages at its control rate (as one asks PX4 for
    ODOMETRY and ATTITUDE_TARGET above their onboard defaults): accepted and recorded; a
    message the simulator does not stream is denied."""
    from amlink.codec import mav
    from amlink.errors import CommandRejectedError

    server = server_for([2], timeout_s=2.0)
    server.open()
    outcome = {}

    def companion():
        try:
            with CompanionClient(2, sim=url(server)) as c:
                c.connect(5.0)
                for msgid in (mav.MAVLINK_MSG_ID_ODOMETRY, mav.MAVLINK_MSG_ID_ATTITUDE_TARGET):
                    c.set_message_interval(msgid, 4000.0, timeout_s=2.0)
                try:
                    c.set_message_interval(mav.MAVLINK_MSG_ID_HIGHRES_IMU, 4000.0, timeout_s=2.0)
                except CommandRejectedError as e:
                    outcome["denied"] = e.result
                c.arm(2.0)  # the server answers the commands while it waits for this
        except BaseException as exc:  # reported by the main thread
            outcome["error"] = exc

    t = threading.Thread(target=companion)
    t.start()
    try:
        server.wait_for_peers(5.0)
        server.wait_for_armed(5.0)
    finally:
        server.close("done")
        t.join(5.0)
    assert "error" not in outcome, outcome
    assert outcome["denied"] == mav.MAV_RESULT_DENIED
    assert server._peers[2].intervals == {mav.MAVLINK_MSG_ID_ODOMETRY: 4000.0,
                                          mav.MAVLINK_MSG_ID_ATTITUDE_TARGET: 4000.0}
