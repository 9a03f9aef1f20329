"""A benchmark case's images, kept for the leaderboard's contender pages (dsm.benchmark.contenders).

Per suite case (scene, unit, offset) two indexed PNGs under ``<out>/case_images/``: its records'
class images stacked top to bottom in the order of results.json (the oracles' left out), and their
FLIP maps alike. A class image's palette index is its class (:data:`dsm.truth.metrics.CLASS_COLORS`,
report.html's error.png colours); a FLIP map's is round(255 FLIP) in a magma palette, so a pixel's
value, and a map's mean, is within :data:`FLIP_BOUND` of FLIP's. A record's sheet and place in it
follow from results.json alone (:func:`places`), so a page needs nothing else to show it. One
sheet per case, not a file per record: the default size's 3,850 records would be 7,700 files of
under a disk block each (33 MB of blocks for 8 MB of bytes). Both sheets are written atomically
when the case finishes, before its entry in ``cases/`` (dsm.benchmark.caselog): a kept case has its
images, and a case run again on ``--resume`` writes the same bytes.
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
FLIP_BOUND = 0.5 / FLIP_LEVELS          # the most a stored pixel (and so a map's mean) is off FLIP's


@lru_cache(maxsize=1)
def magma() -> np.ndarray:
    """The (256, 3) uint8 palette of the FLIP maps: matplotlib's magma, index i for FLIP i / 255."""
    from matplotlib import colormaps
    return np.round(colormaps["magma"](np.linspace(0.0, 1.0, FLIP_LEVELS + 1))[:, :3] * 255).astype(np.uint8)


def sheets(rec: dict) -> tuple:
    """(class sheet, FLIP sheet) of a record's case, relative to the benchmark's folder."""
    stem = f"{FOLDER}/{slug(rec['scene'])}_{slug(rec['unit'])}_{slug(rec.get('offset', '0'))}"
    return stem + "_classes.png", stem + "_flip.png"


def places(records: list) -> list:
    """Per record of results.json's ``cases``: its place in its case's sheets (0 the top image), None
    for an oracle's (which has no image). A case's records are consecutive there, in the order kept."""
    out, count = [], {}
    for r in records:
        if r["contender"] == "oracle":
            out.append(None)
            continue
        key = sheets(r)[0]
        out.append(count.get(key, 0))
        count[key] = out[-1] + 1
    return out


def flip_indices(error: np.ndarray) -> np.ndarray:
    """A FLIP map (H, W) in [0, 1] as its palette indices, round(255 FLIP)."""
    return np.round(np.clip(np.asarray(error, np.float64), 0.0, 1.0) * FLIP_LEVELS).astype(np.uint8)


def keep(out: Path, records: list, images: list):
    """Write a case's sheets under ``out``: ``records`` its records but the oracles', in results.json's
    order; ``images`` per record (class image (H, W), FLIP map (H, W) or None where the suite has no FLIP)."""
    if not records:
        return
    class_path, flip_path = sheets(records[0])
    classes = np.concatenate([np.asarray(c, np.uint8) for c, _ in images])
    items = [(class_path, png.encode_indexed(classes, metrics.CLASS_COLORS))]
    if all(f is not None for _, f in images):
        items.append((flip_path, png.encode_indexed(np.concatenate([flip_indices(f) for _, f in images]), magma())))
    for rel, data in items:
        path = Path(out) / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        png.write_bytes(path, data)


def read_indices(path: Path) -> np.ndarray:
    """The palette indices (rows, W) uint8 of an indexed PNG written by :func:`keep`."""
    from PIL import Image
    with Image.open(path) as im:
        if im.mode != "P":
            raise ValueError(f"{path}: not an indexed PNG (mode {im.mode})")
        return np.asarray(im)


def image_at(sheet: np.ndarray, place: int) -> np.ndarray:
    """The square image at ``place`` of a sheet (its images are as tall as wide: the suite's camera)."""
    side = sheet.shape[1]
    return sheet[place * side:(place + 1) * side]


def read_class(out: Path, records: list, index: int) -> np.ndarray:
    """The class image (H, W) of results.json's ``cases[index]``, from the benchmark's folder ``out``."""
    return image_at(read_indices(Path(out) / sheets(records[index])[0]), places(records)[index])

