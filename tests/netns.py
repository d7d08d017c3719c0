"""Three hosts on one machine: network namespaces joined by veth pairs, with latency and loss.

    worker host A (10.77.1.2) --veth-- hub (10.77.1.1 | 10.77.2.1) --veth-- worker host B (10.77.2.2)

The hub runs the router/coordinator. Links are shaped with tc netem (delay and loss) where the kernel
has it; otherwise loss comes from iptables' statistic match and latency from a delaying TCP relay in the
hub (tests/delay_relay.py) in front of the coordinator, which then listens on the hub's loopback. A
partition drops every packet (netem 100 % loss, else iptables DROP). Only addresses inside namespaces
this module creates are used; `close()` deletes them (and with them every veth and rule), also after a
failure. Needs root and iproute2.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

PORT = 7447
HUB_ADDR = {"a": "10.77.1.1", "b": "10.77.2.1"}


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True, timeout=10)


def netns_unavailable() -> str | None:
    """Why namespaces cannot be made here, or None."""
    probe = f"sfprobe{os.getpid()}"
    try:
        _ip("netns", "add", probe)
    except FileNotFoundError:
        return "iproute2 (`ip`) is not installed"
    except subprocess.CalledProcessError as exc:
        return f"`ip netns add` failed (needs root / CAP_SYS_ADMIN): {exc.stderr.strip()}"
    try:
        _ip("-n", probe, "link", "set", "lo", "up")
        netem = subprocess.run(["ip", "netns", "exec", probe, "tc", "qdisc", "add", "dev", "lo", "root", "netem",
                                "delay", "1ms"], capture_output=True, timeout=10).returncode == 0
    finally:
        subprocess.run(["ip", "netns", "del", probe], capture_output=True, timeout=10)
    if not netem and shutil.which("iptables") is None:
        return "links cannot be shaped: neither tc netem (kernel module sch_netem) nor iptables is available"
    return None


@dataclass
class ThreeHosts:
    tag: str = field(default_factory=lambda: f"sf{os.getpid() % 100000}")
    delay_ms: float = 20.0   # each way, on every link: 40 ms round trip between a worker and the hub
    loss_pct: float = 2.0
    made: list[str] = field(default_factory=list)

    @property
    def hub(self) -> str:
        return f"{self.tag}hub"

    def host(self, name: str) -> str:
        return f"{self.tag}{name}"

    shaping: str = ""        # "netem" or "relay+iptables": how latency and loss are made
    _relay: subprocess.Popen | None = None

    def open(self) -> ThreeHosts:
        try:
            for ns in (self.hub, self.host("a"), self.host("b")):
                _ip("netns", "add", ns)
                self.made.append(ns)
                _ip("-n", ns, "link", "set", "lo", "up")
            for side, net in (("a", 1), ("b", 2)):
                hub_if, host_if = f"{self.tag}{side}0", f"{self.tag}{side}1"
                _ip("link", "add", hub_if, "netns", self.hub, "type", "veth", "peer", "name", host_if, "netns",
                    self.host(side))
                _ip("-n", self.hub, "addr", "add", f"10.77.{net}.1/24", "dev", hub_if)
                _ip("-n", self.host(side), "addr", "add", f"10.77.{net}.2/24", "dev", host_if)
                _ip("-n", self.hub, "link", "set", hub_if, "up")
                _ip("-n", self.host(side), "link", "set", host_if, "up")
            self.shaping = "netem" if self._try_netem() else "relay+iptables"
            if self.shaping != "netem":
                for ns in (self.hub, self.host("a"), self.host("b")):
                    self._iptables(ns, "-A", "INPUT", "-m", "statistic", "--mode", "random", "--probability",
                                   f"{self.loss_pct / 100:g}", "-j", "DROP")
                self._start_relay()
        except BaseException:
            self.close()
            raise
        return self

    # --- shaping ----------------------------------------------------------------------------------
    def _netem(self, ns: str, dev: str, verb: str, loss_pct: float) -> None:
        subprocess.run(["ip", "netns", "exec", ns, "tc", "qdisc", verb, "dev", dev, "root", "netem", "delay",
                        f"{self.delay_ms:g}ms", "loss", f"{loss_pct:g}%"], check=True, capture_output=True,
                       timeout=10)

    def _try_netem(self) -> bool:
        try:
            for side in ("a", "b"):
                self._netem(self.hub, f"{self.tag}{side}0", "add", self.loss_pct)
                self._netem(self.host(side), f"{self.tag}{side}1", "add", self.loss_pct)
        except subprocess.CalledProcessError:
            return False
        return True

    def _iptables(self, ns: str, *rule: str) -> None:
        subprocess.run(["ip", "netns", "exec", ns, "iptables", "-w", *rule], check=True, capture_output=True,
                       timeout=10)

    def _start_relay(self) -> None:
        relay = Path(__file__).with_name("delay_relay.py")
        self._relay = subprocess.Popen(
            [*self.exec_args(self.hub), sys.executable, str(relay), f"{self.delay_ms:g}", f"127.0.0.1:{PORT}",
             f"{HUB_ADDR['a']}:{PORT}", f"{HUB_ADDR['b']}:{PORT}"], stdout=subprocess.PIPE, text=True)
        if self._relay.stdout.readline().strip() != "ready":
            raise RuntimeError("the delaying relay did not start")

    # --- what the processes use -------------------------------------------------------------------
    @property
    def coordinator_listen(self) -> str:
        """Endpoint the coordinator (in the hub) listens on."""
        return f"tcp/0.0.0.0:{PORT}" if self.shaping == "netem" else f"tcp/127.0.0.1:{PORT}"

    def endpoint(self, side: str) -> str:
        """Endpoint a worker on host `side` connects to."""
        return f"tcp/{HUB_ADDR[side]}:{PORT}"

    def cut(self, side: str, cut: bool = True) -> None:
        """Cut host `side` off (every packet dropped both ways), or heal it back to the shaped link."""
        if self.shaping == "netem":
            loss = 100.0 if cut else self.loss_pct
            self._netem(self.hub, f"{self.tag}{side}0", "change", loss)
            self._netem(self.host(side), f"{self.tag}{side}1", "change", loss)
            return
        verb = "-I" if cut else "-D"
        self._iptables(self.host(side), verb, "INPUT", "-j", "DROP")
        self._iptables(self.host(side), verb, "OUTPUT", "-j", "DROP")

    def exec_args(self, ns: str) -> list[str]:
        return ["ip", "netns", "exec", ns]

    def close(self) -> None:
        if self._relay is not None:
            self._relay.kill()
            self._relay.wait(10)
            self._relay = None
        for ns in reversed(self.made):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=10)
        self.made.clear()
