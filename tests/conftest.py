"""Session-wide: calibrations (spinefarm calibrate, search --engine auto) cache into a temporary folder, never
into the user's cache, also in the processes tests start."""

from __future__ import annotations

import os

import pytest


@pytest.fixture(autouse=True, scope="session")
def _calibration_cache(tmp_path_factory):
    os.environ["SPINEFARM_CACHE_DIR"] = str(tmp_path_factory.mktemp("spinefarm-cache"))
    yield
