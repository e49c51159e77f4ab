"""The shipped zenoh config files: they load, and TLS with mutual authentication plus the
recorder's access control let the fleet's certificates in and keep others out."""
from __future__ import annotations

import shutil
import subprocess
import time
from pathlib import Path

import pytest
import zenoh

from telemetry.publisher import TelemetryPublisher
from telemetry.schema import samples_of
from telemetry.session import ZenohOptions, build_config

from .zenoh_testing import free_endpoint

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = sorted((ROOT / "configs" / "zenoh").glob("*.json5"))


@pytest.mark.parametrize("path", CONFIGS, ids=[p.name for p in CONFIGS])
def test_shipped_configs_load(path):
    build_config(ZenohOptions(config_file=path))  # zenoh rejects unknown or mistyped keys


@pytest.mark.parametrize("name,key", [("recorder-tls.json5", "root_ca_certificate"),
                                      ("publisher-tls.json5", "root_ca_certificate")])
def test_a_tls_file_that_is_not_there_is_named_before_any_session_opens(name, key, tmp_path):
    """zenoh's own error names neither the key nor the file; the shipped configs' example paths
    (/etc/amstack/tls/...) are not on this machine."""
    from ground_station.recorder import Recorder
    from telemetry.session import TelemetryConfigError

    path = ROOT / "configs" / "zenoh" / name
    assert not Path("/etc/amstack/tls/ca.pem").exists()
    words = f"transport.link.tls.{key}: /etc/amstack/tls/ca.pem: no such file"
    with pytest.raises(TelemetryConfigError, match=words):
        TelemetryPublisher(ZenohOptions(config_file=path))
    with pytest.raises(TelemetryConfigError, match=words):
        Recorder(tmp_path / "r.mcap", ZenohOptions(role="recorder", config_file=path)).open()
    assert not (tmp_path / "r.mcap").exists()  # refused before the log was created


def _certificates(d: Path) -> None:
    """A throw-away CA and certificates for localhost with the given common names."""
    def run(*args):
        subprocess.run(["openssl", *args], cwd=d, check=True, capture_output=True, timeout=60)

    run("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca-key.pem", "-out", "ca.pem", "-days", "1",
        "-subj", "/CN=amstack-test-ca")
    (d / "ext").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\nbasicConstraints=CA:FALSE\n")
    for name, cn in (("gs", "ground-station"), ("companion", "companion"), ("intruder", "intruder")):
        run("req", "-newkey", "rsa:2048", "-nodes", "-keyout", f"{name}-key.pem", "-out", f"{name}.csr", "-subj",
            f"/CN={cn}")
        run("x509", "-req", "-in", f"{name}.csr", "-CA", "ca.pem", "-CAkey", "ca-key.pem", "-CAcreateserial",
            "-out", f"{name}.pem", "-days", "1", "-extfile", "ext")


def _localized(src: Path, dst: Path, d: Path, cert: str, acl: bool = True) -> Path:
    text = src.read_text().replace("/etc/amstack/tls/ca.pem", str(d / "ca.pem"))
    for tail in ("ground-station", "companion"):
        text = text.replace(f"/etc/amstack/tls/{tail}-key.pem", str(d / f"{cert}-key.pem"))
        text = text.replace(f"/etc/amstack/tls/{tail}.pem", str(d / f"{cert}.pem"))
    if not acl:
        text = text.replace("enabled: true,\n    default_permission", "enabled: false,\n    default_permission")
    dst.write_text(text)
    return dst


@pytest.fixture(scope="module")
def certs(tmp_path_factory):
    if shutil.which("openssl") is None:
        pytest.skip("needs openssl to make certificates")
    d = tmp_path_factory.mktemp("tls")
    _certificates(d)
    return d


@pytest.mark.parametrize("acl", [True, False], ids=["acl", "no-acl"])
def test_mtls_and_acl_admit_the_fleet_only(certs, tmp_path, acl):
    ep = free_endpoint().replace("tcp/127.0.0.1", "tls/localhost")
    rec_cfg = _localized(ROOT / "configs/zenoh/recorder-tls.json5", tmp_path / "rec.json5", certs, "gs", acl=acl)
    got: list[bytes] = []
    with zenoh.open(build_config(ZenohOptions(role="recorder", config_file=rec_cfg, listen=(ep,)))) as s:
        sub = s.declare_subscriber("amstack/**", lambda x: got.extend(samples_of(x.payload.to_bytes())))
        sent = {}
        for who in ("companion", "intruder"):
            cfg = _localized(ROOT / "configs/zenoh/publisher-tls.json5", tmp_path / f"{who}.json5", certs, who)
            pub = TelemetryPublisher(ZenohOptions(config_file=cfg, connect=(ep,)))
            pub.open()
            pub.wait_for_subscriber("amstack/am/4/controller", 3.0 if who == "companion" or not acl else 1.0)
            for i in range(5):
                pub.publish("amstack/am/4/controller", {"t": float(i), "seq": 0, "who": who})
            time.sleep(0.3)
            sent[who] = pub.close(5.0).sent
        deadline = time.monotonic() + 3.0
        while len(got) < (10 if not acl else 5) and time.monotonic() < deadline:
            time.sleep(0.05)
        sub.undeclare()
    assert sent == {"companion": 5, "intruder": 5}
    whos = [b.decode() for b in got]
    assert sum('"who":"companion"' in w for w in whos) == 5
    assert sum('"who":"intruder"' in w for w in whos) == (0 if acl else 5)
