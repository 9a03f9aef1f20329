"""One writer per results folder: an OS lock on ``<folder>/.dsm-lock``, holding the owner's pid.

The lock is ``fcntl.flock`` on an open file, not the file's existence: the kernel drops it when
the holder's last descriptor closes, so a run killed with SIGKILL leaves the folder free (the
file may stay behind; the next holder takes it over). Two ``dsm run`` into one ``--out`` would
otherwise write both runs' rows into one metrics.csv.
"""
from __future__ import annotations

import fcntl
import os
from pathlib import Path

LOCK_NAME = ".dsm-lock"


class Busy(RuntimeError):
    """The folder is held by another live process (``pid`` as it wrote it, or None)."""

    def __init__(self, folder: Path, pid):
        self.folder, self.pid = folder, pid
        who = f"process {pid}" if pid else "another process"
        super().__init__(f"{folder} is in use by another dsm command ({who}); wait for it to finish "
                         "or choose another --out")


class FolderLock:
    """The lock on one folder; a context manager that releases it on exit."""

    def __init__(self, folder: Path, fd: int):
        self.folder, self.fd = folder, fd

    def release(self):
        """Drop the lock and remove the lock file (while still holding it, so no one else has it)."""
        if self.fd is None:
            return
        try:
            (self.folder / LOCK_NAME).unlink(missing_ok=True)
        except OSError:
            pass                    # a read-only folder: the file stays, unlocked
        os.close(self.fd)           # closing releases the flock
        self.fd = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()


def acquire(folder) -> FolderLock:
    """Lock ``folder`` (created if missing) for this process; raises Busy, or OSError if it cannot be made."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / LOCK_NAME
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            pid = _read_pid(fd)
            os.close(fd)
            raise Busy(folder, pid) from None
        except BaseException:
            os.close(fd)
            raise
        # the holder before us may have removed the file after we opened it: then ours is a lock
        # on a deleted file that a third process would not see, so take the lock again on the new one
        if _same_file(fd, path):
            break
        os.close(fd)
    os.ftruncate(fd, 0)
    os.write(fd, f"{os.getpid()}\n".encode())
    return FolderLock(folder, fd)


def _read_pid(fd: int):
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _same_file(fd: int, path: Path) -> bool:
    try:
        a, b = os.fstat(fd), os.stat(path)
    except FileNotFoundError:
        return False
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)
