"""The writer lock follows the file, not its name: a symlink or a hard link to a live run file is refused."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from spinefarm.coordinator.setup import resume_run
from spinefarm.protocol.errors import StorageError
from spinefarm.storage.hdf5_reader import read_run
from tests.coordinator_tests.helpers import free_endpoint, sphere_core
from tests.coordinator_tests.procs import ROOT, coordinator, stop, wait_status


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def links(tmp_path: Path, target: Path) -> tuple[Path, Path]:
    (tmp_path / "elsewhere").mkdir()
    sym, hard = tmp_path / "elsewhere" / "sym.h5", tmp_path / "hard.h5"
    sym.symlink_to(target)
    os.link(target, hard)
    return sym, hard


def test_resume_through_a_symlink_or_a_hard_link_to_a_live_file_is_refused(tmp_path):
    path = tmp_path / "run.h5"
    _, storage, _ = sphere_core(out=path)
    try:
        sym, hard = links(tmp_path, path)
        before = digest(path)
        for link in (sym, hard):
            with pytest.raises(StorageError, match="another coordinator"):
                resume_run(link)
        assert sym.is_symlink() and os.stat(hard).st_ino == os.stat(path).st_ino
        assert digest(path) == before
        assert not list(tmp_path.rglob("*.resume-tmp"))
    finally:
        storage.close()
    # released on close; a resume through the symlink replaces its target and keeps the link a link
    _, storage2 = resume_run(sym)
    try:
        assert sym.is_symlink() and read_run(path)[0].run_id == "test-run"
        with pytest.raises(StorageError, match="another coordinator"):
            resume_run(path)  # the resumed file (a new inode) is held too
    finally:
        storage2.close()


def test_search_resume_through_links_to_a_live_coordinators_file_exits_2(tmp_path):
    path, ep = tmp_path / "run.h5", free_endpoint()
    first = coordinator(ep, path, "sphere:3", "--trials", "100000", "--run-id", "first")
    try:
        wait_status(path, lambda st: st["state"] == "running", "the first coordinator")
        sym, hard = links(tmp_path, path)
        for link in (sym, hard):
            r = subprocess.run([sys.executable, "-m", "spinefarm", "search", "--resume", str(link), "--workers", "0",
                                "--api-port", "-1"], cwd=ROOT, capture_output=True, text=True, timeout=60)
            assert r.returncode == 2, r.stderr
            assert "being written by another coordinator" in r.stderr, r.stderr
        assert sym.is_symlink() and os.stat(hard).st_ino == os.stat(path).st_ino
        assert first.poll() is None
    finally:
        stop(first)


def test_after_a_resume_a_hard_link_to_the_new_file_is_refused(tmp_path):
    """A resume writes a fresh copy and renames it over the run file (a new inode): the identity lock must
    follow it. A hard link made afterwards has a name (and a name lock) of its own, so only the identity lock
    can refuse it."""
    path = tmp_path / "run.h5"
    _, storage, _ = sphere_core(out=path)
    storage.close()  # may itself write a compressed copy: the inode to compare is the closed file's
    old_inode = os.stat(path).st_ino
    held = os.open(path, os.O_RDONLY)  # keeps the old inode allocated, so the copy cannot be given its number
    try:
        _, resumed = resume_run(path)
    finally:
        os.close(held)
    try:
        assert os.stat(path).st_ino != old_inode  # the resume's fresh copy
        hard = tmp_path / "hard-after-resume.h5"
        os.link(path, hard)
        before = digest(path)
        with pytest.raises(StorageError, match="another coordinator"):
            resume_run(hard)
        assert digest(path) == before and os.stat(hard).st_ino == os.stat(path).st_ino
    finally:
        resumed.close()
