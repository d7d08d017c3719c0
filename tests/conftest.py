"""Session-wide: calibrations (spinefarm calibrate, search --engine auto) cache into a temporary folder, never
into the user's cache, also in the processes tests start. Under CI (CI=true, as root, with what .ci/ensure-*
installs) a test that skips fails instead: only a developer's own run may skip, and it says why. A test marked
`ci_may_skip(reason=...)` is let off, with its reason."""

from __future__ import annotations

import os
import sys

import pytest


@pytest.fixture(autouse=True, scope="session")
def _calibration_cache(tmp_path_factory):
    os.environ["SPINEFARM_CACHE_DIR"] = str(tmp_path_factory.mktemp("spinefarm-cache"))
    yield


def under_ci() -> bool:
    return os.environ.get("CI", "").lower() == "true"


def _fail_skip_under_ci(item, report) -> None:
    """A skip (not an expected failure) under CI becomes a failure naming the skip's reason."""
    if not (report.skipped and under_ci()) or hasattr(report, "wasxfail"):
        return
    allowed = item.get_closest_marker("ci_may_skip")
    if allowed is not None and allowed.kwargs.get("reason"):
        return
    reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
    reason = reason.removeprefix("Skipped: ")
    report.outcome = "failed"
    report.longrepr = (f"skipped under CI ({reason}): CI runs as root and .ci/ensure-* installs what the tests "
                       "need, so this test must run there (mark it ci_may_skip(reason=...) only if it cannot)")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """A failed test shows the last lines each spinefarm process still on record wrote to stderr."""
    outcome = yield
    report = outcome.get_result()
    _fail_skip_under_ci(item, report)
    procs = sys.modules.get("tests.coordinator_tests.procs")
    if procs is None:
        return
    if report.failed:
        for args, path, _ in procs.STARTED:
            try:
                tail = procs.log_tail(path, 40)
            except OSError:
                continue
            report.sections.append((f"stderr of spinefarm {' '.join(args)[:120]}", tail))
    if report.when == "teardown":
        procs.forget_exited()
