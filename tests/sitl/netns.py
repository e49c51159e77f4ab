"""Separate Linux network namespaces joined by virtual links, as separate hosts would be
(helpers of the distributed SITL test). Needs root (CAP_NET_ADMIN) and iproute2."""
from __future__ import annotations

import os
import shutil
import subprocess


def available() -> str | None:
    """None if namespaces can be made here, else why not."""
    if shutil.which("ip") is None:
        return "iproute2 ('ip') is not installed"
    name = f"amprobe{os.getpid()}"
    p = subprocess.run(["ip", "netns", "add", name], capture_output=True, text=True)
    if p.returncode != 0:
        return f"cannot create network namespaces: {p.stderr.strip()}"
    subprocess.run(["ip", "netns", "del", name], capture_output=True)
    return None


class Lan:
    """Hosts on one switched 10.77.x.0/24 network: a bridge in its own namespace, one veth each."""

    def __init__(self, hosts: list[str]) -> None:
        tag = f"{os.getpid() % 10000}"
        self.br = f"ambr{tag}"
        self.ns = {h: f"am{h}{tag}" for h in hosts}
        self.ip = {h: f"10.77.{os.getpid() % 200}.{i + 1}" for i, h in enumerate(hosts)}
        self._made: list[str] = []
        try:
            self._sh("ip", "netns", "add", self.br)
            self._made.append(self.br)
            self._sh("ip", "netns", "exec", self.br, "ip", "link", "add", "br0", "type", "bridge")
            self._sh("ip", "netns", "exec", self.br, "ip", "link", "set", "br0", "up")
            for i, h in enumerate(hosts):
                ns = self.ns[h]
                self._sh("ip", "netns", "add", ns)
                self._made.append(ns)
                a, b = f"v{tag}h{i}", f"v{tag}b{i}"
                self._sh("ip", "link", "add", a, "netns", ns, "type", "veth", "peer", "name", b, "netns", self.br)
                self._sh("ip", "netns", "exec", self.br, "ip", "link", "set", b, "master", "br0", "up")
                self._sh("ip", "netns", "exec", ns, "ip", "addr", "add", f"{self.ip[h]}/24", "dev", a)
                self._sh("ip", "netns", "exec", ns, "ip", "link", "set", a, "up")
                self._sh("ip", "netns", "exec", ns, "ip", "link", "set", "lo", "up")
        except BaseException:
            self.close()
            raise

    @staticmethod
    def _sh(*cmd: str) -> None:
        p = subprocess.run(cmd, capture_output=True, text=True)
        if p.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)}: {p.stderr.strip()}")

    def popen(self, host: str, cmd: list[str], **kw) -> subprocess.Popen:
        return subprocess.Popen(["ip", "netns", "exec", self.ns[host], *cmd], **kw)

    def close(self) -> None:
        for ns in reversed(self._made):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
        self._made.clear()
