"""The compose deployment run for real: build, search, kill, refuse, down/up, and check the run file.

docker-compose.yml with deploy/compose.offline.yml, under a project name of its own; its containers talk
only on the project's network (compose makes it) and publish the router and the API on loopback ports.
"""

from __future__ import annotations

import json
import socket
import time
import urllib.request
from pathlib import Path
from typing import Any

from tests.deploy.host import (
    BASE_IMAGE,
    ROOT,
    DeployError,
    docker,
    docker_env,
    log,
    sh,
    wait_until,
)
from tests.deploy.run_file import check_run_file

PROJECT = "spinefarm-deploy-test"
RUN_ID = "deploy-compose"
TRIALS = 150
WORKERS = 3
SEARCH_ARGS = "--rungs 0.4,1.2 --eta 3 --no-verify"
IMAGES = ("spinefarm-coordinator", "spinefarm-worker", "spinefarm-api", "spinefarm-credentials", BASE_IMAGE)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Compose:
    """docker-compose with the offline override, this test's project, settings and wheelhouse."""

    def __init__(self) -> None:
        self.api_port = free_port()
        self.env = dict(docker_env(), COMPOSE_DOCKER_CLI_BUILD="0", DOCKER_BUILDKIT="0", MORPHOLOGY="sphere:4",
                        TRIALS=str(TRIALS), RUN_ID=RUN_ID, SEED="5", SEARCH_ARGS=SEARCH_ARGS,
                        API_PORT=str(self.api_port), ZENOH_PORT=str(free_port()), BASE_IMAGE=BASE_IMAGE)

    def __call__(self, *args: str, timeout_s: float = 300.0, check: bool = True) -> str:
        files = ("-f", str(ROOT / "docker-compose.yml"), "-f", str(ROOT / "deploy" / "compose.offline.yml"))
        return sh("docker-compose", "-p", PROJECT, *files, *args, timeout_s=timeout_s, check=check,
                  env=self.env).stdout

    def container(self, service: str, index: int = 1) -> str:
        return f"{PROJECT}_{service}_{index}"

    def up(self) -> None:
        self("up", "-d", "--no-build", "--scale", f"worker={WORKERS}", timeout_s=300)


def volume_path(name: str) -> Path:
    return Path(docker("volume", "inspect", "-f", "{{.Mountpoint}}", f"{PROJECT}_{name}").stdout.strip())


def run_status(runs: Path) -> dict[str, Any]:
    try:
        return json.loads((runs / f"{RUN_ID}.h5.status.json").read_text())
    except (OSError, ValueError):
        return {}


def wait_complete(runs: Path, count: int, timeout_s: float = 180.0) -> dict[str, Any]:
    return wait_until(lambda: (st := run_status(runs)).get("trials_complete", 0) >= count and st, timeout_s,
                      f"{count} complete trials in {RUN_ID}")


def state(container: str) -> tuple[str, int]:
    out = docker("inspect", "-f", "{{.State.Status}} {{.State.ExitCode}}", container, check=False).stdout.split()
    return (out[0], int(out[1])) if len(out) == 2 else ("missing", -1)


def http_json(port: int, path: str) -> Any:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=10) as reply:
        body = reply.read()
    return json.loads(body) if path != "/" else body.decode()


def build(compose: Compose) -> dict[str, Any]:
    t0 = time.monotonic()
    log("building the images (docker-compose build)")
    compose("build", timeout_s=1800)
    sizes = {}
    for image in IMAGES:
        size = docker("image", "inspect", "-f", "{{.Size}}", image).stdout.strip()
        sizes[image.split(":")[0]] = round(int(size) / 1e6)
    simulators = docker("run", "--rm", "--entrypoint", "python", "spinefarm-api", "-c",
                        "import importlib.util as u; print([m for m in ('pybullet', 'mujoco', 'numba', 'zenoh') "
                        "if u.find_spec(m)])").stdout.strip()
    if simulators != "[]":
        raise DeployError(f"the API image carries {simulators}; it should carry no simulator")
    return {"build_s": round(time.monotonic() - t0, 1), "image_sizes_mb": sizes, "api_image_simulators": []}


