"""Lockstep over a lossy socket path (retransmission) and with dead companions (partial exchange, rejoin)."""

from __future__ import annotations

import threading
import time

import pytest

from amlink.errors import SimulatorTimeoutError
from amlink.shim import LossyShim
from tests.amlink.kit import answer, client_for, make_frame, server_for

SYSIDS = (2, 3)


def _companion(client, sysid, seen, errors, stop=None, last_step=None):
    """Answer frames until shutdown (or ``stop``); a lost SHUTDOWN after ``last_step`` also ends it."""
    try:
        client.connect(5.0)
        client.arm(5.0)
        while stop is None or not stop.is_set():
            done = last_step is not None and seen and seen[-1] == last_step
            try:
                frame = client.recv_frame(0.5 if done else 5.0 if stop is None else 0.1)
            except SimulatorTimeoutError:
                if done:
                    return  # all SHUTDOWN copies lost: the run is over anyway
                if stop is not None:
                    continue
                raise
            if frame is None:
                return
            seen.append(frame.step)
            client.send_setpoint(answer(frame, sysid))
    except BaseException as exc:  # reported by the main thread
        errors.append(exc)


def run_lockstep(steps: int, signing: bool, impair: dict | None, retry_s: float = 0.002):
    """Run ``steps`` lockstep steps; returns (setpoint bytes per step, frames each companion saw, stats)."""
    shim = (lambda seed: LossyShim(**impair, seed=seed)) if impair else (lambda seed: None)
    server = server_for(SYSIDS, timeout_s=5.0, signing=signing, retry_s=retry_s, shim=shim(1))
    server.open()
    clients = {s: client_for(server, s, signing, shim=shim(s)) for s in SYSIDS}
    seen: dict[int, list[int]] = {s: [] for s in SYSIDS}
    errors: list[BaseException] = []
    threads = [threading.Thread(target=_companion, args=(clients[s], s, seen[s], errors, None, steps - 1))
               for s in SYSIDS]  # fmt: skip
    record = []
    try:
        for t in threads:
            t.start()
        server.wait_for_peers(10.0)
        server.wait_for_armed(10.0)
        for k in range(steps):
            got = server.exchange({s: make_frame(s, k) for s in SYSIDS})
            record.append(tuple((s, sp.step, sp.thrust_n, sp.tau_B_nm.tobytes(), sp.tau_q_nm.tobytes())
                                for s, sp in sorted(got.items())))  # fmt: skip
    finally:
        server.close("done")
        for t in threads:
            t.join(10.0)
        for c in clients.values():
            c.close()
    assert not errors, errors
    return record, seen, server.stats, {s: c.stats for s, c in clients.items()}


@pytest.mark.parametrize("signing", [True, False], ids=["signed", "unsigned"])
def test_lossy_duplicating_reordering_link_gives_bit_identical_setpoints(signing):
    steps = 500 if signing else 200
    clean, clean_seen, _, _ = run_lockstep(steps, signing, None)
    t0 = time.monotonic()
    lossy, lossy_seen, st, client_stats = run_lockstep(
        steps, signing, dict(loss=0.2, duplicate=0.1, reorder=0.1))
    elapsed = time.monotonic() - t0
    assert len(lossy) == steps and lossy == clean  # bit-identical setpoints
    assert lossy_seen == clean_seen == {s: list(range(steps)) for s in SYSIDS}  # each step seen once
    assert st.retransmits > 0 and sum(c.retransmits for c in client_stats.values()) > 0
    assert sum(c.duplicate_frames for c in client_stats.values()) > 0
    if signing:  # a duplicate or late datagram is a replay to the signature check
        assert st.replayed + sum(c.replayed for c in client_stats.values()) > 0
    assert elapsed < 30.0


def test_dead_companion_is_reported_missing_others_continue_and_a_restart_rejoins():
    server = server_for(SYSIDS, timeout_s=0.3, signing=True)
    server.open()
    errors: list[BaseException] = []
    stops = {s: threading.Event() for s in SYSIDS}
    old = {s: client_for(server, s, signing=True) for s in SYSIDS}
    threads = [threading.Thread(target=_companion, args=(old[s], s, [], errors, stops[s])) for s in SYSIDS]
    new3 = client_for(server, 3, signing=True)
    stop_new3 = threading.Event()
    t3 = threading.Thread(target=_companion, args=(new3, 3, [], errors, stop_new3))
    threads.append(t3)
    k = 0

    def step(**kw):
        nonlocal k
        t0 = time.monotonic()
        got = server.exchange({s: make_frame(s, k) for s in SYSIDS}, partial=True, **kw)
        for s, sp in got.items():
            assert sp.step == k and sp.thrust_n == 100.0 * s + k
        k += 1
        return set(got), time.monotonic() - t0

    try:
        for t in threads[:2]:
            t.start()
        server.wait_for_peers(5.0)
        server.wait_for_armed(5.0)
        for _ in range(5):
            assert step()[0] == {2, 3} and server.last_missing == ()
        stops[3].set()  # companion 3 hangs: socket open, no more answers
        threads[1].join(2.0)
        got, dt = step()
        assert got == {2} and server.last_missing == (3,) and server.lost_peers == {3}
        assert 0.25 < dt < 1.0  # reported within the timeout
        for _ in range(5):  # the others are no longer held up by it
            got, dt = step()
            assert got == {2} and server.last_missing == (3,) and dt < 0.2
        t3.start()  # restarted companion 3: new socket, HEARTBEAT, AM_SCENARIO, ARM
        for _ in range(200):
            got, _dt = step()
            if got == {2, 3}:
                break
        assert got == {2, 3} and server.lost_peers == frozenset()
        assert server.peer_address(3) == ("127.0.0.1", new3.local_address[1]) and server.armed(3)
        assert server.stats.rejoins == 1 and server.stats.peers_lost == 1
        for _ in range(20):
            assert step()[0] == {2, 3}
        assert not errors, errors
    finally:
        for e in (*stops.values(), stop_new3):
            e.set()
        server.close("done")
        for t in threads:
            if t.ident is not None:
                t.join(2.0)
        for c in (*old.values(), new3):
            c.close()
