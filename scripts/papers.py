#!/usr/bin/env python3
"""The papers page: docs/papers.md from the runs committed under docs/papers/runs/ (no run here).

    python scripts/papers.py                  # write docs/papers.md from docs/papers/runs/
    python scripts/papers.py --check          # exit 1 where docs/papers.md is not what the runs give
    python scripts/papers.py record RUNS      # copy the small files of the runs in RUNS (dsm run/tune
                                              # --out RUNS/<experiment>) and their provenance here

Each claim of the five source documents is one sentence, the figure or table it comes from, the
experiment that measures it, dsm's number and a verdict computed from the numbers (agrees, does
not, or not measurable); where it does not agree, the claim's note says why.
"""
from __future__ import annotations

import argparse
import csv
import hashlib
import json
import math
import platform
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parent.parent
RUNS = ROOT / "docs" / "papers" / "runs"
PAGE = ROOT / "docs" / "papers.md"
KEEP = ("metrics.csv", "cascades.csv", "tune.json", "tuned.toml", "table.md")   # small result files of a run


# ---------------------------------------------------------------- reading the runs

def read_rows(runs: Path, experiment: str) -> list[dict]:
    """The metrics.csv rows of a committed run, numbers as floats (an empty cell: NaN)."""
    with open(runs / experiment / "metrics.csv", newline="") as f:
        return [{k: _number(v) for k, v in r.items()} for r in csv.DictReader(f)]


def _number(v: str):
    try:
        return float(v) if v != "" else math.nan
    except ValueError:
        return v


def where(rows: list[dict], **eq) -> list[dict]:
    """The rows whose columns equal ``eq`` (a trailing ``__has``: the column contains the text)."""
    def ok(r):
        return all((str(v) in str(r[k[:-5]])) if k.endswith("__has") else r[k] == v for k, v in eq.items())
    return [r for r in rows if ok(r)]


def one(rows: list[dict], **eq) -> dict:
    """The one row matching ``eq``; a clear error where none or several match."""
    got = where(rows, **eq)
    if len(got) != 1:
        raise LookupError(f"{len(got)} rows match {eq}")
    return got[0]


def pct(x: float) -> str:
    """A rate as a percentage with 3 significant digits ("undefined" for NaN)."""
    return "undefined" if math.isnan(x) else f"{100 * x:.3g} %"


# ---------------------------------------------------------------- claims

@dataclass(frozen=True)
class Claim:
    """One headline claim of a source, where it is made, the run that measures it, and why not."""
    source: str
    claim: str
    where: str
    experiment: str
    measure: Callable          # rows -> (dsm's number in words, True / False / None: not measurable)
    agrees_when: str = ""      # the verdict's test, in words
    why: str = ""              # shown where the verdict is not "agrees"


def _culling_removes_midpoint_acne(rows):
    a, b = (one(rows, scheme="midpoint", culling=c, resolution=64.0)["acne_rate"] for c in ("none", "back_closed"))
    return f"midpoint acne {pct(a)} without culling, {pct(b)} with (64^2)", b < a


def _dual_culled_is_best(rows):
    r64 = [r for r in rows if r["resolution"] == 64.0]
    best = min(r64, key=lambda r: r["error_rate"])
    dual = one(r64, scheme="dual", culling="back_closed")
    const = one(r64, scheme="constant")
    return (f"dual + culling errs {pct(dual['error_rate'])} (acne {int(dual['n_acne'])} receivers, the constant "
            f"0.3's {int(const['n_acne'])}); lowest: {best['scheme']} {best['params']} {pct(best['error_rate'])}",
            best is dual)


def _second_layer_doubles_build(rows):
    c, d = (one(rows, scheme=s)["build_ms"] for s in ("constant", "dual"))
    return f"build {d:.0f} ms (two layers) against {c:.0f} ms (one), x{d / c:.2f} (1024^2)", d / c > 1.3


