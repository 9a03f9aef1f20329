"""Virtual maps of spot and point lights against one ordinary map at equal memory (docs/vsm_vs_cascades.md,
*Spot and point lights*): runs experiments/vsm_punctual.toml (EEVEE's punctual virtual maps), then the same
scenes and lights with one perspective map (spot) and one cube map (point light) at the resolution R whose
bytes (faces x R^2 x 4: float32 z1, the schemes read one layer) are nearest the virtual map's map_bytes +
page_table_bytes, and writes one row per scene, light, scheme and map to docs/vsm_vs_cascades/punctual.csv.

    .venv/bin/python scripts/vsm_punctual.py [--config experiments/vsm_punctual.toml] [--out runs/vsm_punctual]
        [--docs docs/vsm_vs_cascades]
"""
import argparse
import csv
import math
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import dsm  # noqa: E402

KEEP = ("scene", "light", "view", "scheme", "params", "resolution", "n_receivers", "acne_rate", "peterpan_rate",
        "error_rate", "map_bytes", "page_table_bytes", "vsm_pages_built", "map_rays", "texels_per_pixel")
FACES = {"perspective": 1, "cube": 6}


def equal_resolution(total_bytes: int, faces: int) -> int:
    """The R whose faces x R^2 float32 texels are nearest ``total_bytes``."""
    r = math.sqrt(total_bytes / (4 * faces))
    lo = max(1, math.floor(r))
    return min((lo, lo + 1), key=lambda k: abs(faces * k * k * 4 - total_bytes))


def rows(config: dict, out: Path) -> list:
    """metrics.csv's rows of ``config`` run into ``out``, as dicts."""
    dsm.run(config, out=out, force=True)
    with open(out / "metrics.csv", newline="") as f:
        return list(csv.DictReader(f))


def main() -> None:
    """Both halves, the pairing by scene, light and scheme, punctual.csv."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "experiments" / "vsm_punctual.toml"))
    ap.add_argument("--out", default=str(ROOT / "runs" / "vsm_punctual"))
    ap.add_argument("--docs", default=str(ROOT / "docs" / "vsm_vs_cascades"))
    a = ap.parse_args()
    cfg = tomllib.loads(Path(a.config).read_text())
    virtual = rows(cfg, Path(a.out) / "virtual")
    want = {}
    for r in virtual:
        if int(r["n_receivers"]) > 0:
            want[(r["scene"], r["light"])] = equal_resolution(int(r["map_bytes"]) + int(r["page_table_bytes"]),
                                                              FACES[r["view"]])
    plain = dict(cfg, map={k: v for k, v in cfg["map"].items() if k != "virtual"})
    plain["map"]["resolution"] = sorted(set(want.values()))
    single = rows(plain, Path(a.out) / "single")
    out = [dict({k: r[k] for k in KEEP}, map="virtual") for r in virtual if (r["scene"], r["light"]) in want]
    out += [dict({k: r[k] for k in KEEP}, map="single") for r in single
            if want.get((r["scene"], r["light"])) == int(r["resolution"])]
    Path(a.docs).mkdir(parents=True, exist_ok=True)
    with open(Path(a.docs) / "punctual.csv", "w", newline="") as f:
        w = csv.DictWriter(f, ("map",) + KEEP)
        w.writeheader()
        w.writerows(out)
    print(f"{len(out)} rows -> {Path(a.docs) / 'punctual.csv'}")


if __name__ == "__main__":
    main()
