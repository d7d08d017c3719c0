"""Access control in one flag: `--credentials FILE`, Zenoh's own user/password authentication.

FILE holds `user:password` lines (Zenoh's dictionary format; blank lines and # comments allowed). Every
process authenticates with the FIRST line; a process that listens (the coordinator as router, a
peer-mode worker) also accepts every line as a known user. A session without valid credentials is
refused when it opens its link, so it can neither join nor read work. Give workers a file with only
their own line; keep the full file on the coordinator (mode 0600).
"""

from __future__ import annotations

import json
import re
import stat
from dataclasses import dataclass
from pathlib import Path

from spinefarm.protocol.errors import ConfigError

_USER = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")
MIN_PASSWORD_CHARS = 16


@dataclass(frozen=True)
class Credentials:
    path: Path
    user: str
    password: str
    users: tuple[str, ...]

    def zenoh_settings(self, accept: bool) -> dict[str, str]:
        """Zenoh config keys (JSON5 values): authenticate as `user`; with `accept`, check every peer."""
        out = {"transport/auth/usrpwd/user": json.dumps(self.user),
               "transport/auth/usrpwd/password": json.dumps(self.password)}
        if accept:
            out["transport/auth/usrpwd/dictionary_file"] = json.dumps(str(self.path.resolve()))
        return out

    @property
    def world_readable(self) -> bool:
        return bool(self.path.stat().st_mode & stat.S_IROTH)


def load_credentials(path: str | Path) -> Credentials:
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read credentials file {path}: {exc}",
                          expected="a file of user:password lines") from exc
    pairs = []
    for number, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        user, sep, password = line.partition(":")
        if not sep or not _USER.match(user) or len(password) < MIN_PASSWORD_CHARS or ":" in password:
            raise ConfigError(f"credentials file {path} line {number} is malformed",
                              received=f"{user[:20]!r}:<{len(password)} characters>" if sep else "no ':'",
                              expected=f"user:password with a 1-64 character user (A-Z a-z 0-9 _ . -) and a "
                                       f"password of at least {MIN_PASSWORD_CHARS} characters without ':'")
        pairs.append((user, password))
    if not pairs:
        raise ConfigError(f"credentials file {path} holds no user", expected="at least one user:password line")
    return Credentials(path, pairs[0][0], pairs[0][1], tuple(u for u, _ in pairs))


def is_loopback(endpoint: str) -> bool:
    """tcp/127.0.0.1:7447, tcp/localhost:1, tcp/[::1]:1 -> True; tcp/0.0.0.0:7447 -> False."""
    host = endpoint.split("/", 1)[-1].rsplit(":", 1)[0].strip("[]").split("#")[0]
    return host in ("localhost", "::1") or host.startswith("127.")
