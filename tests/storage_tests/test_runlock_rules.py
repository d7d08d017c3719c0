"""The run lock's rules on real files, in one process (storage/runlock.py's docstring): the name lock beside the
resolved path, the identity lock on the file's inode (a hard link finds it held), `bind` moving it to a new
file, the holder's pid for messages, both dropped on release. flock and OFD locks belong to the open file
description, so two opens in one process contend as two coordinators would."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from spinefarm.protocol.errors import StorageError
from spinefarm.storage.runlock import RunLock, lock_path


def test_the_name_lock_sits_beside_the_resolved_file(tmp_path: Path) -> None:
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "run.h5").write_bytes(b"x")
    (tmp_path / "link.h5").symlink_to(tmp_path / "data" / "run.h5")
    assert lock_path(tmp_path / "link.h5") == (tmp_path / "data" / "run.h5.lock").resolve()
    assert lock_path(tmp_path / "new.h5") == (tmp_path / "new.h5.lock").resolve()


def test_a_second_taker_is_refused_with_the_holders_pid_and_may_take_it_after_release(tmp_path: Path) -> None:
    run = tmp_path / "a" / "b" / "run.h5"      # a file (and directories) that do not exist yet: --overwrite
    first = RunLock(run)
    assert not first.held
    assert first.acquire() is first and first.held
    sidecar = tmp_path / "a" / "b" / "run.h5.lock"
    assert sidecar.read_text() == f"{os.getpid()}\n"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(sidecar.stat().st_mode) == 0o644 & ~umask   # readable by all, written by its owner
    with pytest.raises(StorageError, match=f"another coordinator.*pid {os.getpid()}") as refused:
        RunLock(run).acquire()
    assert str(run) in str(refused.value)      # names the file it was asked for
    first.release()
    assert not first.held
    first.release()                             # twice is harmless
    second = RunLock(run).acquire()
    assert second.held
    second.release()


def test_a_hard_link_to_a_held_file_is_refused_by_its_inode(tmp_path: Path) -> None:
    run, hard = tmp_path / "run.h5", tmp_path / "other" / "hard.h5"
    run.write_bytes(b"run")
    hard.parent.mkdir()
    os.link(run, hard)
    held = RunLock(run).acquire()
    try:
        with pytest.raises(StorageError, match=f"inode {os.stat(run).st_ino}") as refused:
            RunLock(hard).acquire()
        assert str(hard) in str(refused.value)
        # the refused taker dropped its name lock: the link's sidecar is free again
        assert held.held
    finally:
        held.release()
    RunLock(hard).acquire().release()           # released: the link may be taken


def test_bind_moves_the_identity_lock_to_the_new_file(tmp_path: Path) -> None:
    run, copy = tmp_path / "run.h5", tmp_path / "run.h5.resume-tmp"
    run.write_bytes(b"old")
    copy.write_bytes(b"new")
    old_link, new_link = tmp_path / "old-link.h5", tmp_path / "new-link.h5"
    os.link(run, old_link)
    os.link(copy, new_link)
    lock = RunLock(run).acquire()
    try:
        lock.bind(copy)
        RunLock(old_link).acquire().release()   # the old file is no longer held
        with pytest.raises(StorageError, match="inode"):
            RunLock(new_link).acquire()
    finally:
        lock.release()
    RunLock(new_link).acquire().release()       # release dropped the identity lock too


def test_release_drops_the_identity_lock_of_an_existing_file(tmp_path: Path) -> None:
    run, hard = tmp_path / "run.h5", tmp_path / "hard.h5"
    run.write_bytes(b"run")
    os.link(run, hard)
    lock = RunLock(run).acquire()
    lock.release()
    RunLock(hard).acquire().release()
