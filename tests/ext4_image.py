"""A real ext4 file system in an image file on a loop device, and a disk that dies under it.

`shutdown()` is the ext4 shutdown ioctl with EXT4_GOING_FLAGS_NOLOGFLUSH: the journal is not flushed,
so what was not synced is gone as after a power cut, and every later write or fsync fails with EIO.
(A read-only remount cannot stand in for a dying disk: the kernel refuses it with EBUSY while a file
is open for writing.) `remount()` unmounts the dead file system and mounts the image again, replaying
the journal as a reboot would. Needs root, mkfs.ext4 and a loop device.
"""

from __future__ import annotations

import fcntl
import os
import shutil
import struct
import subprocess
from pathlib import Path

EXT4_IOC_SHUTDOWN = 0x8004587D  # _IOR('X', 125, __u32)
EXT4_GOING_FLAGS_NOLOGFLUSH = 2


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(list(args), capture_output=True, text=True, timeout=60)


class Ext4Image:
    def __init__(self, directory: Path, size_mb: int = 64) -> None:
        self.image = directory / "disk.img"
        self.mnt = directory / "mnt"
        self.size_mb = size_mb
        self.mounted = False

    @staticmethod
    def unavailable() -> str | None:
        """Why an ext4 image cannot be mounted here, or None."""
        if os.geteuid() != 0:
            return "mounting a loop device needs root"
        if shutil.which("mkfs.ext4") is None:
            return "mkfs.ext4 is not installed"
        if not Path("/dev/loop-control").exists():
            return "no loop devices (/dev/loop-control is missing)"
        return None

    def open(self) -> Ext4Image:
        """Make the image and mount it; raises RuntimeError with the tool's message if that fails."""
        self.mnt.mkdir(parents=True, exist_ok=True)
        with open(self.image, "wb") as fh:
            fh.truncate(self.size_mb << 20)
        r = _run("mkfs.ext4", "-q", "-F", str(self.image))
        if r.returncode != 0:
            raise RuntimeError(f"mkfs.ext4 failed: {r.stderr.strip()}")
        self._mount()
        return self

    def _mount(self) -> None:
        r = _run("mount", "-t", "ext4", "-o", "loop", str(self.image), str(self.mnt))
        if r.returncode != 0:
            raise RuntimeError(f"cannot mount the ext4 image on a loop device: {r.stderr.strip()}")
        self.mounted = True

    def shutdown(self) -> None:
        """The disk dies now: nothing more reaches it and the unflushed journal is dropped."""
        fd = os.open(self.mnt, os.O_RDONLY | os.O_DIRECTORY)
        try:
            fcntl.ioctl(fd, EXT4_IOC_SHUTDOWN, struct.pack("I", EXT4_GOING_FLAGS_NOLOGFLUSH))
        finally:
            os.close(fd)

    def remount(self) -> None:
        """Unmount (every writer must have exited) and mount the image again, as after a reboot."""
        self.unmount()
        self._mount()

    def unmount(self) -> None:
        if self.mounted:
            r = _run("umount", str(self.mnt))
            if r.returncode != 0:
                raise RuntimeError(f"cannot unmount {self.mnt}: {r.stderr.strip()}")
            self.mounted = False

    def close(self) -> None:
        """Unmount (lazily if something still holds it) and delete the image; also after a failure."""
        if self.mounted:
            if _run("umount", str(self.mnt)).returncode != 0:
                _run("umount", "-l", str(self.mnt))
            self.mounted = False
        self.image.unlink(missing_ok=True)

    def __enter__(self) -> Ext4Image:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()
