"""Zenoh session configuration for telemetry publishers and the recorder.

Embedded default (one host, no router, no multicast):

    recorder   peer, listens on  tcp/127.0.0.1:7447
    publishers peer, connect to  tcp/127.0.0.1:7447, listen on nothing

Multicast and gossip scouting are off, so nothing leaves loopback and nothing but the
configured endpoints is tried. A publisher opened before the recorder, or with none at
all, opens at once (scouting delay 0) and retries the connection in the background
(every 0.25 s, backing off to 2 s); until then its samples simply have no subscriber.

Across hosts: give the recorder `--zenoh-listen tcp/0.0.0.0:7447` and each publisher
`--zenoh-connect tcp/<recorder-host>:7447`, or run a `zenohd` router and make every
process `--zenoh-mode client --zenoh-connect tcp/<router>:7447`. TLS, authentication and
access control are zenoh config-file features: pass the file with `--zenoh-config`
(see docs/telemetry.md); explicit --zenoh-* options are applied on top of it.

`config_items` is pure (testable without zenoh); `build_config` imports zenoh.
"""
from __future__ import annotations

import argparse
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from amcore.cliargs import seconds_or_zero

from .auth import parse_key
from .schema import DEFAULT_PREFIX, Keys

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
MODES = ("peer", "client", "router")
ROLES = ("publisher", "recorder")


class TelemetryConfigError(ValueError):
    """Telemetry options that cannot make a zenoh session (bad mode, unreadable config file)."""


@dataclass(frozen=True)
class ZenohOptions:
    """How one process joins the telemetry network.

    connect / listen: zenoh endpoints ("tcp/host:port", "tls/host:port", ...). None means
    the role's default (see the module docstring); an empty tuple means none at all.
    config_file: a zenoh JSON5 config (TLS, access control) used as the base.
    """

    role: str = "publisher"
    mode: str = "peer"
    connect: tuple[str, ...] | None = None
    listen: tuple[str, ...] | None = None
    config_file: Path | None = None
    prefix: str = DEFAULT_PREFIX
    enabled: bool = True
    retry_init_ms: int = 250
    retry_max_ms: int = 2000
    # telemetry.auth: a publisher's own key (it seals every message), or the recorder's run
    # master key (it keeps only sealed messages); None: nothing is authenticated
    auth_key: bytes | None = field(default=None, repr=False)

    def __post_init__(self):
        if self.role not in ROLES:
            raise TelemetryConfigError(f"telemetry role {self.role!r} is not one of {ROLES}")
        if self.mode not in MODES:
            raise TelemetryConfigError(f"zenoh mode {self.mode!r} is not one of {MODES}")
        for flag, endpoints in (("--zenoh-connect", self.connect), ("--zenoh-listen", self.listen)):
            for e in endpoints or ():
                check_zenoh_endpoint(e, flag, listening=flag == "--zenoh-listen")
        Keys(self.prefix)  # validates

    @property
    def keys(self) -> Keys:
        return Keys(self.prefix)

    @property
    def connect_endpoints(self) -> tuple[str, ...]:
        if self.connect is not None:
            return tuple(self.connect)
        if self.config_file is not None:
            return ()
        return (DEFAULT_ENDPOINT,) if self.role == "publisher" else ()

    @property
    def listen_endpoints(self) -> tuple[str, ...]:
        if self.listen is not None:
            return tuple(self.listen)
        if self.config_file is not None:
            return ()
        return (DEFAULT_ENDPOINT,) if self.role == "recorder" else ()


# zenoh's link protocols whose address is HOST:PORT, and the others it knows
_HOST_PORT_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")
_OTHER_PROTOCOLS = ("unixsock-stream", "unixpipe", "serial", "vsock")


