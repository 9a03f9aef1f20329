"""The table of experiments/prefiltered.toml from a run's metrics.csv (docs/design.md,
"Pre-filtered maps"): per scene and kernel width K, PCF (pcf_wide:K, nearest for K = 1) with
its best constant bias against each pre-filtered kind blurred K x K.

    python scripts/prefiltered_table.py runs/prefiltered-<time>/metrics.csv
"""
import csv
import sys


def width(row) -> int:
    """The kernel width of a case: K of pcf_wide:K or box:K, 1 for nearest."""
    f = row["filter"]
    return int(f.split(":")[1]) if ":" in f else 1


def num(x) -> float:
    """A metrics.csv cell as a number (an empty cell: NaN)."""
    return float(x) if x != "" else float("nan")


def main(path):
    """Print the Markdown table."""
    rows = list(csv.DictReader(open(path)))
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    kinds = list(dict.fromkeys(r["map_kind"] for r in rows if r["map_kind"] != "depth"))
    print("| scene | K | PCF best bias: error (leak) | " + " | ".join(f"{k}: error (leak) mae" for k in kinds)
          + " | PCF lookup ms | " + " | ".join(f"{k} moments + lookup ms" for k in kinds) + " |")
    print("|---" * (3 + 2 * len(kinds) + 1) + "|")
    for s in scenes:
        for K in sorted({width(r) for r in rows if r["scene"] == s}):
            depth = [r for r in rows if r["scene"] == s and r["map_kind"] == "depth" and width(r) == K]
            best = min(depth, key=lambda r: num(r["error_rate"]))
            cells = [s, str(K), f"{num(best['error_rate']):.4f} ({best['n_leak']}) at {best['params'].split('=')[1]}"]
            cost = []
            for k in kinds:
                r = next(r for r in rows if r["scene"] == s and r["map_kind"] == k and width(r) == K)
                mark = " *" if num(r["error_rate"]) < num(best["error_rate"]) else ""
                cells.append(f"{num(r['error_rate']):.4f} ({r['n_leak']}) {num(r['mean_abs_error']):.4f}{mark}")
                cost.append(f"{num(r['moments_ms']):.1f} + {num(r['lookup_ms']):.2f}")
            print("| " + " | ".join(cells + [f"{num(best['lookup_ms']):.2f}"] + cost) + " |")


if __name__ == "__main__":
    main(sys.argv[1])
