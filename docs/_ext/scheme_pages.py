"""One page per bias scheme, generated from its module: its docstring (what it fixes, the formula), its
parameters with units and defaults (the registry's ``Params``), its source, and its error image of one
scene beside every other scheme's.

The images are committed (``docs/scheme_images/``, with ``rates.json``), made by ``make_images`` from
``CONFIG``: every scheme at its defaults on the room and its point light (the depth schemes on a cube
map, the voxelized shadow volumes on their own view). tests/test_scheme_pages.py runs ``CONFIG`` again
and fails where a committed image or rate is stale. ``python docs/_ext/scheme_pages.py`` remakes them.
"""
from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1]
IMAGES = DOCS / "scheme_images"
RATES = IMAGES / "rates.json"
CONFIG = {"experiment": {"name": "scheme_images"}, "camera": {"resolution": [160, 160]},
          "scene": [{"builtin": "room"}], "light": [{"type": "scene"}],
          "map": {"resolution": 256, "view": ["cube", "vsv"]},
          "timing": {"repeats": 1}, "report": {"images": "errors"}}
RATE_COLUMNS = ("acne_rate", "peterpan_rate", "error_rate")


def config() -> dict:
    """CONFIG with one ``[[scheme]]`` a registered scheme, each at its defaults."""
    from dsm import schemes
    return {**CONFIG, "scheme": [{"name": s.NAME} for s in schemes.ALL]}


def make_images(folder: Path, out: Path | None = None) -> dict:
    """Run config() and write each scheme's error image (``<name>.png``) and the rates
    (``rates.json``) into ``folder``; returns the rates {name: {view, params, rates...}}."""
    import dsm
    from dsm.report import figures
    res = dsm.run(config(), out=out)
    folder.mkdir(parents=True, exist_ok=True)
    rates = {}
    for r in res.rows:
        shutil.copyfile(res.out / figures.image_paths(r)[0], folder / f"{r['scheme']}.png")
        rates[r["scheme"]] = {"view": r["view"], "params": r["params"], **{c: r[c] for c in RATE_COLUMNS}}
    (folder / "rates.json").write_text(json.dumps(rates, indent=1, sort_keys=True) + "\n")
    return rates


def rate_text(x) -> str:
    """A rate to three significant digits; ``undefined`` for an empty denominator (NaN)."""
    return "undefined" if x != x else f"{x:.3g}"


def scheme_page(s, rates: dict) -> str:
    """A scheme's page (Markdown): its docstring, parameters, source, needs, and its error image."""
    from dsm.core.labels import params_label
    from generate import param_table
    doc = (s.__doc__ or "").strip()
    title, _, body = doc.partition("\n")
    r = rates.get(s.NAME)
    out = [f"# {s.NAME}", "", f"**{title.strip()}**", "", body.strip(), "",
           "## Parameters", "", "Units: a length is world units, `\"k texel\"` or `\"k range\"` (a fraction of the "
           "view's depth range); `2^k` reads as a number (`\"2^-24 range\"`).", ""] + param_table(s.Params) + [
           "", "## Source", "", f"{s.SOURCE}. Map layers it reads beyond the depth: "
           f"{', '.join(sorted(s.NEEDS)) or 'none'}. Module: `dsm/schemes/{s.__name__.rsplit('.', 1)[1]}.py`.", "",
           "## Its errors on the room", ""]
    if r is None:
        return "\n".join(out + ["No image: this scheme is not in docs/scheme_images/rates.json yet.", ""])
    out += [f"The room lit by its point light, camera 160 x 160, map 256 ({r['view']} view), "
            f"`{s.NAME}` at its defaults ({params_label(r['params'], exact=True) or 'no parameters'}): acne rate {rate_text(r['acne_rate'])}, "
            f"peter-panning rate {rate_text(r['peterpan_rate'])}, error rate {rate_text(r['error_rate'])}. Colours: "
            "red acne, blue peter-panning (dark: below the map's resolution), cream correctly lit, slate correctly "
            "shadowed, black no receiver. Every scheme's page shows the same scene: "
            "[all of them side by side](index.md).", "",
            f"```{{image}} ../../scheme_images/{s.NAME}.png", f":alt: error classes of {s.NAME} on the room",
            ":width: 480px", ":class: pixelated", "```", ""]
    return "\n".join(out)


def index_page(registry, rates: dict) -> str:
    """The schemes' index: a line per scheme (its page, its first docstring line, its error rate) and every image."""
    out = ["# One page per scheme", "", "Each scheme's page: what it fixes and its formula (its module's docstring), "
           "its parameters with units and defaults, its source, and its errors on one scene (the room, its point "
           "light, map 256), the same for every scheme.", "",
           "```{toctree}", ":hidden:", ""] + [s.NAME for s in registry] + ["```", "",
           "| scheme | what it is | error rate on the room |", "|---|---|---|"]
    for s in registry:
        r = rates.get(s.NAME, {})
        what = " ".join((s.__doc__ or "").strip().split("\n")[0].split()).replace("|", "\\|")
        out.append(f"| [{s.NAME}]({s.NAME}.md) | {what} | {rate_text(r['error_rate']) if r else '-'} |")
    shown = [s.NAME for s in registry if s.NAME in rates]
    out += ["", "Side by side (four a row):", ""]
    for i in range(0, len(shown), 4):
        row = shown[i:i + 4]
        out += ["| " + " | ".join(f"[{n}]({n}.md)" for n in row) + " |", "|---" * len(row) + "|",
                "| " + " | ".join(f"![{n}](../../scheme_images/{n}.png)" for n in row) + " |", ""]
    return "\n".join(out)


def write_pages(gen: Path):
    """Every scheme's page and the index under ``gen/schemes/``."""
    from dsm import schemes
    rates = json.loads(RATES.read_text()) if RATES.is_file() else {}
    folder = gen / "schemes"
    folder.mkdir(parents=True, exist_ok=True)
    for s in schemes.ALL:
        (folder / f"{s.NAME}.md").write_text(scheme_page(s, rates))
    (folder / "index.md").write_text(index_page(schemes.ALL, rates))


if __name__ == "__main__":          # remake the committed images and rates
    sys.path.insert(0, str(DOCS.parent))
    print(json.dumps(make_images(IMAGES), indent=1))
