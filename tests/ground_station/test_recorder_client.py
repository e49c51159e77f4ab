"""The recorder as a zenoh client (through a router): it waits for a router that is not
there yet, as the publishers do, instead of failing at start (docs/telemetry.md)."""
from __future__ import annotations

import json
import subprocess
import sys
import threading
import time

import pytest
import zenoh

from ground_station.recorder import Recorder, RecorderError
from telemetry.schema import Keys
from telemetry.session import ZenohOptions, build_config

from ..telemetry.zenoh_testing import free_endpoint
from .conftest import message_of


def test_a_client_recorder_started_before_its_router_records_once_the_router_appears(tmp_path):
    endpoint = free_endpoint()
    opts = ZenohOptions(role="recorder", mode="client", connect=(endpoint,), listen=())
    told = []
    rec = Recorder(tmp_path / "late_router.mcap", opts, notify=told.append)
    rec.open()  # no router: does not raise, keeps retrying
    router = None
    try:
        assert not rec.connected and endpoint.split("/", 1)[1] in rec.waiting_for_router
        stop = threading.Event()
        runner = threading.Thread(target=rec.run, kwargs={"stop": stop})
        runner.start()
        time.sleep(0.6)  # a few of the client's retries fail first
        assert runner.is_alive() and not rec.connected
        router = zenoh.open(build_config(ZenohOptions(role="recorder", mode="router", listen=(endpoint,),
                                                      connect=())))
        key = Keys().controller(4)
        deadline = time.monotonic() + 8.0
        while rec.summary().received == 0 and time.monotonic() < deadline:
            router.put(key, message_of({"t": 0.0, "seq": 0}))
            time.sleep(0.1)
        stop.set()
        runner.join(5.0)
    finally:
        summary = rec.close()
        if router is not None:
            router.close()
    assert summary.connected and summary.received >= 1, summary
    assert rec.waiting_for_router is None and told == [f"zenoh: connected to {endpoint}"]


def test_a_client_recorder_without_any_endpoint_still_fails_at_once(tmp_path):
    """Only a router that does not answer is waited for; a session zenoh cannot make at all is an error."""
    rec = Recorder(tmp_path / "x.mcap", ZenohOptions(role="recorder", mode="client", connect=(), listen=()))
    with pytest.raises(RecorderError, match="zenoh: No peer specified"):
        rec.open()


def test_record_in_client_mode_without_a_router_waits_then_says_it_never_reached_it(tmp_path):
    endpoint = free_endpoint()
    r = subprocess.run([sys.executable, "-m", "ground_station", "record", "--insecure", "--out", str(tmp_path / "c.mcap"),
                        "--zenoh-mode", "client", "--zenoh-connect", endpoint, "--zenoh-listen", "none",
                        "--duration", "1.5", "--summary-json"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["stop_reason"] == "duration" and summary["connected"] is False
    assert f"no router answers yet (Unable to connect to any of [Single({endpoint})]!); retrying" in r.stderr
    assert f"warning: zenoh: never reached {endpoint}" in r.stderr
    assert "listen none," in r.stderr and "Traceback" not in r.stderr