def _paraboloid_as_good_as_cube(rows):
    ratios = []
    for dp in where(rows, scene="room", scheme="adaptive", view="dual_paraboloid"):
        cube = [r for r in where(rows, scene="room", scheme="adaptive", view="cube", light=dp["light"])
                if abs(r["total_texels"] - dp["total_texels"]) / dp["total_texels"] < 0.01]
        ratios.append(dp["error_rate"] / one(cube)["error_rate"])
    geo = math.exp(sum(map(math.log, ratios)) / len(ratios))
    return (f"dual paraboloid / cube error, adaptive bias, the room's two lights at 2^17, 2^19, 2^21 texels: "
            f"{', '.join(f'{x:.2f}' for x in ratios)} (geometric mean {geo:.2f})", geo <= 1.25)


def _not_measurable(_rows):
    return "not measured", None


def _slope_beats_constant(rows):
    s = one(rows, scene__has="sponza", scheme="slope_scaled", resolution=1024.0)
    c = one(rows, scene__has="sponza", scheme="constant", params="bias=1 texel", resolution=1024.0)
    return f"acne {pct(s['acne_rate'])} (slope-scaled) against {pct(c['acne_rate'])} (constant 1 texel)", \
        s["acne_rate"] < c["acne_rate"]


def _tight_fit_helps(rows):
    got = {fit: one(rows, scheme="constant", format="float32", cascade_layout=f"1x practical(0.5) fit={fit}")
           for fit in ("scene", "frustum")}
    s, f = got["scene"], got["frustum"]
    return (f"texels per pixel {f['texels_per_pixel']:.3g} (fit to the view frustum) against "
            f"{s['texels_per_pixel']:.3g} (the scene); error {pct(f['error_rate'])} against {pct(s['error_rate'])}",
            f["texels_per_pixel"] > s["texels_per_pixel"] and f["error_rate"] < s["error_rate"])


def _sixteen_bits_suffice(rows):
    lay = "1x practical(0.5) fit=frustum"
    a, b = (one(rows, scheme="constant", format=fmt, cascade_layout=lay)["error_rate"] for fmt in ("float32", "unorm16"))
    return f"error {pct(b)} in unorm16 against {pct(a)} in float32 (tight near/far)", b <= 1.05 * a


def _texel_steps_stop_shimmer(rows):
    moving = where(rows, motion="camera sideways", scheme="constant")
    stable = [r["flicker_rate"] for r in moving if "stable" in r["cascade_layout"]]
    loose = [r["flicker_rate"] for r in moving if "stable" not in r["cascade_layout"]]
    return f"flicker {pct(max(stable))} stabilized against {pct(min(loose))} to {pct(max(loose))} not " \
           f"(camera moving sideways)", max(stable) < min(loose)


def _no_constant_fits_all(rows):
    lo, hi = (one(rows, scene__has="sponza", scheme="constant", params=f"bias={b} texel", resolution=1024.0)
              for b in (1, 3))
    return (f"1 texel: acne {pct(lo['acne_rate'])}, peter-panning {pct(lo['peterpan_rate'])}; 3 texels: acne "
            f"{pct(hi['acne_rate'])}, peter-panning {pct(hi['peterpan_rate'])}",
            hi["acne_rate"] < lo["acne_rate"] and hi["peterpan_rate"] > lo["peterpan_rate"])


def _metal_values_do_well(rows):
    rs = where(rows, scene__has="sponza", resolution=1024.0)
    s = one(rs, scheme="slope_scaled")
    rank = 1 + sum(r["error_rate"] < s["error_rate"] for r in rs)
    ties = sum(r["error_rate"] == s["error_rate"] for r in rs) - 1
    tied = f", tied with {ties}" if ties else ""
    return f"error {pct(s['error_rate'])}, rank {rank}{tied} of {len(rs)} instances (1024^2)", rank <= 3


