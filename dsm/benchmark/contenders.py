"""A contender's page (``contenders/<name>.html`` beside leaderboard.html): every case it ran, its
class image and FLIP map side by side (dsm.benchmark.case_images) with its numbers, the worst first.

Written from results.json alone (the images are named from each record), static and from the file
system: no server, no network; images load as they scroll into view.
"""
from __future__ import annotations

import hashlib
import html
import math
from pathlib import Path

from ..report.figures import slug
from ..report.html import CSS
from ..report.io import write_text
from ..truth import metrics
from . import case_images, ranking

FOLDER = "contenders"
SLUG_MAX = 64               # characters of a contender's name kept in its page's file name
HASH_CHARS = 12             # hex digits of the name's SHA-256 that tell apart names of one slug
SHOWN_PX = 256              # an image's side on the page (the default size's 64 pixels at 4 CSS px each)
SCALE_TICKS = (0.0, 0.25, 0.5, 0.75, 1.0)
PAGE_CSS = f"""
.order button{{margin-right:.4em}} .order button[aria-pressed=true]{{font-weight:600;background:#dde8ff}} #cards{{display:flex;flex-wrap:wrap;gap:14px;margin-top:.6em}}
figure.case{{margin:0;border:1px solid #ccc;padding:6px;width:{SHOWN_PX * 2 + 30}px;max-width:100%;
box-sizing:border-box}}
figure.case:target{{outline:3px solid #36c}} .pair{{display:flex;flex-wrap:wrap;gap:6px}}
.pair figure{{margin:0}} .crop{{width:{SHOWN_PX}px;height:{SHOWN_PX}px;overflow:hidden;border:1px solid #999}}
.crop img{{width:{SHOWN_PX}px;image-rendering:pixelated;display:block}}
.pair figcaption,.nums{{font-size:12px;color:#333;margin:2px 0}}
.bar{{height:14px;width:{SHOWN_PX * 2}px;max-width:100%;border:1px solid #888}}
.ticks{{display:flex;justify-content:space-between;width:{SHOWN_PX * 2}px;max-width:100%;font-size:12px;
margin-bottom:.6em}}
"""
# the cards' order: by a data attribute, undefined values last, ties in the suite's order
ORDER_SCRIPT = r"""
function orderBy(key) {
  const box = document.getElementById('cards');
  const cards = Array.from(box.children);
  const v = c => c.dataset[key] === '' ? NaN : parseFloat(c.dataset[key]);
  cards.sort((a, b) => {
    const x = v(a), y = v(b);
    if (isNaN(x) !== isNaN(y)) return isNaN(x) ? 1 : -1;
    const d = key === 'suite' ? x - y : y - x;
    return (isNaN(d) || d === 0) ? a.dataset.suite - b.dataset.suite : d;
  });
  cards.forEach(c => box.appendChild(c));
  document.querySelectorAll('.order button').forEach(b => b.setAttribute('aria-pressed', b.dataset.key === key));
}
document.querySelectorAll('.order button').forEach(b => b.addEventListener('click', () => orderBy(b.dataset.key)));
"""


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


def numbers_html(rec: dict) -> str:
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
    return "<p class=nums>" + html.escape("; ".join(parts)) + "</p>"


