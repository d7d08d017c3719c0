"""Where the environment record's CPU and commit come from, read independently: /proc/cpuinfo's model name
(platform's guess where it cannot be read), and `git` in a checkout of the module's own, "+dirty" exactly when a
tracked file changed (protocol.environment)."""

from __future__ import annotations

import importlib.util
import platform
import re
import shutil
import subprocess
from pathlib import Path

from spinefarm.protocol import environment

ROOT = Path(__file__).resolve().parents[2]


def test_the_cpu_is_proc_cpuinfos_model_name_else_platforms_guess(monkeypatch) -> None:
    text = Path("/proc/cpuinfo").read_text()
    name = re.search(r"^model name\s*:\s*(.*)$", text, re.M)
    # some CPUs (arm) have no "model name" line: platform's machine then
    assert environment._cpu()[0] == (name.group(1).strip() if name else platform.machine())

    class Unreadable:
        def __init__(self, _path: str) -> None:
            pass

        def read_text(self) -> str:
            raise OSError("no /proc here")

    monkeypatch.setattr(environment, "Path", Unreadable)
    monkeypatch.setattr(platform, "processor", lambda: "")  # as on Linux: platform knows no processor name
    assert environment._cpu() == (platform.machine(), "")
    monkeypatch.setattr(platform, "processor", lambda: "Some CPU")
    assert environment._cpu() == ("Some CPU", "")


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t", *args], check=True,
                          capture_output=True, text=True).stdout.strip()


def test_the_commit_of_its_own_checkout_and_dirty_when_a_tracked_file_changed(tmp_path) -> None:
    copy = tmp_path / "spinefarm" / "protocol" / "environment.py"
    copy.parent.mkdir(parents=True)
    shutil.copy(ROOT / "spinefarm" / "protocol" / "environment.py", copy)
    (tmp_path / "README.md").write_text("a\n")
    _git(tmp_path, "init", "-q")
    _git(tmp_path, "add", "-A")
    _git(tmp_path, "commit", "-qm", "x")
    spec = importlib.util.spec_from_file_location("own_checkout_environment", copy)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    head = _git(tmp_path, "rev-parse", "HEAD")
    assert module._commit() == head
    (tmp_path / "notes.txt").write_text("untracked\n")  # an untracked file does not make it dirty
    assert module._commit() == head
    (tmp_path / "README.md").write_text("b\n")
    assert module._commit() == head + "+dirty"