def _table1_costs(rows):
    cost = {r["scheme"]: r["build_ms"] + r["lookup_ms"] for r in rows}
    rel = {k: v / cost["constant"] for k, v in cost.items()}
    return (f"build + lookup relative to constant: slope {rel['slope_scaled']:.2f}, adaptive {rel['adaptive']:.2f}, "
            f"dual {rel['dual']:.2f} (paper: 1.05, 1.16, 1.56)",
            rel["adaptive"] <= 1.3 and rel["dual"] > max(rel["adaptive"], rel["slope_scaled"]))


def _figure6(rows):
    get = {r["scheme"]: r for r in rows}
    a, c, s = get["adaptive"], get["constant"], get["slope_scaled"]
    counts = {(r["n_acne"], r["n_peterpan"]) for r in rows}
    tie = " (a tie: every scheme errs on the same counts)" if len(counts) == 1 else ""
    return (f"acne: adaptive {pct(a['acne_rate'])}, constant {pct(c['acne_rate'])}, slope {pct(s['acne_rate'])}; "
            f"peter-panning: adaptive {pct(a['peterpan_rate'])}, constant {pct(c['peterpan_rate'])}, "
            f"slope {pct(s['peterpan_rate'])}{tie}",
            a["acne_rate"] < min(c["acne_rate"], s["acne_rate"])
            and a["peterpan_rate"] <= min(c["peterpan_rate"], s["peterpan_rate"]))


def _vsv_adaptive(rows):
    out, ok = [], True
    for res in sorted({r["resolution"] for r in where(rows, view="vsv")}):
        ad = one(rows, scheme="vsv_adaptive", resolution=res)
        eps = where(rows, scheme="vsv_epsilon", resolution=res)
        best = min(eps, key=lambda r: r["error_rate"])
        out.append(f"R = {int(res)}: {pct(ad['error_rate'])} against the best epsilon's {pct(best['error_rate'])}")
        ok = ok and ad["error_rate"] < best["error_rate"]
    return "error, adaptive voxel choice: " + "; ".join(out), ok


def _adaptive_needs_resolution(rows):
    a = {int(r["resolution"]): r["acne_rate"] for r in where(rows, scene__has="sponza", scheme="adaptive")}
    return f"adaptive acne {pct(a[512])} at 512^2, {pct(a[1024])} at 1024^2", a[512] > a[1024]


WE, BR, MS, SA, DO = ("Weiskopf & Ertl 2003", "Brabec et al. 2002", "Microsoft, Common Techniques",
                      "Salcedo, Shadow Maps", "Dou et al. 2014")