def image_html(out: Path, sheet: str, place: int, alt: str, caption: str) -> str:
    """One image of a card: the square at ``place`` of its case's ``sheet`` (from the benchmark's
    folder), shown SHOWN_PX wide; or a note where the sheet was not kept."""
    if not (Path(out) / sheet).is_file():
        return f"<figure><p class=note>{html.escape(alt)}: not kept in {html.escape(case_images.FOLDER)}/</p></figure>"
    return (f"<figure><div class=crop><img loading=lazy src=\"../{html.escape(sheet, quote=True)}\" "
            f"alt=\"{html.escape(alt, quote=True)}\" style=\"margin-top:-{place * SHOWN_PX}px\"></div>"
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def card_html(out: Path, index: int, place: int, rec: dict, has_flip: bool) -> str:
    """A record's card (``place``: its image's in its case's sheets): where it ran, its class image and FLIP
    map, its numbers, its links."""
    where = f"{rec['scene']}, {rec['unit']}, offset {ranking.offset_of(rec)}, {rec['light']} light"
    class_sheet, flip_sheet = case_images.sheets(rec)
    kept = (Path(out) / case_images.FOLDER).is_dir()       # none in a run from before they were kept: said once
    images = "" if not kept else image_html(out, class_sheet, place, f"error classes of {where}",
                                            "error classes (colours above)")
    if has_flip and kept:
        images += image_html(out, flip_sheet, place, f"FLIP map of {where}", "FLIP error (scale above)")
    row = (f"<a href=\"../leaderboard.html#case-{index}\">its row in the leaderboard</a>; "
           if ranking.at_origin(rec) else "")
    key = lambda k: "" if rec.get(k) is None or (isinstance(rec[k], float) and math.isnan(rec[k])) else repr(rec[k])
    return (f"<figure class=case id={case_anchor(index)} data-error=\"{key('error_rate')}\" "
            f"data-flip=\"{key('flip')}\" data-suite={index}><figcaption><b>{html.escape(where)}</b></figcaption>"
            f"<div class=pair>{images}</div>{numbers_html(rec)}<p class=nums>{row}results.json cases[{index}]</p>"
            "</figure>")


def legend_html(has_flip: bool) -> str:
    """The class colours, named, and the FLIP colour scale from 0 to 1 with its ticks."""
    swatch = lambda col: f"<span class=sw style=\"background:rgb{tuple(int(c) for c in col)}\"></span>"
    classes = " ".join(f"{swatch(col)} {html.escape(n)}" for n, col in zip(metrics.CLASS_NAMES, metrics.CLASS_COLORS))
    out = f"<p class=note>Error classes: {classes}.</p>"
    if has_flip:
        pal = case_images.magma()
        stops = ",".join(f"rgb({','.join(str(int(c)) for c in pal[round(t * case_images.FLIP_LEVELS)])}) {t * 100:g}%"
                         for t in [i / 16 for i in range(17)])
        ticks = "".join(f"<span>{t:g}</span>" for t in SCALE_TICKS)
        out += (f"<p class=note>FLIP error per pixel (0: no visible difference from the exact render, 1: the "
                f"largest), stored to within {case_images.FLIP_BOUND:.5f}:</p><div class=bar "
                f"style=\"background:linear-gradient(to right,{stops})\"></div><div class=ticks>{ticks}</div>")
    return out


def contender_page(doc: dict, out: Path, contender: str) -> str:
    """The HTML of one contender's page."""
    place = case_images.places(doc["cases"])
    recs = [(i, r) for i, r in enumerate(doc["cases"]) if r["contender"] == contender]
    has_flip = any("flip" in r for _, r in recs)
    worst = sorted(recs, key=lambda ir: (not metrics.defined(ir[1]["error_rate"]),
                                         -ir[1]["error_rate"] if metrics.defined(ir[1]["error_rate"]) else 0, ir[0]))
    buttons = [("error", "worst error rate first")] + ([("flip", "worst FLIP first")] if has_flip else []) + [
        ("suite", "the suite's order (scene, unit, offset, light)")]
    order = "".join(f"<button type=button data-key={k} aria-pressed={'true' if k == 'error' else 'false'}>"
                    f"{html.escape(t)}</button>" for k, t in buttons)
    body = (f"<p class=meta><a href=\"../leaderboard.html\">leaderboard</a>: {html.escape(doc['suite'])}, size "
            f"{html.escape(str(doc['size']))}</p><h1>{html.escape(contender)}: its {len(recs)} cases</h1>"
            "<p class=note>Each case (a scene at a unit and offset, under one light): the error classes of the "
            "camera's receivers under the contender's shadow map against the exact visibility, and the FLIP "
            "error of the shaded render under its visibility against the exact render (what the FLIP column "
            "averages). Rates with an empty denominator are undefined.</p>" + legend_html(has_flip)
            + ("" if (Path(out) / case_images.FOLDER).is_dir() else
               f"<p class=note><b>No images:</b> this results folder has no {case_images.FOLDER}/ (a run from before "
               "dsm benchmark kept them); a new run keeps each case's pair.</p>")
            + f"<div class=order>Order: {order}</div><div id=cards>"
            + "".join(card_html(out, i, place[i], r, has_flip) for i, r in worst) + "</div>")
    return (f"<!doctype html><html><head><meta charset=utf-8><title>{html.escape(contender)}: "
            f"{html.escape(doc['suite'])}</title><meta name=viewport content=\"width=device-width\">"
            f"<style>{CSS}{PAGE_CSS}</style></head><body>{body}<script>{ORDER_SCRIPT}</script></body></html>")


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
