"""The report's drawing jobs, shared between this process and one more per further core.

A job is ``(function, arguments)``: a figure or a batch of images written to files. With at
least ``pool_min`` jobs and two or more cores they are dealt out interleaved (every process gets
a share of the costly figures) and drawn at once.

**Forked, not started.** On Linux the other processes are forks of this one, made after its
first figure: a fork costs no interpreter start and no import of matplotlib (about 0.7 CPU
seconds a worker, a tenth of the default experiment's report), and it inherits the drawn
layouts' Figures and the cached text bitmaps (dsm/report/canvas.py). Forking a process whose
other threads (Dr.Jit's workers, idle once every measurement is done) are left behind is safe
for a child that touches none of their state: it only draws with numpy and matplotlib and
leaves with ``os._exit``, so no exit handler of the parent (Dr.Jit's would join threads the
child does not have) runs in it, and the kernel stops it if this process dies (a kill -9). A child
that fails, or has not finished ``HANG_S`` seconds after this process finished its own share, is
stopped and its share drawn here, saying so.
Elsewhere (no ``fork``), each worker is a fresh ``python -c`` given its jobs in a pickle file:
a multiprocessing pool would re-import the caller's main script, which re-runs a script that
calls dsm.run without an ``if __name__ == "__main__"`` guard.
"""
from __future__ import annotations

import gc
import os
import pickle
import signal
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

from . import canvas

HANG_S = 120.0          # how long a forked share may run past this process's own (a stuck child, not a slow one)
POLL_S = 0.01
STOP_GRACE_S = 1.0      # a stopped child's time to remove its half-written file before SIGKILL
PR_SET_PDEATHSIG = 1    # linux/prctl.h


def workers() -> int:
    """The CPUs this process may run on (at least 1)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:
        return max(1, os.cpu_count() or 1)


def run_jobs(jobs: list, pool_min: int = 12, fork: bool | None = None) -> int:
    """Run (function, arguments) jobs: when there are at least ``pool_min`` of them, shared
    between this process and one process per further core, else all here. ``fork``: None
    forks where the platform can (Linux), False starts fresh interpreters. Returns the number
    of processes that drew (0: no pool). A worker that fails has its share drawn here, saying so."""
    n = min(workers(), len(jobs))
    if n < 2 or len(jobs) < pool_min:
        _draw(jobs)
        return 0
    fork = hasattr(os, "fork") and sys.platform.startswith("linux") if fork is None else fork
    shares = [jobs[i::n] for i in range(n)]
    failed = _forked(shares) if fork else _started(shares)
    for part, why in failed:
        print(f"dsm: a drawing worker failed ({why}); drawing its {len(part)} figures here", file=sys.stderr)
        _draw(part)
    return n


def _draw(jobs):
    with canvas.reusing():
        for fn, args in jobs:
            fn(*args)


def _forked(shares: list) -> list:
    """Draw shares[0] here and every other share in a fork of this process; [(share, why)] of
    those that failed (a fork the system refused included)."""
    mine = shares[0]
    children, failed = [], []
    with canvas.reusing():
        mine[0][0](*mine[0][1])           # first, so the forks inherit its Figure and text bitmaps
        try:
            for part in shares[1:]:
                try:
                    children.append((part, *_fork(part)))
                except OSError as e:      # no memory or process left for a fork: drawn here
                    failed.append((part, f"fork refused: {e}"))
            for fn, args in mine[1:]:
                fn(*args)
            deadline = time.monotonic() + HANG_S
            failed += [(part, why) for part, pid, pipe in children if (why := _wait(pid, pipe, deadline))]
            return failed
        finally:
            for _, pid, pipe in children:      # interrupted: no child outlives this call
                _stop(pid)
                os.close(pipe)


def _fork(part) -> tuple:
    """(pid, read end of its message pipe) of a fork drawing ``part``."""
    sys.stdout.flush()
    sys.stderr.flush()
    r, w = os.pipe()
    parent = os.getpid()
    held = {signal.SIGINT, signal.SIGTERM}
    try:
        # signals held over the fork: one arriving in the child before its try would raise in
        # its parent's code; uncollected garbage frozen, so the child never finalizes the parent's
        # objects (Dr.Jit arrays among them, whose threads the child does not have)
        old = signal.pthread_sigmask(signal.SIG_BLOCK, held)
        gc.freeze()
        try:
            with warnings.catch_warnings():   # Python 3.12 warns on any fork of a threaded process (see above)
                warnings.simplefilter("ignore", DeprecationWarning)
                pid = os.fork()
        finally:
            if os.getpid() == parent:
                gc.unfreeze()
                signal.pthread_sigmask(signal.SIG_SETMASK, old)
    except BaseException:
        os.close(r)
        os.close(w)
        raise
    if pid == 0:
        _child(part, parent, r, w, old)
    os.close(w)
    return pid, r


def _child(part, parent: int, r: int, w: int, mask):
    """A fork's life: draw ``part``, write why not to ``w`` if it fails, and leave."""
    code = 1
    try:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        _die_with(parent)
        os.close(r)
        for fn, args in part:
            fn(*args)
        code = 0
    except BaseException as e:        # Ctrl-C too: the child never returns into its parent's code
        try:
            os.write(w, f"{type(e).__name__}: {e}".encode(errors="replace")[:2000])
        except BaseException:
            pass
    finally:
        os._exit(code)