CLAIMS = (
    Claim(WE, "Back-face culling removes midpoint shadow mapping's self-shadowing at silhouettes.", "Figure 5 (b), (e)",
          "weiskopf_fig5", _culling_removes_midpoint_acne, "culled acne < unculled acne"),
    Claim(WE, "Dual shadow mapping with back-face culling of solid objects gives the most convincing result of the "
          "six, even heavily undersampled.", "Figure 5 (f)", "weiskopf_fig5", _dual_culled_is_best,
          "dual + culling has the lowest error at 64^2",
          why="With culling, z1 is the L-shape's back face and (z2 - z1) / 2 exceeds z_offset = 0.3 nearly everywhere, "
              "so dual reduces to the constant 0.3 (the same acne count as image (d)); midpoint's half-thickness bias "
              "is larger, and errs less on this closed solid."),
    Claim(WE, "The second depth layer makes phase one (the map's build) markedly slower at large maps: midpoint and "
          "dual run at about half the speed of one layer.", "Table 1", "dou_table1", _second_layer_doubles_build,
          "dual's build / constant's > 1.3 (times on a shared machine vary between runs)"),
    Claim(BR, "A dual paraboloid map (two maps) serves an omnidirectional light as well as a cube (six).",
          "Section 3, Figure 3", "point_views", _paraboloid_as_good_as_cube,
          "geometric mean of the error ratios at equal texels <= 1.25",
          why="The cube's texels are spread more evenly than the paraboloid's, whose sampling rate falls toward "
              "the rim."),
    Claim(BR, "The paraboloid map fails for very large polygons, whose depth the rasterizer interpolates linearly.",
          "Section 4, Conclusion", "point_views", _not_measurable, "-",
          why="dsm casts one ray per texel, so the rasterizer's interpolation this is about never happens."),
    Claim(MS, "Slope-scaled depth bias removes acne that a constant bias leaves.", "Figure 10", "real_meshes",
          _slope_beats_constant, "slope-scaled acne < constant 1 texel's, Sponza 1024^2"),
    Claim(MS, "Fitting the light's projection to the view frustum, not the scene, gives more texels per pixel and "
          "less aliasing.", "Figures 11, 12", "common_techniques_fit", _tight_fit_helps,
          "more texels per pixel and a lower error (one map, float32, constant bias)"),
    Claim(MS, "With tight near and far planes a 16-bit depth buffer can do.",
          "Calculating the Near Plane and Far Plane",
          "common_techniques_fit", _sixteen_bits_suffice, "unorm16 error <= 1.05 x float32's"),
    Claim(MS, "Moving the light in texel-sized increments removes shimmering edges.", "Figures 16, 17",
          "common_techniques_shimmer", _texel_steps_stop_shimmer, "every stabilized flicker rate < every other"),
    Claim(SA, "A hard-coded bias never works for all cases: pushed far enough to remove acne, it detaches shadows.",
          "Shadow acne, peter-panning", "real_meshes", _no_constant_fits_all,
          "3 texels: less acne and more peter-panning than 1 texel (Sponza 1024^2)"),
    Claim(SA, "The API's slope-scaled bias (bias 1, slope 3, clamp 1/128) performs quite well.",
          "setDepthBias example", "real_meshes", _metal_values_do_well, "among the 3 lowest errors on Sponza 1024^2"),
    Claim(DO, "Adaptive bias adds little to the cost of constant and slope-scaled bias; dual layers, with a second "
          "shadow-map pass, cost the most.", "Table 1", "dou_table1", _table1_costs,
          "adaptive / constant <= 1.3 and dual the dearest (times on a shared machine vary between runs)"),
    Claim(DO, "At 1024^2 constant and slope-scaled bias show acne and detachment; adaptive bias shows no false "
          "shadows, as dual layers.", "Figure 6", "dou_table1", _figure6,
          "adaptive acne < constant's and slope's, and its peter-panning no higher",
          why="From this camera every scheme errs on the same receivers (the Figure 6 table below): at 1024^2 the "
              "bias decides none of them, so the difference the figure shows does not appear in the counts."),
    Claim(DO, "The adaptive voxel choice removes VSVs' false self-shadowing and keeps more shadow detail than a "
          "constant epsilon.", "Section 3.3, Figure 8", "vsv_sponza", _vsv_adaptive,
          "adaptive error < the best epsilon's at each R"),
    Claim(DO, "The planar-occluder assumption needs resolution: at 512^2 false self-shadowing reappears.",
          "Figure 12", "real_meshes", _adaptive_needs_resolution, "adaptive acne at 512^2 > at 1024^2 (Sponza)"),
)


def verdict(ok) -> str:
    """A claim's verdict in words."""
    return {True: "agrees", False: "does not agree", None: "not measurable"}[ok]


def claims_table(runs: Path) -> list[str]:
    """The claims as Markdown: one table per source."""
    out = []
    for source in dict.fromkeys(c.source for c in CLAIMS):
        out += [f"### {source}", "", "| claim | from | experiment | dsm | agrees when | verdict |",
                "| --- | --- | --- | --- | --- | --- |"]
        for c in (c for c in CLAIMS if c.source == source):
            number, ok = c.measure(read_rows(runs, c.experiment))
            note = f" {c.why}" if ok is not True and c.why else ""
            out.append(f"| {c.claim} | {c.where} | `{c.experiment}` | {number} | {c.agrees_when} | {verdict(ok)}.{note} |")
        out.append("")
    return out


