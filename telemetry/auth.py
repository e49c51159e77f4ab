"""Per-run telemetry authentication: every zenoh message carries an HMAC of its key and samples.

Pure: imports hmac and hashlib only. Without it any process that reaches the zenoh network
can publish to the recorder (a forged run_end ends a log early; forged samples show in the
review). With a run key the recorder keeps only what the run's own publishers sealed:

- am-run draws a random 32-byte master key per run (`telemetry.key`, mode 0600, in the run
  folder) and gives the recorder the master and each publisher only its own key,
  `publisher_key(master, name)` ('simulator', 'am<sysid>');
- a publisher appends one line to every message, `#hmac-sha256:` and the first 128 bits of
  HMAC-SHA256(its key, key expression, NUL, the message's samples), in hex;
- the recorder derives the key of the one publisher that may write each key expression
  (`publisher_of`: the simulator for <p>/sim/**, am<sysid> for <p>/am/<sysid>/**, <name> for
  <p>/telemetry/<name> and <p>/batch/<name>) and drops and counts every message whose tag is
  missing or wrong, or whose key no publisher may write, and every sample of a batch whose
  own key is not the batch publisher's. So a run_end (<p>/sim/event) comes only from the
  simulator: a companion's key cannot seal it.

A recorded message can be replayed within the run (the seq accounting shows the repeat); a
new run has a new key, so nothing of an old run is accepted.
"""
from __future__ import annotations

import hashlib
import hmac

from .schema import Channel, Keys

TAG = b"#hmac-sha256:"
TAG_HEX_CHARS = 32  # 128 bits
KEY_BYTES = 32


def publisher_key(master: bytes, name: str) -> bytes:
    """The key of publisher `name` ('simulator', 'am4', ...) under a run's master key."""
    return hmac.new(master, b"amstack telemetry publisher\0" + name.encode("ascii"), hashlib.sha256).digest()


def publisher_of(keys: Keys, key_expr: str) -> str | None:
    """The one publisher that may write `key_expr`, or None if none may. A batch key
    <p>/batch/<name> is <name>'s (and every sample in it must be of a key <name> may write)."""
    m = keys.parse(key_expr)
    if m is None:
        return keys.batch_name(key_expr)
    if m.channel is Channel.PUBLISHER:
        return m.name
    if m.channel in (Channel.CONTROLLER, Channel.AM_EVENT):
        return f"am{m.sysid}"
    return "simulator"


def _tag(key: bytes, key_expr: str, body: bytes) -> bytes:
    mac = hmac.new(key, key_expr.encode("utf-8") + b"\0", hashlib.sha256)
    mac.update(body)  # not concatenated: a batch is tens of kB
    return mac.hexdigest()[:TAG_HEX_CHARS].encode("ascii")


def seal(key: bytes, key_expr: str, body: bytes) -> bytes:
    """`body` (samples, one JSON text per line) with its tag line appended."""
    return body + b"\n" + TAG + _tag(key, key_expr, body)


def unseal(master: bytes, keys: Keys, key_expr: str, message: bytes) -> bytes | None:
    """The samples of an authentic message (its tag line removed), or None: no tag, a wrong
    tag, or a key expression no publisher of the run may write."""
    body, sep, last = message.rpartition(b"\n")
    if not sep or not last.startswith(TAG):
        return None
    name = publisher_of(keys, key_expr)
    if name is None:
        return None
    want = _tag(publisher_key(master, name), key_expr, body)
    return body if hmac.compare_digest(last[len(TAG):], want) else None


def parse_key(text: str, where: str) -> bytes:
    """A key file's content: 64 hex digits (32 bytes). ValueError naming `where` if not."""
    try:
        key = bytes.fromhex(text.strip())
    except ValueError:
        key = b""
    if len(key) != KEY_BYTES:
        raise ValueError(f"{where}: a telemetry key file holds 64 hex digits (32 bytes)")
    return key
