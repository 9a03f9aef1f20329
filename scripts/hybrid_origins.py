#!/usr/bin/env python3
"""The hybrid origin rules' false shadow and leaking across scene scales 1e-3 to 1e6
(dsm.hybrid.origin_study): writes the CSV (default docs/hybrid/origins.csv) and prints its table.

    .venv/bin/python scripts/hybrid_origins.py [OUT.csv] [--resolution 160]
"""
import argparse
import csv
from pathlib import Path

from dsm.core import env


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(Path(__file__).resolve().parent.parent / "docs/hybrid/origins.csv"))
    ap.add_argument("--resolution", type=int, default=160, help="camera pixels a side")
    args = ap.parse_args()
    env.use_variant(None)
    from dsm.hybrid import origin_study
    rows = origin_study.table(resolution=args.resolution)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=origin_study.COLUMNS, lineterminator="\n")
        w.writeheader()
        w.writerows({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()} for r in rows)
    print("\n".join(origin_study.markdown(rows)))


if __name__ == "__main__":
    main()
