"""The leaderboard table of docs/benchmark.md from a dsm benchmark results.json: the top ranks (rank <= TOP),
every engine preset and every hybrid contender (its ray fraction beside the error; a dash for a map alone), each
contender's notes as the page gives them, then the oracles' floor.

    .venv/bin/python scripts/leaderboard_table.py bench4/results.json
"""
import sys

from dsm.benchmark import document, ranking
from dsm.schemes.presets import PRESETS

TOP = 12


def cell(v, signed=False) -> str:
    """A number as docs/benchmark.md writes it: 4 decimals ('-' for none)."""
    if v is None or v != v:
        return "-"
    return f"{v:+.4f}" if signed else f"{v:.4f}"


def notes(doc: dict, ranked: list) -> dict:
    """Contender -> its notes: best pre-filtered, best tuned, best preset, most scale-robust preset, a world depth bias."""
    out = {}
    add = lambda name, note: out.setdefault(name, []).append(note)
    best = lambda pool: min(pool, key=lambda r: (r["error"], r["contender"]))["contender"] if pool else None
    for name, note in ((best([r for r in ranked if r.get("leak") is not None]), "best pre-filtered"),
                       (best([r for r in ranked if r["contender"] in doc.get("tuned", {})]), "best tuned"),
                       (best([r for r in ranked if r["contender"] in PRESETS]), "best preset")):
        if name:
            add(name, note)
    robust = ranking.most_scale_robust(ranked, among=set(PRESETS))
    if robust:
        add(robust["contender"], "most scale-robust preset")
    return out


def main(path):
    """Print the Markdown table."""
    doc = document.read(path)
    ranked = ranking.ranking(doc)
    far = list(ranked[0]["far"])[1:] if ranked else []
    tags = notes(doc, ranked)
    print("| rank | contender | error rate | ray fraction | acne rate | peter-pan rate | spread over cm/m/km | FLIP | "
          "leak rate | flicker | " + " | ".join(f"error at {o}" for o in far) + f" | change to {far[-1]} |")
    print("| --- " * (12 + len(far) - 1) + "|")
    for r in ranked:
        hybrid = r.get("ray_fraction") is not None
        if r["rank"] > TOP and r["contender"] not in PRESETS and not hybrid:
            continue
        name = r["contender"] + (f" ({', '.join(tags[r['contender']])})" if r["contender"] in tags else "")
        rays = cell(r["ray_fraction"]) if hybrid else "\u2014"
        print(f"| {r['rank']} | {name} | {cell(r['error'])} | {rays} | {cell(r['acne'])} | {cell(r['peterpan'])} | "
              f"{cell(r['spread'])} | {cell(r['flip'])} | {cell(r.get('leak'))} | {cell(r.get('flicker'))} | "
              + " | ".join(cell(r["far"][o]) for o in far) + f" | {cell(r['far_change'], True)} |")
    floor = ranking.oracle_floor(doc)
    print(f"| | oracle floor: per-texel / one world bias / one texel bias | {floor['per_texel_objective']:.5f} / "
          f"{floor['world_objective']:.4f} / {floor['texel_objective']:.4f} |" + " |" * (9 + len(far)))


if __name__ == "__main__":
    main(sys.argv[1])
