"""--credentials: Zenoh user/password authentication, one flag on coordinator, search and worker."""

from __future__ import annotations

import secrets
import time

import pytest
import zenoh

from spinefarm.coordinator.service import zenoh_config
from spinefarm.protocol import keys
from spinefarm.protocol.credentials import load_credentials
from spinefarm.protocol.errors import ConfigError
from tests.coordinator_tests.helpers import free_endpoint
from tests.coordinator_tests.procs import coordinator, spinefarm, status, stop, wait_status

pytestmark = pytest.mark.integration


def write(path, *lines):
    path.write_text("".join(f"{ln}\n" for ln in lines))
    path.chmod(0o600)
    return path


def test_a_worker_without_valid_credentials_cannot_join_or_read_work(tmp_path):
    worker_pw = secrets.token_hex(16)
    all_users = write(tmp_path / "all", f"coordinator:{secrets.token_hex(16)}", f"worker:{worker_pw}")
    mine = write(tmp_path / "worker", f"worker:{worker_pw}")
    wrong = write(tmp_path / "wrong", f"worker:{secrets.token_hex(16)}")
    ep, out = free_endpoint(), tmp_path / "run.h5"
    coord = coordinator(ep, out, "sphere:3", "--trials", "40", "--run-id", "locked", "--credentials", str(all_users))
    outsiders = [spinefarm("worker", "--connect", ep, "--run", "locked", "--worker-id", f"outsider{i}",
                           *(["--credentials", str(f)] if f else [])) for i, f in enumerate((None, wrong))]
    try:
        wait_status(out, lambda st: st["state"] == "running", "the coordinator")
        # A bare session without credentials is refused at the link: it cannot even ask for work.
        with pytest.raises(zenoh.ZError):
            zenoh.open(zenoh_config("client", connect=[ep]))
        time.sleep(3.0)
        st = status(out)
        assert st["trials_sampled"] == 0 and st["workers"] == [] and all(p.poll() is None for p in outsiders)
        insider = spinefarm("worker", "--connect", ep, "--run", "locked", "--worker-id", "insider",
                            "--credentials", str(mine), "--exit-when-done")
        assert coord.wait(60) == 0 and insider.wait(30) == 0
        final = status(out)
        assert final["trials_complete"] == 40 and [w["worker_id"] for w in final["workers"]] == ["insider"]
    finally:
        stop(coord, *outsiders)


def test_an_authenticated_session_reads_run_info(tmp_path):
    creds = write(tmp_path / "c", f"coordinator:{secrets.token_hex(16)}")
    ep, out = free_endpoint(), tmp_path / "run.h5"
    coord = coordinator(ep, out, "sphere:3", "--trials", "5", "--run-id", "open", "--credentials", str(creds))
    try:
        wait_status(out, lambda st: st["state"] == "running", "the coordinator")
        s = zenoh.open(zenoh_config("client", connect=[ep], credentials=load_credentials(creds)))
        try:
            assert [r for r in s.get(keys.run_info("open"), timeout=5.0) if r.ok]
        finally:
            s.close()
    finally:
        stop(coord)


@pytest.mark.parametrize(("text", "message"), [
    ("", "holds no user"),
    ("alice\n", "line 1 is malformed"),
    ("# users\nalice:short\n", "line 2 is malformed"),
    ("a/b:" + "x" * 20 + "\n", "line 1 is malformed"),
])
def test_a_malformed_credentials_file_is_a_clear_error(tmp_path, text, message):
    (tmp_path / "c").write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_credentials(tmp_path / "c")


def test_the_compose_deployment_tls_and_passwords_let_its_services_in_and_nobody_else(tmp_path):
    """deploy/make-credentials.sh (the compose init service) and the configs it writes, with the compose
    topology on loopback: a Zenoh router from router.json5, the coordinator and a worker process as the
    compose file starts them. A client without the deployment's certificate, or with it but an unknown
    password, is refused; the files are made once and kept."""
    import os
    import shutil
    import subprocess

    from tests.coordinator_tests.procs import ROOT

    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed (the compose image installs it from Debian)")
    d = tmp_path / "secrets"
    env = dict(os.environ, SECRETS_DIR=str(d), SECRETS_OWNER=str(os.getuid()))
    for _ in range(2):
        subprocess.run(["sh", str(ROOT / "deploy" / "make-credentials.sh")], env=env, check=True, capture_output=True)
    first = (d / "credentials").read_text()
    assert [ln.split(":")[0] for ln in first.splitlines()] == ["coordinator", "worker"]
    assert (d / "worker").read_text() == first.splitlines()[1] + "\n"
    assert all((d / n).stat().st_mode & 0o077 == 0 for n in ("credentials", "ca.key", "worker.key", "router.key"))
    port = free_endpoint().rsplit(":", 1)[1]
    ep = f"tls/localhost:{port}"
    conf = zenoh.Config.from_file(str(d / "router.json5"))
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", f'["{ep}"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    router = zenoh.open(conf)
    out = tmp_path / "run.h5"
    coord = spinefarm("coordinator", "sphere:3", "--trials", "30", "--run-id", "compose", "--out", str(out),
                      "--connect", ep, "--api-port", "-1", "--quiet", "--credentials", str(d / "coordinator"),
                      "--zenoh-config", str(d / "coordinator.json5"))
    worker = spinefarm("worker", "--connect", ep, "--run", "compose", "--exit-when-done", "--credentials",
                       str(d / "worker"), "--zenoh-config", str(d / "worker.json5"))
    try:
        assert coord.wait(60) == 0 and worker.wait(30) == 0
        assert status(out)["trials_complete"] == 30
        stranger = write(tmp_path / "stranger", f"worker:{secrets.token_hex(16)}")
        attempts = [(None, load_credentials(d / "worker")),          # the password, but no certificate
                    (d / "worker.json5", load_credentials(stranger)),  # the certificate, a wrong password
                    (d / "worker.json5", None)]                        # the certificate, no password
        for config_file, creds in attempts:
            with pytest.raises(ConfigError):
                open_session(ep, config_file, creds)
    finally:
        stop(coord, worker)
        router.close()


def open_session(ep, config_file, creds):
    """A client session as the coordinator's zenoh_config builds it; ConfigError when refused."""
    from spinefarm.coordinator.service import zenoh_config

    try:
        zenoh.open(zenoh_config("client", connect=[ep], config_file=config_file, credentials=creds)).close()
    except zenoh.ZError as exc:
        raise ConfigError(str(exc)) from exc
