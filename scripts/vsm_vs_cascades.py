"""Virtual shadow maps against 4 cascades at equal memory and at equal rays, and their flicker under
the camera's motions (docs/vsm_vs_cascades.md): runs experiments/vsm_vs_cascades.toml scene by scene,
then the cascades at the budgets its virtual maps set, and writes the small result files the page is
made from (scripts/vsm_vs_cascades_page.py).

    .venv/bin/python scripts/vsm_vs_cascades.py [--config experiments/vsm_vs_cascades.toml]
        [--out runs/vsm_vs_cascades] [--docs docs/vsm_vs_cascades]

The budgets (dsm.maps.budget.cascade_resolution): equal memory, the R whose 4 R^2 texels are nearest
the virtual map's physical texels (pages x page_size^2); equal rays, the R whose rays are nearest the
virtual map's, the cascades' rays per texel taken from their run at equal memory.
"""
import argparse
import csv
import json
import platform
import subprocess
import sys
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import dsm  # noqa: E402
from dsm.maps.budget import budget_gap, cascade_resolution  # noqa: E402

CASCADES = 4
KEEP = ("scene", "scheme", "params", "resolution", "total_texels", "n_receivers", "n_acne", "n_peterpan",
        "acne_rate", "peterpan_rate", "error_rate", "texels_per_pixel", "tpp_p10", "tpp_p90", "tpp_below_1",
        "n_transition", "transition_error_rate", "off_transition_error_rate", "fit_ms", "lookup_ms",
        "vsm_pages_tagged", "vsm_memory_texels", "vsm_rays", "vsm_level_histogram")
FLICKER = ("scene", "motion", "scheme", "params", "resolution", "flicker_rate", "flicker_within_rate",
           "flicker_change_rate", "flicker_ever", "maps_built")
# the kit's camera motions, 6 frames each (a scene unit is a metre): on the first MOTION_SCENES scenes
MOTIONS = [{"label": "dolly", "frames": 6, "camera": "dolly", "offset": [0.5, 0.0, 0.0], "points": 2000},
           {"label": "pan", "frames": 6, "camera": "pan", "angle": 3.0, "points": 2000},
           {"label": "orbit", "frames": 6, "camera": "orbit", "angle": 3.0, "points": 2000}]
MOTION_SCENES = 2


def scene_tables(cfg: dict, base: Path) -> list:
    """The config's [[scene]] tables, a list of translates expanded, files absolute; a missing optional
    file left out."""
    out = []
    for t in cfg["scene"]:
        t = dict(t)
        if "file" in t:
            t["file"] = str((base / t["file"]).resolve())
            if t.pop("optional", False) and not Path(t["file"]).exists():
                print(f"skipped (optional, absent): {t['file']}")
                continue
        moves = t.pop("translate", None)
        if moves and isinstance(moves[0], list):
            out += [{**t, "translate": m} for m in moves]
        else:
            out.append(t if moves is None else {**t, "translate": moves})
    return out


def label(t: dict) -> str:
    """A scene table's short name: the built-in or the file's stem, and where it was moved."""
    name = t.get("builtin") or Path(t["file"]).stem
    far = [c for c in t.get("translate", []) if c]
    return name + (f" at {max(abs(c) for c in far):.0e}" if far else "")


def run(cfg: dict, out: Path) -> tuple:
    """(metrics.csv rows, run.json) of one dsm.run."""
    dsm.run(cfg, out=out, force=True)
    return list(csv.DictReader(open(out / "metrics.csv"))), json.loads((out / "run.json").read_text())


def map_rays(doc: dict) -> dict:
    """{resolution: (rays, build ms)} of a run's maps (one scene, one light)."""
    return {m["resolution"]: (sum(m["rays"].values()), m["build_ms"]) for m in doc["maps"]}


def cascade_cfg(cfg: dict, scene: dict, resolutions: list, name: str) -> dict:
    """The config with 4 cascades of each resolution in place of the virtual map."""
    mp = {k: v for k, v in cfg["map"].items() if k != "virtual"}
    mp.update({"resolution": sorted(set(resolutions)), "cascades": CASCADES})
    return {**cfg, "experiment": {"name": name}, "scene": [scene], "map": mp}


def rows_of(rows: list, budget: str, preset: str, rays: dict, texels: int, target_texels, target_rays) -> list:
    """The comparison rows of one run's cases: the kept columns plus budget, preset, rays, build time, gaps."""
    out = []
    for r in rows:
        res = int(r["resolution"])
        n_rays, build = rays[res]
        mem = int(r["vsm_memory_texels"]) if r["vsm_memory_texels"] else CASCADES * res * res
        out.append({"budget": budget, "preset": preset, **{k: r[k] for k in KEEP}, "memory_texels": mem,
                    "rays": n_rays, "build_ms": f"{build:.1f}",
                    "memory_gap": f"{(mem - target_texels) / target_texels:.5f}",
                    "rays_gap": f"{(n_rays - target_rays) / target_rays:.5f}"})
    return out


