"""Checks of what a user typed, done before any work starts: output paths, Zenoh endpoints, ports.

Each raises ConfigError with one line naming what was received and what was expected, so a mistake
ends with a clear message (and no run file or half a simulation left behind).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import re
from collections.abc import Iterable
from pathlib import Path

from spinefarm.protocol.errors import ConfigError, check_range

# Zenoh endpoint locators a user types: proto/host:port (IPv6 hosts in brackets); unix sockets take a path.
_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic|ws)/(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.\-]+):(\d{1,5})(#.*)?$")
_UNIX = re.compile(r"^unixsock-stream/\S+$")


def output_path(flag: str, path: str | Path, suffixes: tuple[str, ...]) -> Path:
    """`path` ends in one of `suffixes` and its folder exists (or can be made) and is writable."""
    p = Path(path)
    if p.suffix.lower() not in suffixes:
        raise ConfigError(f"{flag} has the wrong extension", received=str(p),
                          expected=f"a file name ending in {' or '.join(suffixes)}")
    if p.is_dir():
        raise ConfigError(f"{flag} is a folder", received=str(p), expected=f"a file name ending in {suffixes[0]}")
    folder = p.parent if str(p.parent) else Path(".")
    existing = folder
    while not existing.exists():  # the nearest existing ancestor decides whether the folder can be made
        existing = existing.parent
    if not existing.is_dir():
        raise ConfigError(f"{flag} cannot be written: {existing} is a file, not a folder", received=str(p),
                          expected="a path inside a folder")
    if not os.access(existing, os.W_OK | os.X_OK) or (p.exists() and not os.access(p, os.W_OK)):
        raise ConfigError(f"{flag} cannot be written: no write permission", received=str(p),
                          expected="a path in a writable folder")
    return p


def endpoint(flag: str, value: str) -> str:
    """A Zenoh endpoint such as tcp/127.0.0.1:7447 with a port in 1..65535."""
    if _UNIX.match(value):
        return value
    m = _ENDPOINT.match(value)
    if m is None:
        raise ConfigError(f"{flag} is not a Zenoh endpoint", received=value,
                          expected="PROTOCOL/HOST:PORT, e.g. tcp/127.0.0.1:7447 (tcp, udp, tls, quic or ws)")
    if not 1 <= int(m.group(3)) <= 65535:
        raise ConfigError(f"{flag} port out of range", received=value, expected="a port from 1 to 65535")
    return value


def endpoints(flag: str, values: Iterable[str] | None) -> list[str] | None:
    return None if values is None else [endpoint(flag, v) for v in values]


def port(flag: str, value: int | None, *, allow_off: bool = False) -> int | None:
    """A TCP port in 1..65535 (or -1 = off when allowed; None = the default)."""
    if value is None or (allow_off and value == -1):
        return value
    if not 1 <= value <= 65535:
        raise ConfigError(f"{flag} out of range", received=value,
                          expected="a port from 1 to 65535" + (", or -1 for no API" if allow_off else ""))
    return value


def at_least(flag: str, value: int | None, low: int, what: str) -> int | None:
    if value is not None and value < low:
        raise ConfigError(f"{flag} out of range", received=value, expected=f"{what} (at least {low})")
    return value


def in_range(flag: str, value: float | None, low: float | None = None, high: float | None = None, *,
             low_inclusive: bool = True) -> None:
    """A number flag in its range (None: not given), the error naming the flag as typed."""
    if value is not None:
        check_range(flag, value, low, high, low_inclusive=low_inclusive)


# (flag, argparse attribute, the TrialConfig field it sets): a bad value names the flag with the field's range
TRIAL_FLAGS = (("--duration", "duration", "duration_s"), ("--settle", "settle", "settle_s"),
               ("--dt", "dt", "dt_s"), ("--cpg-step", "cpg_step", "cpg_step_s"),
               ("--record-every", "record_every", "record_every_s"), ("--verify-dt", "verify_dt", "dt_s"))


def trial_flags(args: argparse.Namespace) -> None:
    """The trial-setting flags a command has, each in the range of its TrialConfig field (--dt may be 'auto')."""
    from spinefarm.robot.trial_config import TrialConfig

    bounds = {f.name: f.metadata["bounds"] for f in dataclasses.fields(TrialConfig) if "bounds" in f.metadata}
    for flag, attr, field in TRIAL_FLAGS:
        value = getattr(args, attr, None)
        if isinstance(value, str):
            try:
                value = float(value)
            except ValueError:
                continue  # 'auto', or a word the step parser names
        low, high, low_inclusive = bounds[field]
        in_range(flag, value, low, high, low_inclusive=low_inclusive)


def seed(text: str) -> int:
    """argparse type of every seed flag: an integer >= 0 (numpy's generators take no negative seed)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a seed is a whole number >= 0; received {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"a seed is a whole number >= 0; received {value}")
    return value


def add_cpg_step_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--cpg-step", type=float, default=None, metavar="S",
                   help="the longest own step of the CPG where the robot updates it every physics step, each "
                        "network within it and 0.25 / its fastest rate (default: the engine's, every step on "
                        "Bullet, 0.004 on MuJoCo; 0: every step; see docs/performance.md)")
