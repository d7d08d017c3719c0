"""Session-wide: calibrations (spinefarm calibrate, search --engine auto) cache into a temporary folder, never
into the user's cache, also in the processes tests start."""

from __future__ import annotations

import os
import sys

import pytest


@pytest.fixture(autouse=True, scope="session")
def _calibration_cache(tmp_path_factory):
    os.environ["SPINEFARM_CACHE_DIR"] = str(tmp_path_factory.mktemp("spinefarm-cache"))
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """A failed test shows the last lines each spinefarm process still on record wrote to stderr."""
    outcome = yield
    report = outcome.get_result()
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
