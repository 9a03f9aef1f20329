"""FLIP (NVIDIA's perceptual image error, the flip-evaluator package) of a shadowed render against the exact one."""
from __future__ import annotations

from functools import lru_cache

import numpy as np


def as_rgb(grey: np.ndarray) -> np.ndarray:
    """A grey render (H, W) in [0, 1] as the (H, W, 3) float32 sRGB image FLIP's LDR mode reads."""
    g = np.clip(np.asarray(grey, np.float32), 0.0, 1.0)
    # a copy in C order: flip_evaluator reads the buffer as HxWxC, so a strided view would be misread
    return np.ascontiguousarray(np.repeat(g[..., None], 3, axis=2))


@lru_cache(maxsize=1)
def one_thread() -> int:
    """Set the OpenMP runtimes this process has loaded (flip-evaluator's wheel brings its own libgomp)
    to one thread; returns how many were set. A benchmark render is 64 x 64 pixels: two threads cost
    1.7 times one's CPU on a quiet machine and 5 times on a loaded one (their barriers spin while the
    other waits for a core), for the same value (FLIP's mean is the same bits at 1, 2 and 4 threads)."""
    import ctypes
    import flip_evaluator  # noqa: F401  (loads its OpenMP runtime)
    try:
        with open("/proc/self/maps") as fh:
            libs = {line.split()[-1] for line in fh if "libgomp" in line or "libomp" in line or "libiomp" in line}
    except OSError:                         # not Linux: FLIP keeps its runtime's default
        return 0
    n = 0
    for path in sorted(libs):
        try:
            ctypes.CDLL(path).omp_set_num_threads(1)
            n += 1
        except (OSError, AttributeError):
            continue
    return n


def flip(reference: np.ndarray, test: np.ndarray, ppd: float) -> tuple:
    """(per-pixel LDR FLIP error (H, W) float32 in [0, 1], its mean as FLIP reports it) of ``test`` against
    ``reference`` (grey renders) at ``ppd`` pixels per degree."""
    import flip_evaluator
    one_thread()
    error, mean, _ = flip_evaluator.evaluate(as_rgb(reference), as_rgb(test), "LDR", inputsRGB=True,
                                             applyMagma=False, computeMeanError=True, parameters={"ppd": float(ppd)})
    return np.asarray(error, np.float32).reshape(np.shape(reference)), float(mean)


def mean_flip(reference: np.ndarray, test: np.ndarray, ppd: float) -> float:
    """The mean LDR FLIP error of ``test`` against ``reference`` (grey renders) at ``ppd`` pixels per degree."""
    return flip(reference, test, ppd)[1]
