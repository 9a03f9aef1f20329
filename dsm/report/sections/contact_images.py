"""images/<scene>_<light>/<case>_contact.png: each receiver coloured by what the contact march did
(dsm.contact): right, recovered, false shadow, missed, or the map's own acne."""
from __future__ import annotations

import numpy as np

from .. import png

# the classes, in the order of their colours (index 0: a pixel that is not a receiver)
CONTACT_CLASSES = ("not a receiver", "lit, right", "shadowed, right", "recovered (peter-pan the march shadows)",
                   "false shadow (lit, the march shadows)", "missed (peter-pan left)", "acne (the map's)")
CONTACT_COLORS = np.array([[0, 0, 0], [205, 205, 205], [90, 90, 90], [40, 170, 60], [220, 40, 40],
                           [245, 150, 20], [150, 60, 200]], np.uint8)


def classes(v, v_star, occluded) -> np.ndarray:
    """Per receiver its index in CONTACT_CLASSES (1 to 6) after the march."""
    lit_map = np.asarray(v, float) >= 0.5
    gt, occ = np.asarray(v_star, bool), np.asarray(occluded, bool)
    out = np.where(gt, np.where(lit_map, 1, 6), np.where(lit_map, 5, 2)).astype(np.uint8)
    out[gt & lit_map & occ] = 4
    out[~gt & lit_map & occ] = 3
    return out


def write_image(path, pixels, cls, width: int, height: int):
    """The contact image of one case: each receiver's class colour (black: not a receiver)."""
    img = np.zeros(width * height, np.uint8)
    img[pixels] = cls
    png.write(path, CONTACT_COLORS[img.reshape(height, width)])
