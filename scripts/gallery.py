"""Regenerate docs/gallery/ from the default experiment and experiments/engine_defaults.toml:
the README's tables (the default experiment; engine defaults against the best possible) and
error images.

    .venv/bin/python scripts/gallery.py [results folder of a default run]
"""
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

import dsm
from dsm.cli import DEFAULT_CONFIG
from dsm.metrics import CLASS_COLORS, CLASS_NAMES

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "docs" / "gallery"


def main():
    res = dsm.run(DEFAULT_CONFIG, out=sys.argv[1] if len(sys.argv) > 1 else None)
    OUT.mkdir(parents=True, exist_ok=True)
    # the table: mean (max) over every case of each scheme instance
    groups = defaultdict(list)
    for r in res.rows:
        groups[(r["scheme"], r["preset"] or r["params"])].append(r)
    # undefined rates (an empty denominator: no lit or no shadowed receiver) are left out, and counted
    lines = ["| scheme | params | cases | acne rate, mean (max) [cases] | peter-panning rate, mean (max) [cases] | "
             "build ms | lookup ms |", "|---|---|---|---|---|---|---|"]

    def cell(values):
        v = np.array(values, float)
        v = v[~np.isnan(v)]
        return f"{v.mean():.4f} ({v.max():.3f}) [{v.size}]" if v.size else "-"
    for (scheme, params), rs in groups.items():
        lines.append(f"| {scheme} | {params} | {len(rs)} | {cell([r['acne_rate'] for r in rs])} | "
                     f"{cell([r['peterpan_rate'] for r in rs])} | "
                     f"{np.median([r['build_ms'] for r in rs]):.1f} | {np.median([r['lookup_ms'] for r in rs]):.2f} |")
    (OUT / "default_table.md").write_text("\n".join(lines) + "\n")
    # the images: the room's own point light, cube view, R = 512, four schemes
    pick = [("none", ""), ("constant", "bias=2 texel"), ("normal_offset", "offset=1.5 texel bias=0"), ("adaptive", "K=0.0001")]
    fig = Figure(figsize=(13, 3.9))
    axes = fig.subplots(1, len(pick))
    for ax, (scheme, params) in zip(axes, pick):
        r = res.where(scene="room", light="0:point", view="cube", resolution=512, scheme=scheme, params=params).rows[0]
        ax.imshow(res.rgb(r))
        ax.set_title(f"{scheme} {params}\nacne {r['acne_rate']:.3f}, peter-panning {r['peterpan_rate']:.3f}", fontsize=9)
        ax.axis("off")
    from matplotlib.patches import Patch
    fig.legend(handles=[Patch(color=c / 255, label=n) for c, n in zip(CLASS_COLORS, CLASS_NAMES)], loc="lower center",
               ncol=5, fontsize=9, frameon=False)
    fig.subplots_adjust(left=0.01, right=0.99, top=0.86, bottom=0.09, wspace=0.04)
    fig.savefig(OUT / "room_point_cube_errors.png", dpi=80)
    print(f"{res.run['n_empty']} empty cases, {res.run['n_failed']} failed")
    print((OUT / "default_table.md").read_text())


def engine_defaults():
    """Every engine preset on the default experiment's cases beside the exact oracles of the
    same maps: objective E = (acne + peter-panning) / receivers (lambda 1, nearest)."""
    res = dsm.run(ROOT / "experiments" / "engine_defaults.toml")
    maps = {}
    for o in res.oracle:
        if o["lambda"] == 1.0 and o["format"] == "float32":
            maps[(o["scene"], o["light"], o["view"], o["resolution"], o["culling"])] = o
    key = lambda r: (r["scene"], r["light"], r["view"], r["resolution"], r["culling"])
    groups = defaultdict(list)
    for r in res.rows:
        if r["n_receivers"] and key(r) in maps:
            groups[r["preset"] or f"{r['scheme']} {r['params']}"].append(r)
    oracle_rows = list(maps.values())
    mean = lambda xs: float(np.nanmean(np.array(xs, float))) if xs else float("nan")
    lines = ["| scheme or oracle | cases | objective E, mean | median | acne rate, mean | peter-panning rate, mean | "
             "E above the world oracle, mean | cases at or below the world oracle |", "|---|---|---|---|---|---|---|---|"]
    for tag, name in (("per_texel", "oracle: best bias per texel (the resolution's share)"),
                      ("world", "oracle: best constant world bias per map"),
                      ("texel", "oracle: best constant texel bias per map")):
        e = [o[f"{tag}_objective"] for o in oracle_rows]
        lines.append(f"| {name} | {len(e)} | {mean(e):.4f} | {np.nanmedian(e):.4f} | "
                     f"{mean([o[f'{tag}_acne_rate'] for o in oracle_rows]):.4f} | "
                     f"{mean([o[f'{tag}_peterpan_rate'] for o in oracle_rows]):.4f} | | |")
    for name, rs in sorted(groups.items(), key=lambda kv: mean([r["error_rate"] for r in kv[1]])):
        e = [r["error_rate"] for r in rs]
        w = [maps[key(r)]["world_objective"] for r in rs]
        below = sum(1 for a, b in zip(e, w) if a <= b)
        lines.append(f"| {name} | {len(rs)} | {mean(e):.4f} | {np.nanmedian(e):.4f} | "
                     f"{mean([r['acne_rate'] for r in rs]):.4f} | {mean([r['peterpan_rate'] for r in rs]):.4f} | "
                     f"{mean([a - b for a, b in zip(e, w)]):+.4f} | {below} |")
    (OUT / "engine_defaults_table.md").write_text("\n".join(lines) + "\n")
    print((OUT / "engine_defaults_table.md").read_text())


if __name__ == "__main__":
    main()
    engine_defaults()
