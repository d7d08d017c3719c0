"""Damaged run files fail fast instead of hanging their readers.

HDF5 opened for SWMR reading (needed while a writer is live or after one was killed) skips its
truncation check and retries unreadable metadata for a very long time while holding h5py's global
lock, so one truncated or corrupted file would hang every reader in the process and keep it from
handling SIGTERM. Two guards:

- `check_eof`: the superblock (48 bytes) states the file's end; a shorter file is truncated. Cheap,
  done before every open.
- `probe`: read the whole file in a child process with a deadline; a child that hangs is killed and
  the file reported as damaged. Done once per file (resume, export, load_run, the API's first sight of
  a file). It also clears the "open for writing" flags a killed writer left (`clear_stale_write_flags`,
  only when no coordinator holds the file), so h5py, h5dump or pandas open it without --resume. A file
  whose flags are then clear has no writer: the child reads it as a plain (not SWMR) reader, which tries
  damaged metadata once, so a corrupted file fails in a fraction of a second with HDF5's own words;
  only a file a writer has open is read as SWMR, where the deadline is the guard.
"""

from __future__ import annotations

import os
import select
import struct
import subprocess
import sys
import time
from pathlib import Path

from spinefarm.protocol.errors import StorageError

PROBE_TIMEOUT_S = 10.0
START_TIMEOUT_S = 120.0  # a child that has not even imported h5py by then: the machine is overloaded
_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_SAID = 3  # the child's exit code when it read the file and said what is wrong (its last stderr line)
_PROBE_CODE = (
    "import sys\n"
    "from spinefarm.protocol.errors import StorageError\n"
    "from spinefarm.storage.hdf5_reader import read_run\n"
    "print('ready', flush=True)\n"
    "try:\n"
    "    meta, cols = read_run(sys.argv[1], swmr=sys.argv[2] == 'swmr')\n"
    "except StorageError as exc:\n"
    "    print(str(exc).replace(chr(10), ' '), file=sys.stderr)\n"
    f"    sys.exit({_SAID})\n"
    "print(meta.run_id)\n"
)


def stored_eof(head: bytes) -> int | None:
    """End-of-file address from a version 2/3 superblock at the start of `head`, else None."""
    for base in (0, 512, 1024, 2048):  # a user block moves the superblock to a power of two >= 512
        if head[base:base + 8] != _SIGNATURE:
            continue
        version, size_of_offsets = head[base + 8], head[base + 9]
        if version < 2 or size_of_offsets != 8:
            return None  # older layouts: HDF5 checks these itself
        # signature 8, version 1, offsets 1, lengths 1, flags 1, base address 8, extension 8, eof 8
        (base_addr, eof) = struct.unpack_from("<Q8xQ", head, base + 12)
        return base_addr + eof
    return None


def check_eof(path: str | Path, settle_s: float = 0.3) -> None:
    """Raise StorageError if the file is shorter than its superblock says (or is not HDF5 at all).

    A live SWMR writer may have announced space it has not written yet; the check is repeated for
    `settle_s` before a short file counts as truncated.
    """
    path = Path(path)
    end = time.monotonic() + settle_s
    while True:
        try:
            with open(path, "rb") as fh:
                head = fh.read(2048 + 48)
                size = os.fstat(fh.fileno()).st_size
        except OSError as exc:
            raise StorageError(f"cannot read run file {path}: {exc.strerror}", expected="a readable file") from exc
        if _SIGNATURE not in head[:2048 + 8]:
            raise StorageError(f"cannot open run file {path}: not an HDF5 file",
                               received=f"{size} bytes starting {head[:8]!r}", expected="a spinefarm run file")
        eof = stored_eof(head)
        if eof is None or size >= eof:
            return
        if time.monotonic() >= end:
            raise StorageError(f"run file {path} is truncated", received=f"{size} bytes",
                               expected=f"{eof} bytes, as its header says")
        time.sleep(0.05)


def probe(path: str | Path, timeout_s: float = PROBE_TIMEOUT_S, start_timeout_s: float = START_TIMEOUT_S) -> str:
    """Read the whole file in a child process within `timeout_s`; its run id, else StorageError.

    The deadline counts from when the child has started (imported h5py): on a busy machine that start alone
    can take longer than the read, and a file must not count as damaged because the machine is busy. The start
    has its own, longer deadline (`start_timeout_s`)."""
    path = Path(path)
    check_eof(path)
    clear_stale_write_flags(path)  # a killed writer's file: plain HDF5 readers can open it from now on
    mode = "swmr" if open_for_writing(path) else "plain"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    child = subprocess.Popen([sys.executable, "-P", "-c", _PROBE_CODE, str(path), mode], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, env=env, stdin=subprocess.DEVNULL)
    try:
        said = _started(child, start_timeout_s)
        if said is None:
            raise StorageError(f"reading run file {path} did not start within {start_timeout_s:g} s",
                               expected="a machine less busy (the reading child process was not even running)")
        out, err = child.communicate(timeout=timeout_s)
        out = said + out
    except subprocess.TimeoutExpired:
        raise StorageError(f"reading run file {path} did not finish within {timeout_s:g} s",
                           expected="an undamaged run file (this one is truncated or corrupted, or the machine "
                                    "was too busy to read it in time)") from None
    finally:
        if child.poll() is None:
            child.kill()
            child.communicate()
    return _verdict(path, child.returncode, out.decode("utf-8", "replace"), err.decode("utf-8", "replace"))


