"""A test helper, run as a script by tests/test_benchmark.py and tests/test_install.py: ``dsm ARGS``
(a dsm benchmark) in a process of its own on some of the suite's cases, optionally sending itself
a signal at a known point.

    python tests/helpers_benchmark_cases.py AFTER SIGNAL CASES ARGS...

CASES: a JSON list of [scene, unit, offset], the cases kept of the suite (dsm.benchmark.suite.cases)
in its order; AFTER, SIGNAL: once the AFTER-th case is kept (its file written, the next not begun),
the process sends itself SIGNAL (a name of the signal module: SIGINT, SIGKILL); AFTER 0 sends none."""
import json
import os
import signal
import sys

from dsm import cli
from dsm.benchmark import caselog, results, suite


def only_cases(keys):
    """A stand-in for dsm.benchmark.suite.cases that keeps the cases named by ``keys`` ((scene, unit,
    offset), in the suite's order): a test that proves a property of every case on a few of them."""
    keys, every = {tuple(k) for k in keys}, suite.cases

    def chosen(s, size):
        picked = [c for c in every(s, size) if (c.scene, c.unit, c.offset) in keys]
        assert len(picked) == len(keys), (keys, picked)
        return picked
    return chosen


def signal_after(n: int, sig):
    """Make the n-th kept case send this process ``sig`` once its file is written."""
    keep, kept = caselog.CaseLog.keep, []

    def keep_then_signal(self, *args):
        keep(self, *args)
        kept.append(args[0])
        if len(kept) == n:
            os.kill(os.getpid(), sig)
    caselog.CaseLog.keep = keep_then_signal


def main(argv) -> int:
    """Run ``dsm argv[3:]`` on the cases argv[2], with the signal argv[1] after argv[0] kept cases."""
    after, sig, keys = int(argv[0]), getattr(signal, argv[1], None), json.loads(argv[2])
    results.cases = only_cases(keys)
    # as a terminal's Ctrl-C finds it: a test suite started in the background (a shell's `&`) passes
    # SIGINT on ignored, and Python then installs no KeyboardInterrupt for it
    signal.signal(signal.SIGINT, signal.default_int_handler)
    if after:
        signal_after(after, sig)
    sys.argv = ["dsm", *argv[3:]]
    return cli.main()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
