"""A benchmark case's images, kept for the leaderboard's contender pages (dsm.benchmark.contenders).

Per record (scene, unit, offset, light, contender) two indexed PNGs under ``<out>/case_images/``,
named from the record alone (:func:`paths`), so that a page needs nothing but results.json to link
them: the class image (the index of a pixel is its class, :data:`dsm.truth.metrics.CLASS_COLORS`
its palette, report.html's error.png colours) and the FLIP error map (the index is round(255 FLIP),
a magma palette: a pixel's value is within :data:`FLIP_BOUND` of FLIP's, and so is the map's mean).
Each file is written atomically before the case's entry in ``cases/`` (dsm.benchmark.caselog), so a
case that is kept has its images, and a case run again on ``--resume`` writes the same bytes.
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from ..report import png
from ..report.figures import slug
from ..truth import metrics

FOLDER = "case_images"
FLIP_LEVELS = 255                       # FLIP in [0, 1] stored as round(255 FLIP), an 8-bit index
FLIP_BOUND = 0.5 / FLIP_LEVELS          # the most a stored pixel (and so the map's mean) is off FLIP's


@lru_cache(maxsize=1)
def magma() -> np.ndarray:
    """The (256, 3) uint8 palette of the FLIP maps: matplotlib's magma, index i for FLIP i / 255."""
    from matplotlib import colormaps
    return np.round(colormaps["magma"](np.linspace(0.0, 1.0, FLIP_LEVELS + 1))[:, :3] * 255).astype(np.uint8)


def case_folder(rec: dict) -> str:
    """The folder of a record's case (scene, unit, offset), relative to the benchmark's folder."""
    return f"{FOLDER}/{slug(rec['scene'])}_{slug(rec['unit'])}_{slug(rec.get('offset', '0'))}"


def paths(rec: dict) -> tuple:
    """(class image, FLIP map) of a record, relative to the benchmark's folder."""
    stem = f"{case_folder(rec)}/{slug(rec['light'])}_{slug(rec['contender'])}"
    return stem + "_classes.png", stem + "_flip.png"


def flip_indices(error: np.ndarray) -> np.ndarray:
    """A FLIP map (H, W) in [0, 1] as its palette indices, round(255 FLIP)."""
    return np.round(np.clip(np.asarray(error, np.float64), 0.0, 1.0) * FLIP_LEVELS).astype(np.uint8)


def keep(out: Path, records: list, rows: list, classes: dict, flips: dict | None):
    """Write each record's class image and FLIP map (``flips``: case id -> map, None without FLIP) under
    ``out``; ``records`` pair with ``rows`` (the metrics rows they were made from) in order."""
    written = set()
    for rec, row in zip(records, rows):
        class_path, flip_path = paths(rec)
        if class_path in written:       # two records of one case named alike: their images would overwrite
            raise RuntimeError(f"dsm benchmark: {class_path} names two records of one case")
        written.add(class_path)
        items = [(class_path, png.encode_indexed(np.asarray(classes[row["case"]], np.uint8), metrics.CLASS_COLORS))]
        if flips is not None:
            items.append((flip_path, png.encode_indexed(flip_indices(flips[row["case"]]), magma())))
        for rel, data in items:
            path = Path(out) / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            png.write_bytes(path, data)


def read_indices(path: Path) -> np.ndarray:
    """The palette indices (H, W) uint8 of an indexed PNG written by :func:`keep`."""
    from PIL import Image
    with Image.open(path) as im:
        if im.mode != "P":
            raise ValueError(f"{path}: not an indexed PNG (mode {im.mode})")
        return np.asarray(im)


def read_flip(path: Path) -> np.ndarray:
    """A stored FLIP map as float64 values (each within FLIP_BOUND of FLIP's)."""
    return read_indices(path) / FLIP_LEVELS