# ---------------------------------------------------------------- the Sponza tables

def md_table(head: list[str], body: list[list]) -> list[str]:
    """A Markdown table."""
    return ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)] + ["| " + " | ".join(map(str, r)) + " |"
                                                                          for r in body]


DOU_TABLE1_MS = {"constant": 6.327, "slope_scaled": 6.647, "adaptive": 7.319, "dual": 9.890}   # "Overall", GTX 580


def table1(rows: list[dict]) -> list[str]:
    """Dou et al.'s Table 1 beside dsm's build and lookup times (dou_table1, 1024^2)."""
    base = rows[0]["build_ms"] + rows[0]["lookup_ms"]
    body = [[r["scheme"], r["params"], f"{r['build_ms']:.1f}", f"{r['lookup_ms']:.3f}",
             f"{(r['build_ms'] + r['lookup_ms']) / base:.2f}", f"{DOU_TABLE1_MS[r['scheme']]:.3f}",
             f"{DOU_TABLE1_MS[r['scheme']] / DOU_TABLE1_MS['constant']:.2f}"] for r in rows]
    return md_table(["scheme", "parameters", "build ms", "lookup ms", "dsm relative", "paper overall ms",
                     "paper relative"], body)


def figure6(rows: list[dict]) -> list[str]:
    """Dou et al.'s Figure 6 as counts: acne and detachment per scheme (dou_table1, 1024^2)."""
    body = [[r["scheme"], r["params"], f"{int(r['n_acne'])} / {int(r['n_gt_lit'])}", pct(r["acne_rate"]),
             f"{int(r['n_peterpan'])} / {int(r['n_gt_shadowed'])}", pct(r["peterpan_rate"]), pct(r["error_rate"])]
            for r in rows]
    return md_table(["scheme", "parameters", "acne (of lit)", "acne rate", "detached (of shadowed)",
                     "peter-panning rate", "error rate"], body)


def vsv_memory_bits(r: dict) -> int:
    """A map's memory in bits: a VSV R^2 light rays of ``alpha`` bits, a dual paraboloid 2 R^2 float32."""
    res = int(r["resolution"])
    if r["view"] == "vsv":
        return res * res * int(str(r["params"]).split("alpha=")[1].split()[0])
    return 2 * res * res * 32


def vsv_table(rows: list[dict]) -> list[str]:
    """The VSV and the dual paraboloid map's adaptive bias on Sponza, with each one's memory."""
    body = [[r["view"], int(r["resolution"]), r["scheme"], r["params"], f"{vsv_memory_bits(r) / 8 / 2**20:.2f}",
             pct(r["acne_rate"]), pct(r["peterpan_rate"]), pct(r["error_rate"])]
            for r in sorted(rows, key=lambda r: (vsv_memory_bits(r), r["view"], r["scheme"], str(r["params"])))]
    return md_table(["view", "R", "scheme", "parameters", "MiB", "acne", "peter-panning", "error"], body)


def rates_table(rows: list[dict], lead: tuple) -> list[str]:
    """Rows' ``lead`` columns with their acne, peter-panning and error rates."""
    body = [[(int(r[k]) if isinstance(r[k], float) and r[k].is_integer() else r[k]) for k in lead]
            + [pct(r["acne_rate"]), pct(r["peterpan_rate"]), pct(r["error_rate"])] for r in rows]
    return md_table(list(lead) + ["acne", "peter-panning", "error"], body)


