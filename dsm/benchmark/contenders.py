"""A contender's page (``contenders/<name>.html`` beside leaderboard.html): every case it ran, its
class image and FLIP map side by side (dsm.benchmark.case_images) with its numbers, the worst first.

Written from results.json alone (the images are named from each record), static and from the file
system: no server, no network; images load as they scroll into view. The markup is the template
contender.html (dsm.report.templates), which the other pages share.
"""
from __future__ import annotations

import hashlib
import math
from pathlib import Path

from ..report.figures import slug
from ..report.io import write_text
from ..report.templates import render
from ..truth import metrics
from . import case_images, ranking

FOLDER = "contenders"
SLUG_MAX = 64               # characters of a contender's name kept in its page's file name
HASH_CHARS = 12             # hex digits of the name's SHA-256 that tell apart names of one slug
SHOWN_PX = 256              # an image's side on the page (the default size's 64 pixels at 4 CSS px each)
SCALE_TICKS = (0.0, 0.25, 0.5, 0.75, 1.0)


def page_path(contender: str) -> str:
    """A contender's page, relative to the benchmark's folder: its name where that is a short, safe file name,
    else its slug cut to SLUG_MAX with a hash of the name (two names never share a page; '~' is no slug's)."""
    name = slug(contender)
    if name != contender or not name or len(name) > SLUG_MAX or name.startswith("."):
        digest = hashlib.sha256(contender.encode("utf-8")).hexdigest()[:HASH_CHARS]
        name = f"{name.lstrip('.')[:SLUG_MAX]}~{digest}"      # no hidden file
    return f"{FOLDER}/{name}.html"


def case_anchor(index: int) -> str:
    """The id of a record's card on its contender's page (``index``: its place in results.json's cases)."""
    return f"c{index}"


def value_text(v, digits=4) -> str:
    """A number to ``digits`` significant digits; None or NaN (an empty denominator) as 'undefined'."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "undefined"
    return f"{v:.{digits}g}" if isinstance(v, float) else str(v)


def numbers_text(rec: dict) -> str:
    """A record's counts and rates in one line: error, acne over the truly lit, peter-panning over the truly
    shadowed, FLIP, leaks where measured."""
    shadowed = rec.get("n_gt_shadowed")
    lit = None if shadowed is None else rec["n_receivers"] - shadowed
    of = lambda n: "" if n is None else f" of {n}"
    parts = [f"error rate {value_text(rec['error_rate'])} ({rec['n_receivers']} receivers)",
             f"acne {rec['n_acne']}{of(lit)} lit: {value_text(rec['acne_rate'])}",
             f"peter-panning {rec['n_peterpan']}{of(shadowed)} shadowed: {value_text(rec['peterpan_rate'])}"]
    if "flip" in rec:
        parts.append(f"FLIP {value_text(rec['flip'])}")
    if "n_leak" in rec:
        parts.append(f"leaks {rec['n_leak']}{of(shadowed)} shadowed: {value_text(rec['leak_rate'])}")
    return "; ".join(parts)


def image(out: Path, sheet: str, place: int, alt: str, caption: str) -> dict:
    """One image of a card: the square at ``place`` of its case's ``sheet`` (from the benchmark's folder),
    shown SHOWN_PX wide (``kept`` False: the sheet was not kept)."""
    return {"kept": (Path(out) / sheet).is_file(), "src": f"../{sheet}", "alt": alt, "caption": caption,
            "shift": place * SHOWN_PX}


def card(out: Path, index: int, place: int, rec: dict, has_flip: bool) -> dict:
    """A record's card (``place``: its image's in its case's sheets): where it ran, its class image and FLIP
    map, its numbers, whether the leaderboard has its row."""
    where = f"{rec['scene']}, {rec['unit']}, offset {ranking.offset_of(rec)}, {rec['light']} light"
    class_sheet, flip_sheet = case_images.sheets(rec)
    images = []
    if (Path(out) / case_images.FOLDER).is_dir():       # none in a run from before they were kept: said once
        images.append(image(out, class_sheet, place, f"error classes of {where}", "error classes (colours above)"))
        if has_flip:
            images.append(image(out, flip_sheet, place, f"FLIP map of {where}", "FLIP error (scale above)"))
    key = lambda k: "" if rec.get(k) is None or (isinstance(rec[k], float) and math.isnan(rec[k])) else repr(rec[k])
    return {"id": case_anchor(index), "index": index, "error": key("error_rate"), "flip": key("flip"), "where": where,
            "images": images, "numbers": numbers_text(rec), "row": ranking.at_origin(rec)}


def flip_scale() -> dict:
    """The FLIP colour scale from 0 to 1 (a CSS gradient of the magma palette), its ticks, and how close a stored
    pixel is to FLIP's value."""
    pal = case_images.magma()
    stops = ",".join(f"rgb({','.join(str(int(c)) for c in pal[round(t * case_images.FLIP_LEVELS)])}) {t * 100:g}%"
                     for t in [i / 16 for i in range(17)])
    return {"stops": stops, "ticks": [f"{t:g}" for t in SCALE_TICKS], "bound": f"{case_images.FLIP_BOUND:.5f}"}


def contender_page(doc: dict, out: Path, contender: str) -> str:
    """The HTML of one contender's page."""
    place = case_images.places(doc["cases"])
    recs = [(i, r) for i, r in enumerate(doc["cases"]) if r["contender"] == contender]
    has_flip = any("flip" in r for _, r in recs)
    worst = sorted(recs, key=lambda ir: (not metrics.defined(ir[1]["error_rate"]),
                                         -ir[1]["error_rate"] if metrics.defined(ir[1]["error_rate"]) else 0, ir[0]))
    buttons = [("error", "worst error rate first")] + ([("flip", "worst FLIP first")] if has_flip else []) + [
        ("suite", "the suite's order (scene, unit, offset, light)")]
    return render("contender.html", title=f"{contender}: {doc['suite']}", contender=contender, suite=doc["suite"],
                  size=doc["size"], count=len(recs), flip=flip_scale() if has_flip else None,
                  kept=(Path(out) / case_images.FOLDER).is_dir(), folder=case_images.FOLDER, buttons=buttons,
                  cards=[card(out, i, place[i], r, has_flip) for i, r in worst], shown_px=SHOWN_PX)


def write_pages(doc: dict, out: Path) -> list:
    """Write a page per contender (the oracle has none) under ``out/contenders/``, removing any other page
    there (an earlier run's, or an earlier naming's); returns their paths."""
    names = sorted({r["contender"] for r in doc["cases"] if r["contender"] != "oracle"})
    (Path(out) / FOLDER).mkdir(parents=True, exist_ok=True)
    written = []
    for name in names:
        path = Path(out) / page_path(name)
        write_text(path, contender_page(doc, out, name))
        written.append(path)
    for stale in set((Path(out) / FOLDER).glob("*.html")) - set(written):     # a page of a name no longer run
        stale.unlink()
    return written