def refused_intruder(compose: Compose, runs: Path) -> dict[str, Any]:
    """A worker container with the deployment's TLS certificate but no password: the router refuses it."""
    name = f"{PROJECT}-intruder"
    docker("rm", "-f", name, check=False)
    docker("run", "-d", "--name", name, "--network", f"{PROJECT}_default", "-v", f"{PROJECT}_secrets:/secrets:ro",
           "spinefarm-worker", "worker", "--connect", "tls/router:7447", "--zenoh-config", "/secrets/worker.json5",
           "--worker-id", "intruder")
    try:
        # the worker names the refusal (or, while the handshake hangs, that nothing answers it)
        said = ("refused by", "no Zenoh session has answered", "cannot reach")
        logs = wait_until(lambda: any(s in (text := docker("logs", name).stderr) for s in said) and text, 60,
                          "the intruder worker to report that the router refuses it")
        listed = [w["worker_id"] for w in run_status(runs).get("workers", [])]
        if "intruder" in listed:
            raise DeployError("a worker without credentials took work from the run")
        if state(name)[0] != "running":
            raise DeployError(f"the intruder worker stopped instead of being refused: {logs[-300:]}")
    finally:
        docker("rm", "-f", name, check=False)
    return {"intruder_refused": True, "intruder_log": logs.strip().splitlines()[-1][-160:]}


def check_api(port: int) -> dict[str, Any]:
    runs = wait_until(lambda: _try(http_json, port, "/runs"), 60, "the API container to answer /runs")
    ids = [r.get("run_id") for r in runs] if isinstance(runs, list) else list(runs)
    if RUN_ID not in json.dumps(runs):
        raise DeployError(f"the API's /runs does not list {RUN_ID}: {ids}")
    best = http_json(port, f"/runs/{RUN_ID}/best?k=3")
    page = http_json(port, "/")
    if "<html" not in page.lower():
        raise DeployError("the API's dashboard / is not an HTML page")
    top = best[0] if isinstance(best, list) else best.get("trials", [best])[0]
    return {"api_runs": len(ids), "api_best_objective": top.get("objective"), "dashboard_bytes": len(page)}


def _try(fn, *args):
    try:
        return fn(*args)
    except (OSError, ValueError):
        return None


def scenario(compose: Compose) -> dict[str, Any]:
    """Up with 3 workers, kill a worker, kill the coordinator, up, refuse an intruder, down, up, finish."""
    figures: dict[str, Any] = {}
    compose("down", "-v", "--remove-orphans", timeout_s=300, check=False)
    t0 = time.monotonic()
    compose.up()
    runs = volume_path("runs")
    wait_complete(runs, 25)
    log("killing a worker container mid-run")
    docker("kill", compose.container("worker", 2))
    wait_complete(runs, 45)
    log("killing the coordinator container mid-run, then up again")
    killed_at = run_status(runs).get("trials_complete", 0)
    docker("kill", compose.container("coordinator"))
    compose.up()
    wait_complete(runs, killed_at + 15)
    figures.update(refused_intruder(compose, runs))
    log("down (volumes kept) mid-run, then up: the coordinator resumes the run file")
    compose("down", timeout_s=300)
    down_at = run_status(runs).get("trials_complete", 0)
    compose.up()
    coord = compose.container("coordinator")
    wait_until(lambda: state(coord)[0] == "exited", 300, "the coordinator to finish the run")
    if state(coord)[1] != 0:
        raise DeployError(f"the coordinator exited {state(coord)[1]}: {docker('logs', coord).stderr[-400:]}")
    figures["search_s"] = round(time.monotonic() - t0, 1)
    figures.update(check_api(compose.api_port))
    figures.update({"killed_coordinator_at": killed_at, "down_at": down_at})
    figures.update(check_run_file(runs / f"{RUN_ID}.h5", TRIALS))
    return figures


def run() -> dict[str, Any]:
    (ROOT / "deploy" / "wheels").mkdir(exist_ok=True)
    compose = Compose()
    figures = build(compose)
    try:
        figures.update(scenario(compose))
    except DeployError:
        _dump_logs(compose)
        raise
    finally:
        compose("down", "-v", "--remove-orphans", timeout_s=300, check=False)
    return figures


def _dump_logs(compose: Compose) -> None:
    text = compose("logs", "--no-color", "--tail", "30", timeout_s=60, check=False)
    log("last lines of the services' logs:\n" + text[-6000:])