def _die_with(parent: int):
    """Have the kernel stop this child when its parent dies (a kill -9 of the run: the child holds
    the run folder's lock, inherited, and would keep drawing into it)."""
    import ctypes
    try:
        ctypes.CDLL(None).prctl(ctypes.c_int(PR_SET_PDEATHSIG), ctypes.c_ulong(signal.SIGKILL),
                                ctypes.c_ulong(0), ctypes.c_ulong(0), ctypes.c_ulong(0))
    except (OSError, AttributeError):     # no prctl: the child finishes its share, then leaves
        pass
    if os.getppid() != parent:            # the parent died before prctl took effect
        os._exit(1)


def _wait(pid: int, pipe: int, deadline: float) -> str | None:
    """None once child ``pid`` has drawn its share; else why not (its error, or stuck past ``deadline``)."""
    while True:
        got, status = os.waitpid(pid, os.WNOHANG)
        if got:
            break
        if time.monotonic() > deadline:
            _stop(pid)
            return f"no answer {HANG_S:g} s after this process's share"
        time.sleep(POLL_S)
    if os.waitstatus_to_exitcode(status) == 0:
        return None
    msg = os.read(pipe, 4096).decode(errors="replace").strip()
    return msg or f"exit status {os.waitstatus_to_exitcode(status)}"


def _stop(pid: int):
    """Stop child ``pid`` if it still runs (SIGTERM, so it removes its half-written file; SIGKILL
    after ``STOP_GRACE_S``) and reap it. Only a child not yet reaped is signalled: once reaped its
    number may belong to another process, and waitpid then says it is no child of ours."""
    try:
        if os.waitpid(pid, os.WNOHANG)[0]:
            return
        os.kill(pid, signal.SIGTERM)
        end = time.monotonic() + STOP_GRACE_S
        while time.monotonic() < end:
            if os.waitpid(pid, os.WNOHANG)[0]:
                return
            time.sleep(POLL_S)
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    except ChildProcessError:             # reaped already (a wait interrupted before it could say so)
        pass


# a started worker: a fresh interpreter running its share of the jobs, pickled into a file
WORKER = ("import pickle, sys\nfrom dsm.report import canvas\nwith canvas.reusing():\n"
          "    for fn, args in pickle.loads(open(sys.argv[1], 'rb').read()):\n        fn(*args)\n")


def _started(shares: list) -> list:
    """Draw shares[0] here and every other share in a fresh interpreter; [(share, why)] of those that failed."""
    env = dict(os.environ, MPLBACKEND="Agg",
               PYTHONPATH=os.pathsep.join([p for p in sys.path if p] + [os.environ.get("PYTHONPATH", "")]))
    failed, procs = [], []
    with tempfile.TemporaryDirectory(prefix="dsm-draw-") as tmp:
        try:
            for i, part in enumerate(shares[1:], 1):
                f = Path(tmp) / f"jobs{i}.pickle"
                f.write_bytes(pickle.dumps(part, protocol=pickle.HIGHEST_PROTOCOL))
                procs.append((part, subprocess.Popen([sys.executable, "-c", WORKER, str(f)], env=env,
                                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)))
            _draw(shares[0])                # this process's share, while the workers draw theirs
            for part, p in procs:
                _, err = p.communicate()
                if p.returncode:
                    failed.append((part, (err.decode(errors="replace").strip().splitlines()[-1:] or ["no message"])[0]))
        finally:
            for _, p in procs:              # interrupted: no worker outlives this call
                if p.poll() is None:
                    p.kill()
                    p.wait()
    return failed