def check_zenoh_endpoint(text: str, flag: str, listening: bool = False) -> None:
    """A zenoh locator PROTOCOL/ADDRESS[#CONFIG] that can work (zenoh itself retries a
    malformed one forever); TelemetryConfigError naming the flag if not."""
    proto, sep, rest = text.partition("/")
    address = rest.partition("#")[0].partition("?")[0]
    known = _HOST_PORT_PROTOCOLS + _OTHER_PROTOCOLS
    if not sep or proto not in known or not address:
        raise TelemetryConfigError(f"{flag} {text!r}: expected PROTOCOL/ADDRESS with PROTOCOL one of "
                                   f"{', '.join(known)}, e.g. {DEFAULT_ENDPOINT}")
    if proto in _HOST_PORT_PROTOCOLS:
        if address.startswith("["):
            host, close, tail = address[1:].partition("]")
            port = tail[1:] if close and tail.startswith(":") else ""
        else:
            host, _, port = address.rpartition(":")
        lo = 0 if listening else 1
        if not host or not port.isdigit() or not lo <= int(port) <= 65535:
            raise TelemetryConfigError(f"{flag} {text!r}: expected {proto}/HOST:PORT with PORT in {lo}..65535")


def config_items(opts: ZenohOptions) -> dict[str, Any]:
    """The zenoh config entries (path -> JSON value) these options set.

    With a config file only the explicit options are set, so the file's own endpoints,
    scouting, TLS and ACL sections stay as written."""
    items: dict[str, Any] = {"mode": opts.mode}
    if opts.config_file is None or opts.connect is not None:
        items["connect/endpoints"] = list(opts.connect_endpoints)
    if opts.config_file is None or opts.listen is not None:
        items["listen/endpoints"] = list(opts.listen_endpoints)
    if opts.config_file is None:
        items.update({
            "scouting/multicast/enabled": False,
            "scouting/gossip/enabled": False,
            "scouting/delay": 0,
            # zenoh's shared-memory transport copies every message of 3 kB or more (a batch of
            # samples) into a shared segment and runs two watchdog threads: ~5 us of CPU per
            # 1 kHz sample in the publisher (benchmarks/bench_telemetry.py), for a few hundred kB/s
            "transport/shared_memory/enabled": False,
            "connect/retry": {"period_init_ms": opts.retry_init_ms, "period_max_ms": opts.retry_max_ms,
                              "period_increase_factor": 2.0},
        })
    return items


# the files a zenoh config's transport.link.tls names (zenoh's own error when one is missing
# names neither the key nor the path: "Invalid TLS private key file: No such file or directory")
TLS_FILE_KEYS = ("root_ca_certificate", "listen_certificate", "listen_private_key", "connect_certificate",
                 "connect_private_key")


def check_tls_files(opts: ZenohOptions) -> None:
    """Before a session opens: TelemetryConfigError naming the key and the path if the config
    file's transport.link.tls names a certificate or key file that is not there."""
    if opts.config_file is None:
        return
    tls = json.loads(build_config(opts).get_json("transport/link/tls") or "{}") or {}
    for key in TLS_FILE_KEYS:
        path = tls.get(key)
        if isinstance(path, str) and not Path(path).is_file():
            raise TelemetryConfigError(f"zenoh config {opts.config_file}: transport.link.tls.{key}: {path}: "
                                       f"no such file (docs/telemetry.md, \"TLS, authentication and access control\")")


def build_config(opts: ZenohOptions):
    """A zenoh.Config for these options."""
    import zenoh

    try:
        cfg = zenoh.Config.from_file(str(opts.config_file)) if opts.config_file is not None else zenoh.Config()
    except Exception as exc:  # zenoh raises ZError for unreadable or invalid files
        raise TelemetryConfigError(f"zenoh config {opts.config_file}: {exc}") from exc
    for path, value in config_items(opts).items():
        try:
            cfg.insert_json5(path, json.dumps(value))
        except Exception as exc:
            raise TelemetryConfigError(f"zenoh config entry {path} = {value!r}: {exc}") from exc
    return cfg


