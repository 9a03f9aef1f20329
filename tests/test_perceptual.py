"""FLIP in the benchmark: one OpenMP thread, the same values as the runtime's default threads."""
import json
import subprocess
import sys

import numpy as np


def _renders(seed: int):
    """A grey render and a copy with a few pixels darkened (a shadow-map error's pattern)."""
    rng = np.random.default_rng(seed)
    exact = rng.random((64, 64))
    shadowed = exact.copy()
    shadowed[rng.random((64, 64)) < 0.05] *= 0.25
    return exact, shadowed


def test_flip_on_one_thread_is_the_same_bits_as_on_the_default_threads():
    """mean_flip sets FLIP's OpenMP runtime to one thread (one_thread: the runtime reports 1 after);
    each value equals, bit for bit, flip-evaluator's own call in a fresh process on its default
    threads (as many as the machine's cores)."""
    import ctypes
    from dsm.benchmark import perceptual
    got = [perceptual.mean_flip(*_renders(s), 67.0) for s in range(6)]
    assert perceptual.one_thread() >= 1
    with open("/proc/self/maps") as fh:
        lib = next(line.split()[-1] for line in fh if "libgomp" in line)
    assert ctypes.CDLL(lib).omp_get_max_threads() == 1
    code = ("import json, sys, numpy as np, flip_evaluator\n"
            "sys.path.insert(0, %r)\n"
            "from test_perceptual import _renders\n"
            "from dsm.benchmark.perceptual import as_rgb\n"
            "out = [float(flip_evaluator.evaluate(as_rgb(e), as_rgb(s), 'LDR', inputsRGB=True, applyMagma=False,"
            " computeMeanError=True, parameters={'ppd': 67.0})[1]) for e, s in (_renders(k) for k in range(6))]\n"
            "print(json.dumps(out))" % str(__import__("pathlib").Path(__file__).parent))
    ref = json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout)
    assert [float(x) for x in got] == ref
