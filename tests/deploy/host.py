"""The host side of the deployment test: packages, a private dockerd, the cached base image and wheelhouse.

Everything made here is either stopped by the caller's ExitStack (dockerd) or kept on purpose as a cache
under CACHE_DIR, keyed by a hash of what builds it, so a second run on the same machine is warm.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Sequence
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CACHE_DIR = Path(os.environ.get("SPINEFARM_DEPLOY_CACHE", "/var/cache/spinefarm-deploy"))
RUN_DIR = Path("/run/spinefarm-deploy")
DOCKER_SOCKET = RUN_DIR / "docker.sock"
DOCKER = "/usr/bin/docker"  # the engine's own client (another docker CLI on PATH may be newer than the engine)
PACKAGES = ("docker.io", "docker-compose", "debootstrap", "slurm-wlm", "munge", "openssl", "iptables")
BASE_IMAGE = "spinefarm-base:bookworm"
BASE_INCLUDE = "python3,python3-venv,python3-pip,ca-certificates"


class DeployError(RuntimeError):
    """A step of the deployment test failed; the message says which and why, in one line."""


class HostUnfit(DeployError):
    """This host cannot run the deployment at all (no packages, no container runtime, no daemons): nothing of
    ours was tested, which is said as such rather than as a failure of the deployment."""


@contextmanager
def host_prerequisite(what: str):
    """A failure inside is the host's, not the deployment's: re-raised as HostUnfit naming `what`."""
    try:
        yield
    except HostUnfit:
        raise
    except DeployError as exc:
        raise HostUnfit(f"{what}: {exc}") from exc


def log(message: str) -> None:
    print(f"[test-deploy {time.strftime('%H:%M:%S')}] {message}", file=sys.stderr, flush=True)


def sh(*cmd: str | Path, timeout_s: float = 600.0, check: bool = True, env: dict[str, str] | None = None,
       input_bytes: bytes | None = None) -> subprocess.CompletedProcess[str]:
    """Run a command to its end within timeout_s; a failure is a DeployError naming it and its last output."""
    args = [str(c) for c in cmd]
    try:
        proc = subprocess.run(args, capture_output=True, timeout=timeout_s, env=env, input=input_bytes)
    except subprocess.TimeoutExpired as exc:
        raise DeployError(f"`{' '.join(args)[:200]}` did not finish within {timeout_s:.0f} s") from exc
    out = proc.stdout.decode(errors="replace")
    err = proc.stderr.decode(errors="replace")
    if check and proc.returncode != 0:
        tail = (err.strip() or out.strip()).splitlines()[-5:]
        raise DeployError(f"`{' '.join(args)[:200]}` exited {proc.returncode}: {' | '.join(tail)}")
    return subprocess.CompletedProcess(args, proc.returncode, out, err)


def wait_until(predicate, timeout_s: float, what: str, poll_s: float = 0.5):
    """predicate() until it is truthy; DeployError naming `what` after timeout_s."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise DeployError(f"timed out after {timeout_s:.0f} s waiting for {what}")
        time.sleep(poll_s)


def install_packages() -> float:
    """apt-get the tools the test drives (a fresh machine has none of them); returns the seconds it took."""
    t0 = time.monotonic()
    missing = [p for p in PACKAGES if sh("dpkg-query", "-W", "-f=${Status}", p, check=False).stdout
               != "install ok installed"]
    if missing:
        log(f"installing {' '.join(missing)}")
        env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
        with host_prerequisite("cannot install the packages the deployment needs"):
            sh("apt-get", "update", "-q", timeout_s=600, env=env)
            sh("apt-get", "install", "-y", "-q", "--no-install-recommends", *missing, timeout_s=1200, env=env)
    return time.monotonic() - t0


def docker_env() -> dict[str, str]:
    return dict(os.environ, DOCKER_HOST=f"unix://{DOCKER_SOCKET}")


def docker(*args: str | Path, timeout_s: float = 300.0, check: bool = True) -> subprocess.CompletedProcess[str]:
    return sh(DOCKER, *args, timeout_s=timeout_s, check=check, env=docker_env())


def storage_driver() -> str:
    """overlay2 where the kernel mounts overlays (each layer holds only its changes), else vfs (every layer
    a full copy: slow and large, but it works everywhere); SPINEFARM_DOCKER_STORAGE picks one."""
    chosen = os.environ.get("SPINEFARM_DOCKER_STORAGE")
    if chosen:
        return chosen
    probe = RUN_DIR / "overlay-probe"
    for sub in ("lower", "upper", "work", "merged"):
        (probe / sub).mkdir(parents=True, exist_ok=True)
    opts = f"lowerdir={probe / 'lower'},upperdir={probe / 'upper'},workdir={probe / 'work'}"
    mounted = sh("mount", "-t", "overlay", "overlay", "-o", opts, probe / "merged", check=False).returncode == 0
    if mounted:
        sh("umount", probe / "merged", check=False)
    shutil.rmtree(probe, ignore_errors=True)
    return "overlay2" if mounted else "vfs"


def start_dockerd(driver: str) -> subprocess.Popen[bytes]:
    """A dockerd of our own (its own socket, and state under CACHE_DIR per storage driver), ready to take
    commands."""
    RUN_DIR.mkdir(parents=True, exist_ok=True)
    data_root = CACHE_DIR / f"docker-{driver}"
    data_root.mkdir(parents=True, exist_ok=True)
    pidfile = RUN_DIR / "dockerd.pid"
    if pidfile.exists():  # a dockerd of an earlier run that was killed: it must not hold our socket
        _stop_stale(pidfile)
    log_file = open(CACHE_DIR / "dockerd.log", "wb")  # noqa: SIM115 (lives as long as the daemon)
    proc = subprocess.Popen(["dockerd", f"--storage-driver={driver}", f"--data-root={data_root}",
                             f"--exec-root={RUN_DIR / 'exec'}", f"--pidfile={pidfile}",
                             f"--host=unix://{DOCKER_SOCKET}"], stdout=log_file, stderr=subprocess.STDOUT)

    def ready() -> bool:
        if proc.poll() is not None:
            raise DeployError(f"dockerd exited {proc.returncode}; see {CACHE_DIR / 'dockerd.log'}")
        return docker("info", "--format", "{{.Driver}}", check=False, timeout_s=10).returncode == 0

    with host_prerequisite("this host cannot run dockerd"):
        wait_until(ready, 60, "dockerd to answer")
    return proc


