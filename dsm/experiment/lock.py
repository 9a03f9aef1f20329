"""One writer per results folder: an OS lock on ``<folder>/.dsm-lock``, holding the owner's pid.

The lock is ``fcntl.flock`` on an open file, not the file's existence: the kernel drops it when
the holder's last descriptor closes, so a run killed with SIGKILL leaves the folder free (the
file may stay behind; the next holder takes it over). Two ``dsm run`` into one ``--out`` would
otherwise write both runs' rows into one metrics.csv.

Beside the lock, what any results folder must be to take one (``claim``: a name the file system
can make, a folder and not a file; ``unwritable``; ``entries``), for the command line and the
Python API (``dsm.run``, ``dsm.tune.tuner.tune``) alike, and the API's wording of a problem.
"""
from __future__ import annotations

import fcntl
import os
import tempfile
from pathlib import Path

LOCK_NAME = ".dsm-lock"
NAME_MAX = 255       # bytes in one file name on Linux's file systems (ext4, xfs, btrfs, tmpfs)


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


# ---------------------------------------------------------------- what a results folder can take

def name_problem(path: Path, flag: str = "--out") -> str | None:
    """Why ``path`` cannot be made (None if it can): a component longer than NAME_MAX bytes."""
    for part in Path(path).parts:
        n = len(os.fsencode(part))
        if n > NAME_MAX:
            return (f"{flag} {str(path)[:60]}...: the name {part[:24]!r}... is {n} bytes long; a file "
                    f"name takes at most {NAME_MAX} bytes: choose a shorter one")
    return None


def claim(out: Path, flag: str = "--out"):
    """(the lock on ``out``, None), or (None, why it cannot be had): one writer per folder (dsm.experiment.lock)."""
    problem = name_problem(out, flag)
    if problem is None and out.is_symlink() and not out.is_dir():
        problem = f"{flag} {out}: a broken symbolic link"
    elif problem is None and out.exists() and not out.is_dir():
        problem = f"{flag} {out}: is a file, not a folder; choose another {flag}"
    if problem:
        return None, problem
    try:
        return acquire(out), None
    except Busy as e:
        return None, f"{flag} {e}"
    except OSError as e:
        return None, f"{flag} {out}: cannot write there: {e.strerror or e}"


def entries(out: Path) -> list:
    """What ``out`` holds, the lock file aside (None if it is no folder)."""
    if not out.is_dir():
        return None
    return [p for p in out.iterdir() if p.name != LOCK_NAME]


def unwritable(out: Path) -> str | None:
    """Why files cannot be written into ``out`` (None if they can), made if missing."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as e:
        return f"--out {out}: cannot write there: {e.strerror or e}"
    return None


def api_words(problem: str) -> str:
    """A folder problem in the command line's words (--out, --force, --resume) in the Python
    API's (out, force=True, resume=True): dsm.run and dsm.tune.tuner.tune raise it so."""
    for flag, arg in (("--out", "out"), ("--force", "force=True"), ("--resume", "resume=True")):
        problem = problem.replace(flag, arg)
    return problem
