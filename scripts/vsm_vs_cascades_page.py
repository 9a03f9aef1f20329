"""The measured tables of docs/vsm_vs_cascades.md from the committed result files (no run): rewrites the
part of the page between its two ``measured`` markers from docs/vsm_vs_cascades/comparison.csv,
flicker.csv and machine.json (written by scripts/vsm_vs_cascades.py).

    .venv/bin/python scripts/vsm_vs_cascades_page.py [--docs docs]
"""
import argparse
import csv
import json
import math
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BEGIN = "<!-- measured: begin (scripts/vsm_vs_cascades_page.py writes this part) -->"
END = "<!-- measured: end -->"
SCHEMES = ("normal_offset", "constant", "midpoint", "distance_normal")
BUDGETS = ("virtual", "equal memory", "equal rays")


def num(x) -> float:
    """A CSV cell as a number; an empty cell (an undefined value) is NaN."""
    return float(x) if x not in ("", None) else math.nan


def rate(x) -> str:
    """A rate to 4 significant digits; NaN (an empty denominator) as 'undefined'."""
    v = num(x)
    return "undefined" if math.isnan(v) else f"{v:.4g}"


def gap(x) -> str:
    """A relative gap as a signed percentage."""
    return f"{100 * num(x):+.2f} %"


def map_name(r: dict) -> str:
    """The map of a comparison row: the preset's pages, or the cascades' resolution."""
    if r["budget"] == "virtual":
        return f"vsm {r['preset']}: {r['vsm_pages_tagged']} pages"
    return f"4 x {r['resolution']}^2 ({r['budget']})"


def budget_table(rows: list) -> list:
    """Per scene, preset and budget: memory and rays (gap to the virtual map), texels per pixel, build time."""
    out = ["| scene | preset | map | texels | rays | texels/pixel median [p10, p90] | share below 1 | build ms |",
           "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["scheme"] != SCHEMES[0]:
            continue
        mem = f"{int(r['memory_texels']):,}" + ("" if r["budget"] == "virtual" else f" ({gap(r['memory_gap'])})")
        rays = f"{int(r['rays']):,}" + ("" if r["budget"] == "virtual" else f" ({gap(r['rays_gap'])})")
        tpp = f"{num(r['texels_per_pixel']):.3g} [{num(r['tpp_p10']):.3g}, {num(r['tpp_p90']):.3g}]"
        out.append(f"| {r['scene_label']} | {r['preset']} | {map_name(r)} | {mem} | {rays} | {tpp} | "
                   f"{rate(r['tpp_below_1'])} | {num(r['build_ms']):.0f} |")
    return out


def error_table(rows: list) -> list:
    """Per scene, preset and budget: each scheme's error rate, normal_offset's acne and peter-panning, and
    its error rate within 4 texels of a transition (receivers there) and off them."""
    by = {(r["scene_label"], r["preset"], r["budget"], r["scheme"]): r for r in rows}
    keys = list(dict.fromkeys((r["scene_label"], r["preset"], r["budget"]) for r in rows))
    out = ["| scene | preset | map | " + " | ".join(f"error {s}" for s in SCHEMES)
           + " | normal_offset acne / peter-panning | near a transition (receivers) | off |",
           "|---" * (3 + len(SCHEMES) + 3) + "|"]
    for k in keys:
        no = by[(*k, SCHEMES[0])]
        errs = " | ".join(rate(by[(*k, s)]["error_rate"]) if (*k, s) in by else "-" for s in SCHEMES)
        out.append(f"| {k[0]} | {k[1]} | {map_name(no)} | {errs} | {rate(no['acne_rate'])} / "
                   f"{rate(no['peterpan_rate'])} | {rate(no['transition_error_rate'])} ({no['n_transition']}) | "
                   f"{rate(no['off_transition_error_rate'])} |")
    return out


def flicker_table(rows: list) -> list:
    """Per scene, motion and map: flicker rates (all, same level or cascade, changed), ever, maps built."""
    out = ["| scene | motion | map | flicker rate | same level | level changed | ever | maps built |",
           "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        m = r["map"] if r["map"].startswith("vsm") else f"4 x {r['resolution']}^2"
        out.append(f"| {r['scene_label']} | {r['motion']} | {m} | {rate(r['flicker_rate'])} | "
                   f"{rate(r['flicker_within_rate'])} | {rate(r['flicker_change_rate'])} | {rate(r['flicker_ever'])} | "
                   f"{r['maps_built']} |")
    return out


def measured_text(folder: Path) -> str:
    """The page's measured part from the result files in ``folder``."""
    rows = list(csv.DictReader(open(folder / "comparison.csv")))
    flick = list(csv.DictReader(open(folder / "flicker.csv")))
    info = json.loads((folder / "machine.json").read_text())
    head = (f"Made by `scripts/vsm_vs_cascades.py` from `{info['config']}` at commit {info['commit']} on "
            f"{info['date']} ({info['machine']}, {info['variant']}, Mitsuba {info['mitsuba']}, Dr.Jit "
            f"{info['drjit']}; {info['wall_s']} s). Counts and rates do not depend on the machine; build times do.")
    parts = [head, "", "### Memory, rays, texels per pixel", "", *budget_table(rows), "",
             "### Errors", "", *error_table(rows), "", "### Flicker (normal_offset, 1 texel)", "",
             *flicker_table(flick)]
    return "\n".join(parts)


def main():
    """Rewrite the measured part of docs/vsm_vs_cascades.md."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--docs", default=str(ROOT / "docs"))
    docs = Path(ap.parse_args().docs)
    page = docs / "vsm_vs_cascades.md"
    text = page.read_text()
    if BEGIN not in text or END not in text:
        raise SystemExit(f"{page}: no measured markers ({BEGIN} ... {END})")
    a, rest = text.split(BEGIN, 1)
    _, b = rest.split(END, 1)
    page.write_text(a + BEGIN + "\n" + measured_text(docs / "vsm_vs_cascades") + "\n" + END + b)
    print(f"wrote {page}")


if __name__ == "__main__":
    main()