# ----------------------------------------------------------------------------- argparse
def add_zenoh_arguments(parser: argparse.ArgumentParser, role: str = "publisher") -> None:
    """Add --zenoh-mode/--zenoh-connect/--zenoh-listen/--zenoh-config/--telemetry-prefix
    (and --no-telemetry for publishers) to a process main's parser."""
    if role not in ROLES:
        raise TelemetryConfigError(f"telemetry role {role!r} is not one of {ROLES}")
    g = parser.add_argument_group("telemetry (zenoh)")
    g.add_argument("--zenoh-mode", choices=MODES, default="peer", help="zenoh session mode (default: peer)")
    d_conn = DEFAULT_ENDPOINT if role == "publisher" else "none"
    d_list = DEFAULT_ENDPOINT if role == "recorder" else "none"
    g.add_argument("--zenoh-connect", action="append", metavar="ENDPOINT",
                   help=f"endpoint to connect to, repeatable (default: {d_conn}; 'none' for none)")
    g.add_argument("--zenoh-listen", action="append", metavar="ENDPOINT",
                   help=f"endpoint to listen on, repeatable (default: {d_list}; 'none' for none)")
    g.add_argument("--zenoh-config", type=Path, metavar="FILE",
                   help="zenoh JSON5 config file used as the base (TLS, access control)")
    g.add_argument("--telemetry-prefix", default=DEFAULT_PREFIX, help=f"key prefix (default: {DEFAULT_PREFIX})")
    g.add_argument("--telemetry-key-file", type=Path, default=None, metavar="FILE",
                   help=("the run's telemetry master key (64 hex digits): keep only messages its publishers sealed"
                         if role == "recorder" else
                         "this publisher's telemetry key (64 hex digits): seal every message with it")
                        + " (telemetry.auth; am-run writes them to the run folder)")
    g.add_argument("--insecure", action="store_true",
                   help=("record without a telemetry key: keep whatever anyone on the zenoh network publishes"
                         if role == "recorder" else
                         "publish without a telemetry key: the recorder cannot tell these messages from forged ones"))
    if role == "publisher":
        g.add_argument("--no-telemetry", action="store_true", help="publish nothing")
        g.add_argument("--telemetry-wait", type=seconds_or_zero, default=0.0, metavar="S",
                       help="at start, wait up to S seconds for a subscriber (the recorder) so that the log "
                            "holds the first samples, then go on without (default 0: do not wait; am-run, "
                            "which starts the recorder first, passes 5)")


def missing_key_message(role: str) -> str:
    """Why a process without a telemetry key does not start, and how to give it one."""
    if role == "recorder":
        return ("no telemetry key: give the run's master key with --telemetry-key-file FILE (am-run writes "
                "telemetry.key into each run folder; 'ground-station keys DIR' writes a set for processes started "
                "by hand), or --insecure to record whatever anyone on the zenoh network publishes")
    return ("no telemetry key: give this publisher's key with --telemetry-key-file FILE (am-run writes "
            "telemetry-<simulator|am<sysid>>.key into each run folder; 'ground-station keys DIR' writes a set for "
            "processes started by hand), --no-telemetry to publish nothing, or --insecure to publish unsealed")


def _endpoints(values: list[str] | None) -> tuple[str, ...] | None:
    if values is None:
        return None
    return tuple(v for v in values if v.lower() != "none")


def options_from_args(args: argparse.Namespace, role: str = "publisher") -> ZenohOptions:
    """ZenohOptions from a namespace parsed with add_zenoh_arguments(parser, role); a config
    that zenoh cannot take (a bad --zenoh-config file) is a TelemetryConfigError now, before
    the run, rather than a session that retries in the background forever. So is a missing
    telemetry key (secure by default): a publisher or recorder without --telemetry-key-file
    is refused unless --insecure says to go without (a publisher may also --no-telemetry)."""
    key = None
    if args.telemetry_key_file is not None and not getattr(args, "no_telemetry", False):
        try:
            key = parse_key(Path(args.telemetry_key_file).read_text(), f"--telemetry-key-file {args.telemetry_key_file}")
        except (OSError, UnicodeDecodeError) as exc:
            raise TelemetryConfigError(f"--telemetry-key-file {args.telemetry_key_file}: cannot read it: "
                                       f"{getattr(exc, 'strerror', None) or exc}") from None
        except ValueError as exc:
            raise TelemetryConfigError(str(exc)) from None
    enabled = not getattr(args, "no_telemetry", False)
    opts = ZenohOptions(
        role=role, mode=args.zenoh_mode, connect=_endpoints(args.zenoh_connect),
        listen=_endpoints(args.zenoh_listen), config_file=args.zenoh_config, prefix=args.telemetry_prefix,
        enabled=enabled, auth_key=key,
    )
    if opts.enabled and opts.config_file is not None:
        if not Path(opts.config_file).is_file():
            raise TelemetryConfigError(f"--zenoh-config {opts.config_file}: not a file")
        build_config(opts)
    if enabled and key is None and not getattr(args, "insecure", False):  # last: other mistakes are named first
        raise TelemetryConfigError(missing_key_message(role))
    return opts
