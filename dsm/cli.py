"""Command line: ``dsm run``, ``dsm plan``, ``dsm schemes``, ``dsm bench``."""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

from . import config as cfgmod
from .env import SetupError

DEFAULT_CONFIG = Path(__file__).with_name("default.toml")


def _parser():
    ap = argparse.ArgumentParser(prog="dsm", description="Measure shadow-map bias schemes against exact visibility.")
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run an experiment config (default: the built-in default experiment)")
    r.add_argument("config", nargs="?", help="experiment TOML file")
    r.add_argument("--out", help="results folder (default: runs/<name>-<time>)")
    r.add_argument("--variant", choices=cfgmod.VARIANTS, help="Mitsuba variant (default llvm_ad_rgb)")
    r.add_argument("--threads", type=int, help="Dr.Jit worker threads")
    r.add_argument("--force", action="store_true", help="write into a non-empty --out folder")
    p = sub.add_parser("plan", help="print what a config will compute: cases, maps, rays by kind, memory")
    p.add_argument("config", nargs="?", help="experiment TOML file (default: the built-in default experiment)")
    sub.add_parser("schemes", help="list bias schemes, their parameters, defaults and sources")
    b = sub.add_parser("bench", help="benchmark: map build against a bare ray cast, lookup cost per scheme")
    b.add_argument("--out", default="bench", help="folder for bench.md and bench.json (default: bench/)")
    b.add_argument("--resolutions", default="256,512,1024,2048,4096", help="comma-separated map resolutions")
    b.add_argument("--repeats", type=int, default=5)
    b.add_argument("--meshes", help="folder of the real test meshes (default: ../shared/meshes)")
    b.add_argument("--variant", choices=cfgmod.VARIANTS)
    return ap


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    if args.cmd == "schemes":
        print(schemes_text())
        return 0
    if args.cmd == "bench":
        from .bench import run_bench
        try:
            res = [int(x) for x in args.resolutions.split(",")]
            run_bench(Path(args.out), res, args.repeats, args.meshes, args.variant)
        except SetupError as e:
            print(f"dsm: setup error: {e}", file=sys.stderr)
            return 3
        except ValueError:
            print(f"dsm: --resolutions: expected integers like 256,1024, got {args.resolutions!r}", file=sys.stderr)
            return 2
        print((Path(args.out) / "bench.md").read_text())
        return 0
    try:
        cfg = cfgmod.load(args.config or DEFAULT_CONFIG)
    except cfgmod.ConfigError as e:
        print(f"dsm: config error: {e}", file=sys.stderr)
        return 2
    if args.cmd == "plan":
        from .plan import make
        print(make(cfg).text())
        return 0
    out = Path(args.out) if args.out else Path("runs") / f"{cfg.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    if out.exists() and any(out.iterdir()) and not args.force:
        print(f"dsm: {out} is not empty; choose another --out or pass --force", file=sys.stderr)
        return 2
    try:
        from . import env
        env.use_variant(args.variant or cfg.variant, args.threads)
        from .runner import Runner
        t0 = time.perf_counter()
        res = Runner(cfg, out, args.variant, progress=True).run()
    except SetupError as e:
        print(f"dsm: setup error: {e}", file=sys.stderr)
        return 3
    failed = res.run["n_failed"]
    print(f"dsm: {len(res.rows)} cases in {time.perf_counter() - t0:.1f} s, {failed} failed -> {out}/"
          f" (table.md, metrics.csv, images/, plots/, run.json)")
    return 1 if failed and not res.rows else 0


def schemes_text() -> str:
    from .schemes import PRESETS, REGISTRY
    lines = []
    for s in REGISTRY:
        needs = ", ".join(sorted(s.NEEDS)) or "first layer only"
        lines.append(f"{s.NAME}  [{s.SOURCE}]  needs: {needs}")
        for f in dataclasses.fields(s.Params):
            lines.append(f"    {f.name} = {f.default}    {f.metadata.get('doc', '')}")
        lines.append("    " + (s.__doc__ or "").strip().splitlines()[0])
    lines.append("presets: " + ", ".join(f"{k} -> {v[0]}" for k, v in PRESETS.items()))
    lines.append('lengths: a number (world units), "k texel" (texel widths at the receiver) or "k range" '
                 "(fraction of the view's depth range)")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