def _started(child: subprocess.Popen, timeout_s: float) -> bytes | None:
    """What the child wrote once it said "ready" (or ended) within `timeout_s`; None if it did not."""
    assert child.stdout is not None
    fd = child.stdout.fileno()
    end = time.monotonic() + timeout_s
    seen = b""
    while b"\n" not in seen:
        left = end - time.monotonic()
        if left <= 0:
            return None
        ready, _, _ = select.select([fd], [], [], left)
        if ready:
            chunk = os.read(fd, 64)
            if not chunk:
                break  # it ended before a word: communicate() collects why from stderr
            seen += chunk
    return seen


def _verdict(path: Path, returncode: int, out: str, err: str) -> str:
    """The run id the child printed after "ready", else the StorageError its exit code and stderr mean."""
    if returncode != 0:
        lines = [ln for ln in err.strip().splitlines() if ln.strip()]
        last = lines[-1] if lines else f"exit code {returncode}"
        if returncode == _SAID:
            raise StorageError(last[:400])
        raise StorageError(f"cannot read run file {path}: {last[:300]}", expected="an undamaged run file")
    lines = out.strip().splitlines()
    return lines[-1] if len(lines) > 1 else ""


def _superblock(path: str | Path) -> bytes | None:
    """The file's first 48 bytes when they are a version 2 or 3 superblock at offset 0 (its byte 11: the
    "open for writing" flags), else None (another layout, or an unreadable file)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(48)
    except OSError:
        return None
    return head if head[:8] == _SIGNATURE and len(head) == 48 and head[8] in (2, 3) else None


def open_for_writing(path: str | Path) -> bool:
    """Whether the superblock says a writer has the file open (True also when it cannot tell)."""
    head = _superblock(path)
    return head is None or head[11] != 0


# --- a writer killed mid-run leaves HDF5's "open for writing" flags set ----------------------------------
def _rot(x: int, k: int) -> int:
    return ((x << k) | (x >> (32 - k))) & 0xFFFFFFFF


def _mix(a: int, b: int, c: int) -> tuple[int, int, int]:
    # lookup3's mix: six rounds, each on the next of (a, b, c) with its own rotation
    m, v = 0xFFFFFFFF, [a, b, c]
    for i, k in enumerate((4, 6, 8, 16, 19, 4)):
        t, s, o = i % 3, (i + 2) % 3, (i + 1) % 3
        v[t] = ((v[t] - v[s]) & m) ^ _rot(v[s], k)
        v[s] = (v[s] + v[o]) & m
    return v[0], v[1], v[2]


def _final(a: int, b: int, c: int) -> int:
    # lookup3's final: seven rounds on c, a, b, c, ... each with its own rotation
    m, v = 0xFFFFFFFF, [a, b, c]
    for i, k in enumerate((14, 11, 25, 16, 4, 14, 24)):
        t, s = (2 + i) % 3, (1 + i) % 3
        v[t] = ((v[t] ^ v[s]) - _rot(v[s], k)) & m
    return v[2]


def lookup3(data: bytes, initval: int = 0) -> int:
    """Bob Jenkins' lookup3 hashlittle, HDF5's metadata checksum."""
    n = len(data)
    a = b = c = (0xDEADBEEF + n + initval) & 0xFFFFFFFF
    i = 0
    while n - i > 12:
        x, y, z = struct.unpack_from("<3I", data, i)
        a, b, c = _mix((a + x) & 0xFFFFFFFF, (b + y) & 0xFFFFFFFF, (c + z) & 0xFFFFFFFF)
        i += 12
    if n - i == 0:
        return c
    tail = data[i:] + bytes(12 - (n - i))
    x, y, z = struct.unpack("<3I", tail)
    return _final((a + x) & 0xFFFFFFFF, (b + y) & 0xFFFFFFFF, (c + z) & 0xFFFFFFFF)


def clear_stale_write_flags(path: str | Path) -> bool:
    """If no coordinator holds the file (storage.runlock) but its superblock still says "open for
    writing" (a writer was killed), clear that, as `h5clear -s` does, so plain HDF5 readers open it too.
    True if the flags were cleared; a file in use, of another layout or not writable is left as it is."""
    from spinefarm.storage.runlock import RunLock

    path = Path(path)
    head = _superblock(path)
    if head is None or head[11] == 0:
        return False
    if struct.unpack_from("<I", head, 44)[0] != lookup3(head[:44]):
        return False  # not a superblock this code understands: leave it to HDF5
    try:
        lock = RunLock(path).acquire()
    except (StorageError, OSError):
        return False  # a live writer (or a directory we may not touch)
    try:
        fixed = head[:11] + b"\0" + head[12:44]
        fd = os.open(path, os.O_WRONLY)
        try:
            os.pwrite(fd, fixed + struct.pack("<I", lookup3(fixed)), 0)
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError:
        return False
    finally:
        lock.release()
    return True
