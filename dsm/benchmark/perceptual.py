"""FLIP (NVIDIA's perceptual image error, the flip-evaluator package) of a shadowed render against the exact one."""
from __future__ import annotations

import numpy as np


def as_rgb(grey: np.ndarray) -> np.ndarray:
    """A grey render (H, W) in [0, 1] as the (H, W, 3) float32 sRGB image FLIP's LDR mode reads."""
    g = np.clip(np.asarray(grey, np.float32), 0.0, 1.0)
    # a copy in C order: flip_evaluator reads the buffer as HxWxC, so a strided view would be misread
    return np.ascontiguousarray(np.repeat(g[..., None], 3, axis=2))


def mean_flip(reference: np.ndarray, test: np.ndarray, ppd: float) -> float:
    """The mean LDR FLIP error of ``test`` against ``reference`` (grey renders) at ``ppd`` pixels per degree."""
    import flip_evaluator
    _, mean, _ = flip_evaluator.evaluate(as_rgb(reference), as_rgb(test), "LDR", inputsRGB=True, applyMagma=False,
                                         computeMeanError=True, parameters={"ppd": float(ppd)})
    return float(mean)
