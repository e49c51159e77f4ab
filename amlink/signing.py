"""MAVLink 2 signing keys of the amstack link: formats, derivation, key files.

Pure (hashlib only; :func:`read_key_file` reads one file).

Keys.  Each companion (sysid ``s``) shares a 32-byte secret with the simulator; the
simulator holds all of them.  :func:`resolve_key` picks a vehicle's key, first match:

1. ``key_hex`` -- 64 hex digits given for that vehicle (scenario ``[[am]].signing_key_hex``);
2. ``master_key`` -- a scenario-wide secret (scenario ``[link].key_file``, a file of
   64 hex digits); the vehicle's key is ``SHA-256(master || "amstack-link-v1" || s)``;
3. otherwise a *development key* derived from ``s`` alone.  It is
   public (anyone with this source can compute it), so it still gives integrity
   against corruption, stale
   processes, and rejects replays of old traffic, but it is no protection against
   an attacker.  :func:`resolve_key` reports which source was used so the process
   mains can warn about it.

The GCS link (the simulator's flight controllers to a ground station) has a key of its own,
:func:`gcs_key_from_passphrase`: SHA-256 of a passphrase, MAVProxy's rule (``signing key
PASSPHRASE``), so a stock GCS can use it; a GCS key file holds the passphrase.

The signatures themselves, and their timestamp clock, are :mod:`amlink.wire`'s.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

KEY_BYTES = 32
_DERIVE_TAG = b"amstack-link-v1"
_DEV_TAG = b"amstack-dev-key-PUBLIC"


class SigningKeyError(ValueError):
    """A signing key is malformed or missing; the message says which and where."""


def key_from_hex(text: str, where: str = "signing key") -> bytes:
    """32-byte key from 64 hex digits (surrounding whitespace ignored)."""
    s = text.strip()
    try:
        key = bytes.fromhex(s)
    except ValueError:
        raise SigningKeyError(f"{where}: not hex digits") from None
    if len(key) != KEY_BYTES:
        raise SigningKeyError(f"{where}: need {2 * KEY_BYTES} hex digits ({KEY_BYTES} bytes), got {len(s)}")
    return key


def read_key_file(path: str | Path) -> bytes:
    """A key file holds 64 hex digits (one line); keep it mode 0600."""
    p = Path(path)
    try:
        text = p.read_text(encoding="ascii")
    except (OSError, UnicodeDecodeError) as exc:
        raise SigningKeyError(f"{p}: cannot read key file: {exc}") from None
    return key_from_hex(text, str(p))


def gcs_key_from_passphrase(passphrase: str) -> bytes:
    """The 32-byte signing key of a passphrase: SHA-256 of its ASCII bytes, as MAVProxy derives it."""
    if not passphrase or not passphrase.isascii() or passphrase != passphrase.strip():
        raise SigningKeyError("a GCS passphrase is non-empty ASCII without surrounding whitespace")
    return hashlib.sha256(passphrase.encode("ascii")).digest()


def read_gcs_key_file(path: str | Path, what: str = "GCS key file") -> bytes:
    """The key of a file holding its passphrase (one line; keep it mode 0600), as MAVProxy's
    'signing key' derives it; `what` names the file in errors."""
    p = Path(path)
    try:
        text = p.read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError) as exc:
        raise SigningKeyError(f"{p}: cannot read {what}: {exc}") from None
    try:
        return gcs_key_from_passphrase(text)
    except SigningKeyError as exc:
        raise SigningKeyError(f"{p}: {exc}") from None


def derive_vehicle_key(master_key: bytes, sysid: int) -> bytes:
    """Per-vehicle key from a scenario-wide secret: SHA-256(master || tag || sysid)."""
    check_key(master_key)
    return hashlib.sha256(master_key + _DERIVE_TAG + bytes([sysid])).digest()


def development_key(scenario_name: str, sysid: int) -> bytes:
    """The PUBLIC default key of vehicle ``sysid`` (see module doc).

    It does not depend on the scenario: a companion started with another scenario must
    still be able to hear the simulator's AM_SCENARIO and be told that it is in the wrong
    run (the scenario fingerprint check), rather than being silently dropped.
    ``scenario_name`` is accepted and ignored."""
    return hashlib.sha256(_DEV_TAG + b"\x00" + bytes([sysid])).digest()


def resolve_key(sysid: int, *, key_hex: str = "", master_key: bytes | None = None,
                scenario_name: str = "") -> tuple[bytes, str]:  # fmt: skip
    """The key of vehicle ``sysid`` and where it came from: ``"vehicle"``, ``"master"`` or ``"development"``."""
    if not 2 <= sysid <= 255:
        raise SigningKeyError(f"sysid {sysid} must be in 2..255")
    if key_hex:
        return key_from_hex(key_hex, f"signing_key_hex of sysid {sysid}"), "vehicle"
    if master_key is not None:
        return derive_vehicle_key(master_key, sysid), "master"
    return development_key(scenario_name, sysid), "development"


def check_key(key: bytes) -> bytes:
    if not isinstance(key, (bytes, bytearray)) or len(key) != KEY_BYTES:
        raise SigningKeyError(f"a signing key must be {KEY_BYTES} bytes")
    return bytes(key)


def keys_for_scenario(spec) -> dict[int, tuple[bytes, str]]:
    """``{sysid: (key, source)}`` for a loaded scenario (``amcore.config.ScenarioSpec``, duck-typed).

    Uses ``[[am]].signing_key_hex``, ``[link].key_file`` and the scenario name as
    :func:`resolve_key` does; ``source == "development"`` means a public key.
    """
    key_path = spec.link.key_path(spec.path)
    master = read_key_file(key_path) if key_path is not None else None
    return {
        am.sysid: resolve_key(am.sysid, key_hex=am.signing_key_hex, master_key=master, scenario_name=spec.name)
        for am in spec.ams
    }


def keys_for_run(spec, key_file: str | Path | None = None) -> tuple[dict[int, bytes] | None, str | None]:
    """What a process main uses: ``({sysid: key} or None when [link] signing = false, warning)``.

    ``key_file`` (a command-line override of ``[link].key_file``) is a master key from
    which every vehicle's key is derived, unless that vehicle has its own
    ``signing_key_hex``.  The warning (or None) says when the link is unsigned or signed
    with the public development key.
    """
    if not spec.link.signing:
        return None, ("MAVLink signing is OFF ([link] signing = false): any host that can reach the "
                      "simulator's port can command the vehicles")
    if key_file is not None:
        master = read_key_file(key_file)
        return {am.sysid: resolve_key(am.sysid, key_hex=am.signing_key_hex, master_key=master)[0]
                for am in spec.ams}, None
    keys = keys_for_scenario(spec)
    warning = None
    if any(src == "development" for _, src in keys.values()):
        warning = ("signing with the PUBLIC development key (no [link].key_file or --key-file): integrity "
                   "and anti-replay only, no protection against an attacker")
    return {s: k for s, (k, _) in keys.items()}, warning
