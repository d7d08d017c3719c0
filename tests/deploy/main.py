"""`make test-deploy`: the compose and SLURM deployments run end to end on this machine, as root.

Installs what it needs (apt), starts its own dockerd and SLURM daemons and stops them at the end, even on
failure. Prints one JSON object with the figures (timings, image sizes, what each run stored).
    python -m tests.deploy.main [--only compose|slurm]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from contextlib import ExitStack
from typing import Any

from tests.deploy import host

NOT_RUN = 3  # the exit code when the host, not the deployment, is what failed (0 with --allow-unfit-host)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="test-deploy", description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=("compose", "slurm"), help="run one of the two deployments")
    parser.add_argument("--allow-unfit-host", action="store_true",
                        help="exit 0 (saying NOT RUN) when this host cannot run containers or the SLURM daemons at "
                             "all; a deployment that runs and fails still fails")
    args = parser.parse_args(argv)
    if os.geteuid() != 0:
        print("test-deploy skipped: it needs root (it installs packages with apt and starts dockerd, munge and "
              "SLURM); run `sudo make test-deploy`", file=sys.stderr)
        return 0
    t0 = time.monotonic()
    report: dict[str, Any] = {"host": os.uname().nodename, "cpus": os.cpu_count()}
    try:
        report.update(run(args.only))
    except host.HostUnfit as exc:
        print(f"test-deploy: NOT RUN, this host cannot run it ({time.monotonic() - t0:.0f} s): {exc}",
              file=sys.stderr)
        return 0 if args.allow_unfit_host else NOT_RUN
    except host.DeployError as exc:
        print(f"test-deploy: FAILED after {time.monotonic() - t0:.0f} s: {exc}", file=sys.stderr)
        return 1
    report["total_s"] = round(time.monotonic() - t0, 1)
    print(json.dumps(report, indent=1))
    print(f"test-deploy: passed in {report['total_s']:.0f} s", file=sys.stderr)
    return 0


def run(only: str | None) -> dict[str, Any]:
    report: dict[str, Any] = {"apt_s": round(host.install_packages(), 1)}
    with ExitStack() as stack:
        if only in (None, "compose"):
            from tests.deploy import compose_check

            report["docker_storage"] = driver = host.storage_driver()
            dockerd = host.start_dockerd(driver)
            stack.callback(host.stop_dockerd, dockerd)
            report["base_image"] = host.base_image()
            host.probe_containers(host.BASE_IMAGE)
            wheels = host.ROOT / "deploy" / "wheels"
            report["wheelhouse"] = host.wheelhouse(sys.executable, wheels, ("worker", "coordinator", "api"))
            stack.callback(_empty, wheels)
            report["compose"] = compose_check.run()
        if only in (None, "slurm"):
            from tests.deploy import slurm_check

            report["slurm"] = slurm_check.run(stack)
    return report


def _empty(wheels) -> None:
    for wheel in wheels.glob("*.whl"):
        wheel.unlink()


if __name__ == "__main__":
    sys.exit(main())
