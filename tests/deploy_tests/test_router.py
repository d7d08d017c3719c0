"""`spinefarm router`: the Zenoh router the offline compose deployment runs from the spinefarm image."""

from __future__ import annotations

import json
import os
import secrets
import shutil
import subprocess
import sys

import pytest
import yaml
import zenoh

from spinefarm.cli.router_command import guarded, router_config
from spinefarm.coordinator.service import zenoh_config
from spinefarm.protocol import keys
from spinefarm.protocol.credentials import load_credentials
from tests.coordinator_tests.helpers import free_endpoint
from tests.coordinator_tests.procs import ROOT, spinefarm, stop, wait_status

pytestmark = pytest.mark.integration


def make_secrets(tmp_path):
    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed (the compose image installs it from Debian)")
    d = tmp_path / "secrets"
    env = dict(os.environ, SECRETS_DIR=str(d), SECRETS_OWNER=str(os.getuid()))
    subprocess.run(["sh", str(ROOT / "deploy" / "make-credentials.sh")], env=env, check=True, capture_output=True)
    return d


def start_router(*args: str) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-P", "-m", "spinefarm", "router", *args], cwd=ROOT, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    line = proc.stdout.readline()
    assert line.startswith("router "), f"the router did not start: {line!r} {proc.stderr.read() if not line else ''}"
    return proc


def refused(ep: str, config_file=None, creds=None) -> bool:
    try:
        zenoh.open(zenoh_config("client", connect=[ep], config_file=config_file, credentials=creds)).close()
    except zenoh.ZError:
        return True
    return False


def test_the_offline_router_runs_with_the_official_routers_config_and_endpoint(tmp_path):
    """deploy/compose.offline.yml starts `spinefarm router` with what docker-compose.yml gives zenohd."""
    main = yaml.safe_load((ROOT / "docker-compose.yml").read_text())["services"]["router"]
    services = yaml.safe_load((ROOT / "deploy" / "compose.offline.yml").read_text())["services"]
    offline = services["router"]
    # the router runs as the images' user (uid 1000), so its files must be made for that user
    assert services["credentials"]["environment"]["ROUTER_OWNER"] == "1000"
    official, ours = main["command"], offline["command"]
    assert ours[0] == "router"
    for flag in ("--config", "--listen"):
        assert ours[ours.index(flag) + 1] == official[official.index(flag) + 1], flag
    assert offline["image"].startswith("spinefarm-") and offline["entrypoint"] == ["spinefarm"]
    d = make_secrets(tmp_path)
    conf = router_config(d / "router.json5", ["tls/0.0.0.0:7447"], None)

    def get(key):
        return json.loads(conf.get_json(key))

    assert get("mode") == "router" and "tls/0.0.0.0:7447" in json.dumps(get("listen/endpoints"))
    assert get("transport/link/tls/enable_mtls") is True
    assert get("transport/link/tls/listen_certificate") == f"{d}/router.pem"
    assert get("scouting/multicast/enabled") is False
    assert guarded(conf) and not guarded(router_config(None, ["tcp/127.0.0.1:7447"], None))


def test_the_router_refuses_a_client_without_credentials_and_serves_one_with_them(tmp_path):
    creds = tmp_path / "creds"
    creds.write_text(f"coordinator:{secrets.token_hex(16)}\nworker:{secrets.token_hex(16)}\n")
    creds.chmod(0o600)
    worker_creds = tmp_path / "worker"
    worker_creds.write_text(creds.read_text().splitlines()[1] + "\n")
    ep, out = free_endpoint(), tmp_path / "run.h5"
    router = start_router("--listen", ep, "--credentials", str(creds))
    coord = spinefarm("coordinator", "sphere:3", "--trials", "5", "--run-id", "routed", "--out", str(out),
                      "--connect", ep, "--api-port", "-1", "--quiet", "--credentials", str(creds))
    try:
        assert refused(ep), "a client without credentials opened a session"
        assert refused(ep, creds=load_credentials(_stranger(tmp_path))), "an unknown user opened a session"
        s = zenoh.open(zenoh_config("client", connect=[ep], credentials=load_credentials(worker_creds)))
        try:
            wait_status(out, lambda st: st["state"] == "running", "the coordinator")
            assert [r for r in s.get(keys.run_info("routed"), timeout=5.0) if r.ok], "no run info through the router"
        finally:
            s.close()
    finally:
        stop(coord)
        router.terminate()
        assert router.wait(10) == 0 and "router stopped" in router.stdout.read()


def test_the_router_with_the_deployments_tls_config_refuses_a_client_without_the_password(tmp_path):
    d = make_secrets(tmp_path)
    ep = f"tls/localhost:{free_endpoint().rsplit(':', 1)[1]}"
    router = start_router("--config", str(d / "router.json5"), "--listen", ep)
    try:
        assert refused(ep, config_file=d / "worker.json5"), "the certificate alone was let in"
        assert refused(ep, creds=load_credentials(d / "worker")), "the password alone was let in"
        assert not refused(ep, config_file=d / "worker.json5", creds=load_credentials(d / "worker"))
    finally:
        router.terminate()
        router.wait(10)


def _stranger(tmp_path):
    path = tmp_path / "stranger"
    path.write_text(f"worker:{secrets.token_hex(16)}\n")
    path.chmod(0o600)
    return path


def test_the_router_stops_on_a_sigterm_that_reaches_one_of_zenohs_threads():
    """A signal to the process may land on any of its threads; one on a Zenoh runtime thread once left the
    router's main thread waiting for ever (the handler runs only when the main thread runs Python)."""
    import ctypes
    import signal

    router = start_router("--listen", free_endpoint())
    try:
        others = [int(t) for t in os.listdir(f"/proc/{router.pid}/task") if int(t) != router.pid]
        assert others, "the router runs no thread besides its main one"
        libc = ctypes.CDLL(None, use_errno=True)
        assert libc.tgkill(router.pid, others[-1], int(signal.SIGTERM)) == 0, os.strerror(ctypes.get_errno())
        assert router.wait(10) == 0 and "router stopped" in router.stdout.read()
    finally:
        if router.poll() is None:
            router.kill()
            router.wait()
