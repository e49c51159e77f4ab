"""Issue 5, distributed run: simulator, two companions and the ground station each in its
own network namespace (a host of its own), joined by virtual links through a switch, with
MAVLink and Zenoh endpoints given on the command line. The two-AM grasp must pass there as
it does on loopback, signed, with the log recorded on the ground-station host."""
from __future__ import annotations

import json
import subprocess

import pytest

from telemetry.keyfiles import write_run_keys

from . import netns
from .runner import SCENARIOS, script

pytestmark = pytest.mark.sitl

why_not = netns.available()


@pytest.mark.skipif(why_not is not None, reason=f"network namespaces unavailable: {why_not}")
def test_two_am_grasp_across_four_hosts(tmp_path):
    lan = netns.Lan(["sim", "c4", "c5", "gs"])
    procs: list[subprocess.Popen] = []
    try:
        key = tmp_path / "link.key"
        key.write_text("5a" * 32)
        cfg = str(SCENARIOS / "two_am_comp.toml")
        gs_endpoint = f"tcp/{lan.ip['gs']}:7447"
        sim_endpoint = f"udp:{lan.ip['sim']}:14550"
        mcap = tmp_path / "run.mcap"
        # the run's telemetry keys, as docs/architecture.md has them written for processes by hand
        tkeys = write_run_keys(tmp_path / "keys", (4, 5))
        rec = lan.popen("gs", [script("ground-station"), "record", "--out", str(mcap), "--zenoh-listen", gs_endpoint,
                               "--telemetry-key-file", str(tkeys["recorder"])],
                        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        procs.append(rec)
        # started by hand: each publisher waits for the recorder's subscription before its first
        # sample, as docs/telemetry.md says (zenoh drops what is put before the route exists)
        tele = ["--zenoh-connect", gs_endpoint, "--telemetry-wait", "30"]
        sim = lan.popen("sim", [script("simulator"), "--config", cfg, "--bind", "udp:0.0.0.0:14550", "--key-file",
                                str(key), "--run-dir", str(tmp_path), "--peer-timeout", "60", *tele,
                                "--telemetry-key-file", str(tkeys["simulator"])],
                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        procs.append(sim)
        comps = {s: lan.popen(f"c{s}", [script("companion"), "--sysid", str(s), "--sim", sim_endpoint, "--config", cfg,
                                          "--key-file", str(key), "--outcome", str(tmp_path / f"am{s}.json"), *tele,
                                          "--telemetry-key-file", str(tkeys[f"am{s}"])],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for s in (4, 5)}
        procs.extend(comps.values())
        out, err = sim.communicate(timeout=1500)
        assert sim.returncode == 0, err[-3000:]
        for s, c in comps.items():
            _, cerr = c.communicate(timeout=60)
            assert c.returncode == 0, cerr
            assert lan.ip["sim"] in cerr  # it really talked to the other host
        rec.communicate(timeout=60)
        o = json.loads((tmp_path / "outcome.json").read_text())
        assert o["object"]["hover_min_lift_m"] >= 0.2 and o["object"]["touching_in_hover"] == []
        share = 1.0 * 9.81 / 2
        for a in o["ams"].values():
            assert -a["hover_mean_ft_force_W_n"][2] == pytest.approx(share, rel=0.02)
            assert a["slip_max_m"] < 2e-3
        for s in (4, 5):
            c = json.loads((tmp_path / f"am{s}.json").read_text())
            assert c["at"]["approach_end"]["r_c_err"] < 5e-3 and c["at"]["end"]["r_c_err"] < 5e-3
        assert o["link"]["bad_signature"] == 0
        r = subprocess.run([script("ground-station"), "review", str(mcap), "--json"], capture_output=True, text=True,
                           timeout=300)
        rv = json.loads(r.stdout)
        assert rv["loss"]["missing"] == 0 and rv["ams"] == [4, 5]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
        lan.close()
