"""`spinefarm router`: a Zenoh router in router mode, for deployments with no `zenohd` image at hand.

It takes the flags the official router is started with in docker-compose.yml (`--config FILE.json5`,
`--listen ENDPOINT`), so deploy/compose.offline.yml runs it from the spinefarm image with the TLS and
user/password settings deploy/make-credentials.sh writes (router.json5). `--credentials FILE` is the
same access control as on the coordinator: only the users in FILE may open a session.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from spinefarm.cli import checks
from spinefarm.cli.stop_signals import stop_on_signals, wait_for_stop
from spinefarm.protocol.errors import ConfigError

DEFAULT_LISTEN = "tcp/127.0.0.1:7447"
CLOSE_WITHIN_S = 5.0  # a router keeps no state: past this its stop does not wait for Zenoh's own


def register(sub: Any) -> None:
    p = sub.add_parser("router", help="a Zenoh router for coordinators and workers on several machines",
                       description="A Zenoh router (router mode) that coordinators and workers connect to with "
                                   "--connect; stops on SIGTERM or Ctrl-C.")
    p.add_argument("--config", metavar="FILE.json5",
                   help="Zenoh JSON5 config (TLS certificates, user/password dictionary), e.g. the router.json5 "
                        "of deploy/make-credentials.sh")
    p.add_argument("--listen", action="append", metavar="ENDPOINT",
                   help=f"endpoint to listen on, repeatable (default {DEFAULT_LISTEN}; tls/0.0.0.0:7447 with "
                        "the certificates of --config)")
    p.add_argument("--credentials", metavar="FILE",
                   help="user:password lines: refuse every session whose user is not in the file")
    p.set_defaults(func=run)


def router_config(config_file: str | Path | None, listen: Sequence[str], credentials_file: str | Path | None) -> Any:
    """The router's zenoh.Config: `config_file` passed through, then mode, endpoints and access control."""
    import zenoh

    try:
        conf = zenoh.Config.from_file(str(config_file)) if config_file else zenoh.Config()
    except Exception as exc:  # zenoh raises its own error type for unreadable files
        raise ConfigError(f"cannot read Zenoh config {config_file}: {exc}", expected="a JSON5 file") from exc
    conf.insert_json5("mode", json.dumps("router"))
    conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    conf.insert_json5("scouting/multicast/enabled", "false")
    if credentials_file:
        from spinefarm.protocol.credentials import load_credentials

        for key, value in load_credentials(credentials_file).zenoh_settings(accept=True).items():
            conf.insert_json5(key, value)
    return conf


def guarded(conf: Any) -> bool:
    """Whether the config refuses sessions without a known user (a user/password dictionary is set)."""
    return bool(json.loads(conf.get_json("transport/auth/usrpwd/dictionary_file") or "null"))


def run(args: argparse.Namespace) -> int:
    listen = args.listen or [DEFAULT_LISTEN]
    checks.endpoints("--listen", listen)
    try:
        import zenoh
    except ImportError as exc:
        raise ConfigError("this installation has no Zenoh", expected="pip install 'spinefarm[worker]'") from exc
    conf = router_config(args.config, listen, args.credentials)
    if not guarded(conf):
        print("warning: no user/password dictionary (--credentials or --config): every session is let in",
              file=sys.stderr)
    stop = threading.Event()
    stop_on_signals(stop)
    try:
        session = zenoh.open(conf)
    except zenoh.ZError as exc:
        raise ConfigError(f"the router cannot start: {exc}", received=", ".join(listen),
                          expected="endpoints free to listen on and readable certificates") from exc
    print(f"router {session.zid()} listening on {', '.join(listen)}", flush=True)
    try:
        wait_for_stop(stop)
    finally:
        closer = threading.Thread(target=session.close, daemon=True)
        closer.start()
        closer.join(CLOSE_WITHIN_S)
    if closer.is_alive():
        print(f"warning: the Zenoh session did not close within {CLOSE_WITHIN_S:g} s; stopping without it",
              file=sys.stderr, flush=True)
    print("router stopped", flush=True)
    # a router keeps nothing to save, so the exit waits for no runtime thread of Zenoh's, in the close or at
    # the interpreter's shutdown
    os._exit(0)
