"""Under CI a skip fails the run (tests/conftest.py): checked on a throw-away test file run with CI=true and
without it, in a child pytest."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEMO = '''
import pytest

def test_needs_a_tool():
    pytest.skip("the tool is not installed")

@pytest.mark.ci_may_skip(reason="needs hardware CI has not")
def test_allowed():
    pytest.skip("no such hardware")

@pytest.mark.xfail(reason="known")
def test_expected_failure():
    assert False
'''


def _run(tmp_path: Path, ci: str | None) -> subprocess.CompletedProcess:
    (tmp_path / "conftest.py").write_text((ROOT / "tests" / "conftest.py").read_text())
    (tmp_path / "test_demo.py").write_text(DEMO)
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    if ci is not None:
        env["CI"] = ci
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:randomly", "-p", "no:cacheprovider",
                           "-rA", "-o", "addopts=", "-c", os.devnull, str(tmp_path)], capture_output=True, text=True,
                          env=env, cwd=tmp_path, timeout=120)


def test_a_skip_fails_under_ci_and_only_there(tmp_path):
    local = _run(tmp_path, None)
    assert local.returncode == 0 and "2 skipped, 1 xfailed" in local.stdout, local.stdout
    ci = _run(tmp_path, "true")
    assert ci.returncode == 1, ci.stdout
    assert "1 failed, 1 skipped, 1 xfailed" in ci.stdout, ci.stdout
    assert "skipped under CI (the tool is not installed)" in ci.stdout, ci.stdout