def probe_containers(image: str) -> None:
    """One throw-away container of `image`: a host whose kernel or sandbox forbids containers says so here."""
    with host_prerequisite(f"this host cannot start a container of {image}"):
        docker("run", "--rm", "--network", "none", image, "true", timeout_s=120)


def _stop_stale(pidfile: Path) -> None:
    try:
        pid = int(pidfile.read_text().strip())
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
    except (OSError, ValueError):
        pidfile.unlink(missing_ok=True)
        return
    if b"dockerd" in cmdline and str(DOCKER_SOCKET).encode() in cmdline:
        log(f"stopping the dockerd a killed earlier run left (pid {pid})")
        os.kill(pid, 15)
        wait_until(lambda: not Path(f"/proc/{pid}").exists(), 30, "the stale dockerd to stop")
    pidfile.unlink(missing_ok=True)


def stop_dockerd(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)


def apt_mirror() -> str:
    """The Debian mirror this machine's apt uses (deb822 or one-line sources)."""
    for path in [*sorted(Path("/etc/apt").glob("sources.list.d/*.sources")), Path("/etc/apt/sources.list")]:
        if not path.is_file():
            continue
        for line in path.read_text().splitlines():
            words = line.split()
            if words[:1] == ["URIs:"] and words[1:] and "security" not in words[1]:
                return words[1]
            if words[:1] == ["deb"] and "security" not in line:
                return next(w for w in words[1:] if "://" in w)
    raise DeployError("no Debian mirror in /etc/apt/sources.list*: cannot debootstrap the base image")


def digest(*parts: str | bytes) -> str:
    h = hashlib.sha256()
    for part in parts:
        h.update(part if isinstance(part, bytes) else part.encode())
        h.update(b"\0")
    return h.hexdigest()[:16]


def base_image() -> dict[str, object]:
    """spinefarm-base:bookworm from a debootstrap rootfs, cached as a tarball keyed by what builds it."""
    t0 = time.monotonic()
    mirror = apt_mirror()
    key = digest("bookworm", "minbase", BASE_INCLUDE, mirror)
    tarball = CACHE_DIR / f"base-{key}.tar"
    cached = tarball.exists()
    if not cached:
        log(f"debootstrap bookworm from {mirror} (cold cache: a few minutes)")
        rootfs = CACHE_DIR / f"rootfs-{key}"
        shutil.rmtree(rootfs, ignore_errors=True)
        sh("debootstrap", "--variant=minbase", f"--include={BASE_INCLUDE}", "bookworm", rootfs, mirror,
           timeout_s=1500)
        sh("rm", "-rf", *rootfs.glob("var/cache/apt/archives/*.deb"), *rootfs.glob("var/lib/apt/lists/*_Packages"))
        sh("tar", "-C", rootfs, "-cf", f"{tarball}.part", ".", timeout_s=600)
        os.replace(f"{tarball}.part", tarball)
        shutil.rmtree(rootfs, ignore_errors=True)
    label = docker("image", "inspect", "-f", "{{index .Config.Labels \"key\"}}", BASE_IMAGE, check=False).stdout
    if label.strip() != key:
        with open(tarball, "rb") as f:
            sh(DOCKER, "import", "--change", f"LABEL key={key}", "-", BASE_IMAGE, env=docker_env(),
               input_bytes=f.read(), timeout_s=600)
    return {"cached": cached, "seconds": round(time.monotonic() - t0, 1), "key": key}


def wheelhouse(python: str, target: Path, extras: Sequence[str]) -> dict[str, object]:
    """Wheels of everything the images install (not spinefarm itself: the images build it from the source),
    made on this host with pip (which reaches the index) and cached by a hash of pyproject.toml."""
    t0 = time.monotonic()
    pyproject = (ROOT / "pyproject.toml").read_bytes()
    key = digest(pyproject, ",".join(extras), sys.version.split()[0])
    cache = CACHE_DIR / f"wheels-{key}"
    cached = cache.is_dir()
    if not cached:
        log("pip wheel: the wheelhouse of the images")
        part = CACHE_DIR / f"wheels-{key}.part"
        shutil.rmtree(part, ignore_errors=True)
        part.mkdir(parents=True)
        requirements = sh(python, ROOT / "deploy" / "requirements.py", ROOT / "pyproject.toml", ",".join(extras))
        (part / "requirements.txt").write_text(requirements.stdout)
        sh(python, "-m", "pip", "wheel", "-q", "--wheel-dir", part, "-r", part / "requirements.txt",
           "setuptools>=77", "wheel", "pip", timeout_s=1500, env=dict(os.environ, PIP_DISABLE_PIP_VERSION_CHECK="1"))
        os.replace(part, cache)
    for old in target.glob("*.whl"):
        old.unlink()
    for wheel in cache.glob("*.whl"):
        try:
            os.link(wheel, target / wheel.name)
        except OSError:
            shutil.copy2(wheel, target / wheel.name)
    return {"cached": cached, "seconds": round(time.monotonic() - t0, 1), "wheels": len(list(cache.glob("*.whl")))}
