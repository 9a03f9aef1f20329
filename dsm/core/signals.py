"""Writes that must land together: Ctrl-C and SIGTERM held until they have.

A run's case is a metrics.csv row, the record's row and its status; an interrupt between them
left run.json's ``n_cases_ok`` disagreeing with metrics.csv (issue 76). The signal is not lost:
it is raised again, to its own handler, as soon as the writes are done.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

HELD = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def deferred():
    """Hold SIGINT and SIGTERM over the block; deliver any that came after it."""
    if threading.current_thread() is not threading.main_thread():
        yield                   # only the main thread takes Python's signal handlers, and so the interrupt
        return
    caught = []
    old = {s: signal.getsignal(s) for s in HELD}
    for s in HELD:
        signal.signal(s, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
        for signum in dict.fromkeys(caught):
            signal.raise_signal(signum)     # its own handler now: Ctrl-C's KeyboardInterrupt, the cli's SIGTERM