def compare_scene(cfg: dict, scene: dict, i: int, out: Path) -> list:
    """Every row of one scene: the virtual presets, then the cascades at each preset's two budgets."""
    vrows, vdoc = run({**cfg, "experiment": {"name": f"vsm-{i}"}, "scene": [scene]}, out / f"{i}-virtual")
    vrays = map_rays(vdoc)
    presets = {r["cascade_layout"].split()[1]: r for r in vrows}
    budget = {p: (int(r["vsm_memory_texels"]), int(r["vsm_rays"])) for p, r in presets.items()}
    rows = []
    for p, r in presets.items():
        rows += rows_of([x for x in vrows if x["cascade_layout"] == r["cascade_layout"]], "virtual", p, vrays,
                        0, *budget[p])
    mem_res = {p: cascade_resolution(m, CASCADES) for p, (m, _) in budget.items()}
    crows, cdoc = run(cascade_cfg(cfg, scene, list(mem_res.values()), f"cascades-mem-{i}"), out / f"{i}-memory")
    crays = map_rays(cdoc)
    per_texel = {p: crays[R][0] / (CASCADES * R * R) for p, R in mem_res.items()}
    ray_res = {p: cascade_resolution(budget[p][1] / per_texel[p], CASCADES) for p in budget}
    rrows, rdoc = run(cascade_cfg(cfg, scene, list(ray_res.values()), f"cascades-rays-{i}"), out / f"{i}-rays")
    rrays = map_rays(rdoc)
    for p, (m, n) in budget.items():
        rows += rows_of([x for x in crows if int(x["resolution"]) == mem_res[p]], "equal memory", p, crays, 0, m, n)
        rows += rows_of([x for x in rrows if int(x["resolution"]) == ray_res[p]], "equal rays", p, rrays, 0, m, n)
        print(f"{label(scene)} {p}: {m} texels -> R {mem_res[p]} (gap {budget_gap(mem_res[p], CASCADES, m):+.4%}); "
              f"{n} rays -> R {ray_res[p]}")
    return [{"scene_label": label(scene), **r} for r in rows], mem_res


def flicker_scene(cfg: dict, scene: dict, i: int, mem_res: dict, out: Path) -> list:
    """Flicker rows of one scene under each motion: the virtual presets and the cascades at equal memory."""
    still = {k: v for k, v in cfg.items() if k != "scheme"}
    schemes = [s for s in cfg["scheme"] if s.get("name") == "normal_offset"]   # one scheme: the flicker's cost
    virt = {**still, "experiment": {"name": f"vsm-motion-{i}"}, "scene": [scene], "scheme": schemes,
            "motion": MOTIONS}
    casc = {**cascade_cfg(still, scene, list(mem_res.values()), f"cascades-motion-{i}"), "scheme": schemes,
            "motion": MOTIONS}
    rows = []
    for kind, c in (("virtual", virt), ("cascades", casc)):
        got, _ = run(c, out / f"{i}-motion-{kind}")
        for r in got:
            if r["motion"]:
                lay = r["cascade_layout"]
                name = lay if kind == "virtual" else f"4 cascades {lay}".strip()
                rows.append({"scene_label": label(scene), "map": name, **{k: r[k] for k in FLICKER}})
    return rows


def write(path: Path, rows: list):
    """A CSV of dict rows (every value as the run wrote it)."""
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def machine() -> dict:
    """Where and from what the files were made."""
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    cpu = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), "?") \
        if Path("/proc/cpuinfo").exists() else platform.processor()
    import mitsuba
    import drjit
    return {"commit": commit, "machine": f"{platform.system()} {platform.machine()}, {cpu}",
            "variant": "llvm_ad_rgb", "mitsuba": mitsuba.__version__, "drjit": drjit.__version__,
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}


def main():
    """Run the comparison and write docs/vsm_vs_cascades/{comparison,flicker}.csv and machine.json."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--config", default=str(ROOT / "experiments" / "vsm_vs_cascades.toml"))
    ap.add_argument("--out", default=str(ROOT / "runs" / "vsm_vs_cascades"))
    ap.add_argument("--docs", default=str(ROOT / "docs" / "vsm_vs_cascades"))
    a = ap.parse_args()
    path = Path(a.config)
    cfg = tomllib.loads(path.read_text())
    out, docs = Path(a.out), Path(a.docs)
    out.mkdir(parents=True, exist_ok=True)
    docs.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows, flicker = [], []
    for i, scene in enumerate(scene_tables(cfg, path.parent)):
        got, mem_res = compare_scene(cfg, scene, i, out)
        rows += got
        if i < MOTION_SCENES:
            flicker += flicker_scene(cfg, scene, i, mem_res, out)
    write(docs / "comparison.csv", rows)
    write(docs / "flicker.csv", flicker)
    info = {**machine(), "config": str(path.relative_to(ROOT) if path.is_relative_to(ROOT) else path),
            "wall_s": round(time.perf_counter() - t0, 1)}
    (docs / "machine.json").write_text(json.dumps(info, indent=1) + "\n")
    print(f"wrote {docs}/comparison.csv, flicker.csv, machine.json in {info['wall_s']} s")


if __name__ == "__main__":
    main()
