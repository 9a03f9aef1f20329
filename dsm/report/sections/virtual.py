"""A run with virtual shadow maps: virtual.md (per case: pages, physical texels, rays, receivers and
pages per level), its section of report.html and each case's level image."""
from __future__ import annotations

import numpy as np

from .. import io as report
from ..templates import Cell, Row, Table, render
from . import md
from ...truth import metrics

COLUMNS = (("case", "case"), ("scene", "scene"), ("cascade_layout", "layout"), ("scheme", "scheme"),
           ("params", "params"), ("filter", "filter"), ("n_receivers", "receivers"), ("error_rate", "error"),
           ("texels_per_pixel", "texels/pixel"), ("vsm_pages_tagged", "pages tagged"),
           ("vsm_pages_built", "pages built"), ("vsm_memory_texels", "physical texels"), ("vsm_rays", "rays"),
           ("vsm_level_histogram", "receivers per level"), ("vsm_level_pages", "pages per level"))
INTRO = ("Per case of a virtual shadow map (metrics.csv's vsm_* columns): the pages its receivers tagged and "
         "the pages built (every tagged page is ray-cast), the physical texels they hold (pages x page_size^2), "
         "the rays the build cast, and the receivers and pages per clipmap level (level:count). Undefined: -.")

# a level's colour in <case>_level.png: this palette at (level mod its length); black: not a receiver
LEVEL_COLORS = np.array([[228, 26, 28], [55, 126, 184], [77, 175, 74], [152, 78, 163], [255, 127, 0],
                         [255, 255, 51], [166, 86, 40], [247, 129, 191], [153, 153, 153], [102, 194, 165],
                         [141, 160, 203], [231, 138, 195]], np.uint8)


def virtual_rows(rows: list) -> list:
    """The rows of cases on a virtual shadow map."""
    given = lambda x: x not in (None, "") and not (isinstance(x, float) and not metrics.defined(x))
    return [r for r in rows if given(r.get("vsm_pages_tagged"))]     # other maps: empty in the file, NaN in memory


def write_table(path, rows: list) -> bool:
    """virtual.md from metrics.csv's rows; False (nothing written) without a virtual case."""
    rows = virtual_rows(rows)
    if not rows:
        return False
    md.write_table(path, "Virtual shadow maps", INTRO, COLUMNS, rows)
    return True


def html_table(rows: list) -> dict | None:
    """report.html's section on the run's virtual shadow maps: its words and table (None without one)."""
    rows = virtual_rows(rows)
    if not rows:
        return None
    body = [Row([Cell(md.cell(r.get(k, ""))) for k, _ in COLUMNS]) for r in rows]
    return {"intro": INTRO, "table": Table([(h, None) for _, h in COLUMNS], body, box="wide")}


def html_section(rows: list) -> str:
    """report.html's section on the run's virtual shadow maps, alone ("" without one)."""
    return render("virtual.html", virtual=html_table(rows))


def write_level_image(path, pixels: np.ndarray, levels: np.ndarray, width: int, height: int):
    """images/<scene>_<light>/<case>_level.png: each receiver coloured by its clipmap level
    (LEVEL_COLORS at level mod 12; black: not a receiver)."""
    from matplotlib.image import imsave
    img = np.zeros((width * height, 3), np.uint8)
    img[pixels] = LEVEL_COLORS[np.mod(np.asarray(levels, int), len(LEVEL_COLORS))]
    with report.atomic(path) as tmp:
        imsave(tmp, img.reshape(height, width, 3), format="png")