def tune_tables(run: Path) -> list[str]:
    """dsm tune on Sponza: each scheme's tuned instance and errors, then the learned map's section."""
    text = (run / "table.md").read_text().splitlines()
    head = next(i for i, l in enumerate(text) if l.startswith("| scheme | tuned |"))
    body = []
    for line in text[head + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        body.append(cells[:4])
    learned = text[text.index("## learned bias map") + 1:]
    return md_table(["scheme", "tuned", "train", "held-out"], body) + [""] + learned


# ---------------------------------------------------------------- provenance and the page

def provenance(runs: Path) -> dict:
    """The committed runs' provenance (provenance.json, written by ``record``)."""
    return json.loads((runs / "provenance.json").read_text())


def provenance_lines(prov: dict) -> list[str]:
    """Where the numbers come from: commit, machine, the mesh copy, each run's command."""
    mesh = prov["mesh"]
    commits = sorted(set(r["commit"] for r in prov["runs"].values()))
    out = [f"Runs made {prov['date']} on {prov['machine']} (Mitsuba {prov['versions']['mitsuba']}, Dr.Jit "
           f"{prov['versions']['drjit']}, variant {prov['variant']}), at dsm commit"
           + ("s " if len(commits) > 1 else " ") + ", ".join(f"`{c[:10]}`" for c in commits) + ".",
           f"Sponza: the team's copy `{mesh['file']}`, {mesh['version']} version, {mesh['triangles']:,} triangles, "
           f"SHA-256 `{mesh['sha256']}` (data/meshes/README.md says where to obtain one).", "",
           "| run | command | dsm commit |", "| --- | --- | --- |"]
    out += [f"| `{name}` | `{r['command']}` | `{r['commit'][:10]}` |" for name, r in sorted(prov["runs"].items())]
    return out


def sponza_sections(runs: Path) -> list[str]:
    """The Sponza measurements: Table 1, Figure 6, the VSVs, the cascades, the tuning, the real-mesh rows."""
    dou, vsv = read_rows(runs, "dou_table1"), read_rows(runs, "vsv_sponza")
    casc = read_rows(runs, "cascades_sponza")
    real = where(read_rows(runs, "real_meshes"), scene__has="sponza")
    out = ["### Dou et al.'s Table 1: relative cost at 1024^2", "",
           "Their scene is \"Sponza (20K polygons)\": neither model exactly (the Dabrovic copy here holds "
           f"{provenance(runs)['mesh']['triangles']:,} triangles, Crytek's remodel about 262,000). dsm times its "
           "ray-traced build and its lookup on the CPU; the paper times a GPU's shadow-map pass and final shading. "
           "Times on a shared machine vary from run to run: the order is what compares, the ratios only roughly.", ""]
    out += table1(dou) + ["", "### Dou et al.'s Figure 6: acne and detachment at 1024^2", "",
                          "The camera inside the courtyard (experiments/dou_table1.toml); counts of receivers.", ""]
    out += figure6(dou) + ["", "### Voxelized shadow volumes on Sponza, a point light (section 3.3, Figure 8)", "",
                           "Beside the dual paraboloid map's adaptive bias; rows in order of memory: a VSV of "
                           "R x R light rays and 256 alpha voxels equals a dual paraboloid map of 2R per face.", ""]
    out += vsv_table(vsv) + ["", "### Cascades on Sponza", ""]
    out += rates_table(casc, ("cascade_layout", "scheme", "params")) + ["", "### dsm tune on Sponza", ""]
    out += tune_tables(runs / "tune_sponza") + ["", "### Sponza's rows of real_meshes", ""]
    out += rates_table(real, ("resolution", "scheme", "params", "culling"))
    return out


def page(runs: Path = RUNS) -> str:
    """docs/papers.md's text from the committed runs."""
    out = ["# The papers' claims, measured", "",
           "Each source document's headline claims, the figure or table each comes from, the experiment that "
           "measures it, dsm's number and whether it agrees. Generated by `scripts/papers.py` from the runs "
           "committed under `docs/papers/runs/` (nothing runs when the page is built); to remake them, see "
           "*Remaking the runs* below.", "", "## Provenance", ""]
    out += provenance_lines(provenance(runs)) + ["", "## Claims", ""] + claims_table(runs)
    out += ["## Sponza, measured with a copy", ""] + sponza_sections(runs)
    out += ["", "## Remaking the runs", "",
            "With a copy of Sponza (docs/sponza.md): run each command of the provenance table with "
            "`--out RUNS/<run>` and `DSM_SPONZA=<your copy>`, then `python scripts/papers.py record RUNS` "
            "and `python scripts/papers.py`.", ""]
    return "\n".join(out)


def record(src: Path, runs: Path = RUNS) -> None:
    """Copy the small result files of the runs in ``src`` under ``runs`` with their provenance."""
    import os
    mesh = Path(os.environ["DSM_SPONZA"])
    prov = {"date": None, "machine": machine(), "mesh": mesh_facts(mesh), "runs": {}}
    for run in sorted(p for p in src.iterdir() if p.is_dir()):
        (runs / run.name).mkdir(parents=True, exist_ok=True)
        for name in KEEP:
            if (run / name).is_file():
                shutil.copyfile(run / name, runs / run.name / name)
        info = json.loads((run / "run.json").read_text()) if (run / "run.json").is_file() else {}
        versions = info.get("versions") or _here_versions()
        prov["versions"], prov["variant"] = versions, info.get("variant", "llvm_ad_rgb")
        command = "dsm tune" if run.name.startswith("tune_") else "dsm run"
        prov["runs"][run.name] = {"command": f"{command} experiments/{run.name}.toml",
                                  "commit": info.get("versions", {}).get("dsm_git_commit")}
    # dsm tune's folder names no commit: the other runs' one where they share it (made together), else HEAD
    made = {r["commit"] for r in prov["runs"].values() if r["commit"]}
    for r in prov["runs"].values():
        r["commit"] = r["commit"] or (made.pop() if len(made) == 1 else _git_commit())
    prov["date"] = subprocess.run(["date", "-u", "+%Y-%m-%d"], capture_output=True, text=True).stdout.strip()
    (runs / "provenance.json").write_text(json.dumps(prov, indent=1, sort_keys=True) + "\n")


def machine() -> str:
    """This machine in words: CPU model, cores, memory, OS."""
    cpu = next((l.split(":", 1)[1].strip() for l in Path("/proc/cpuinfo").read_text().splitlines()
                if l.startswith("model name")), platform.processor())
    mem = int(next(l.split()[1] for l in Path("/proc/meminfo").read_text().splitlines() if l.startswith("MemTotal")))
    import os
    return f"{cpu}, {os.cpu_count()} cores (shared), {mem / 2**20:.0f} GiB, {platform.system()} {platform.machine()}"


def mesh_facts(path: Path) -> dict:
    """The mesh copy's name, SHA-256, triangles and Sponza version."""
    sys.path.insert(0, str(ROOT))
    from dsm.scenes.models import SPONZA, version_of
    from dsm.scenes.size import ply_triangles, obj_triangles
    tris = ply_triangles(path) if path.suffix.lower() == ".ply" else obj_triangles(path)
    return {"file": path.name, "sha256": hashlib.sha256(path.read_bytes()).hexdigest(), "triangles": tris,
            "version": version_of(SPONZA, path, None, "DSM_SPONZA", "scene").name}


def _here_versions() -> dict:
    import drjit
    import mitsuba
    return {"mitsuba": mitsuba.__version__, "drjit": drjit.__version__, "dsm_git_commit": _git_commit()}


def _git_commit() -> str:
    return subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()


def main(argv=None) -> int:
    """Write (or --check) docs/papers.md, or record runs."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 where docs/papers.md differs from the runs' page")
    ap.add_argument("record", nargs="*", help="record RUNS: copy the runs in RUNS here with their provenance")
    args = ap.parse_args(argv)
    if args.record:
        if args.record[0] != "record" or len(args.record) != 2:
            ap.error("usage: papers.py record RUNS")
        record(Path(args.record[1]))
    text = page()
    if args.check:
        same = PAGE.is_file() and PAGE.read_text() == text
        print("docs/papers.md is " + ("up to date" if same else "stale: run python scripts/papers.py"))
        return 0 if same else 1
    PAGE.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
