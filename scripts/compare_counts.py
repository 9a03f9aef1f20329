#!/usr/bin/env python3
"""Compare two runs' metrics.csv case by case: how many cases have identical counts, and the
largest difference in acne, peter-panning or receivers as a share of the case's receivers, per
scheme. Used for cuda_ad_rgb against llvm_ad_rgb on the same config (docs/bench/cuda-h100/).

    scripts/compare_counts.py A/metrics.csv B/metrics.csv [--show 10]
"""
import argparse
import csv
import sys
from collections import defaultdict

COUNTS = ("n_receivers", "n_acne", "n_peterpan")
COLUMNS = ("case", "scene", "light", "view", "resolution", "scheme", "params")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--show", type=int, default=10, help="the cases that differ most (default 10)")
    args = ap.parse_args(argv)
    try:
        with open(args.a, newline="") as fa, open(args.b, newline="") as fb:
            a, b = list(csv.DictReader(fa)), list(csv.DictReader(fb))
        missing = [f"{path}: {k}" for path, rows in ((args.a, a), (args.b, b)) for k in COLUMNS + COUNTS
                   if rows and k not in rows[0]]
        if not missing:
            for r in a + b:
                for k in COUNTS:
                    int(r[k])
    except (OSError, UnicodeDecodeError, csv.Error, ValueError) as exc:
        print(f"compare_counts: {exc}", file=sys.stderr)
        return 2
    if missing or not a or not b:
        print("compare_counts: not a dsm metrics.csv (missing columns: "
              f"{', '.join(missing) or 'no rows'})", file=sys.stderr)
        return 2
    if [r["case"] for r in a] != [r["case"] for r in b]:
        print("compare_counts: the two runs do not have the same cases", file=sys.stderr)
        return 2
    rows, per = [], defaultdict(list)
    for x, y in zip(a, b):
        share = max(abs(int(y[k]) - int(x[k])) for k in COUNTS) / max(int(x["n_receivers"]), 1)
        rows.append((share, x))
        per[(x["scheme"])].append(share)
    same = sum(1 for s, _ in rows if s == 0)
    print(f"{len(rows)} cases: {same} with identical counts; largest difference "
          f"{100 * max(s for s, _ in rows):.3f} % of a case's receivers\n")
    print("| scheme | cases | identical | largest difference (% of receivers) |\n|---|---|---|---|")
    for name, v in per.items():
        print(f"| {name} | {len(v)} | {sum(1 for s in v if s == 0)} | {100 * max(v):.3f} |")
    print("\nlargest differences (acne a/b, peter-panning a/b):")
    rows.sort(key=lambda t: -t[0])
    by_case = {r["case"]: r for r in b}
    for share, x in rows[:args.show]:
        y = by_case[x["case"]]
        print(f"  {100 * share:.3f} %  {x['scene']} {x['light']} {x['view']} R={x['resolution']} {x['scheme']} "
              f"{x['params']}: acne {x['n_acne']}/{y['n_acne']}, peter-panning {x['n_peterpan']}/{y['n_peterpan']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
