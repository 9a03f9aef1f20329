"""A virtual shadow map's columns per case: its pages, memory and rays, and the receivers per level."""
from __future__ import annotations

import numpy as np


def histogram_text(counts: dict) -> str:
    """``{level: count}`` as ``"level:count"`` words in level order (the exact integers)."""
    return " ".join(f"{k}:{counts[k]}" for k in sorted(counts))


def level_histogram(view, faces: np.ndarray) -> dict:
    """{absolute level: receivers} of the receivers' faces (levels without receivers left out)."""
    lv, n = np.unique(view.level_of_face(faces), return_counts=True)
    return {int(a): int(b) for a, b in zip(lv, n)}


def case_metrics(view, smap, faces: np.ndarray) -> dict:
    """metrics.csv's virtual columns: pages tagged and built (every tagged page is built), the physical
    texels they hold, the rays the build cast, and the receivers and pages per level."""
    return {"vsm_pages_tagged": view.n_pages, "vsm_pages_built": view.n_pages, "vsm_memory_texels": view.n_texels,
            "vsm_rays": int(sum(smap.rays.values())) if smap is not None else 0,
            "vsm_level_histogram": histogram_text(level_histogram(view, faces)),
            "vsm_level_pages": histogram_text(view.level_pages())}
