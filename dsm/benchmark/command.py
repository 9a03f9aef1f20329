"""``dsm benchmark``: run the suite (or compare two results) and write results.json, leaderboard.html and scale.png."""
from __future__ import annotations

import os
import sys
from pathlib import Path

from ..config.read import VARIANTS
from ..experiment import lock
from . import compare, page, results
from .suite import LATEST, SUITE_FILES

SIZE_ENV = "DSM_BENCHMARK_SIZE"     # a hidden size for tests: DSM_BENCHMARK_SIZE=test


def add_parser(sub):
    """Add the ``benchmark`` subcommand to an argparse subparsers object."""
    b = sub.add_parser("benchmark", help=f"run the frozen shadow-bias suite ({LATEST}): results.json and a "
                       "leaderboard page; or compare two results")
    b.add_argument("--out", default="benchmark", help="folder for results.json and leaderboard.html (default: benchmark/)")
    b.add_argument("--full", action="store_true", help="the full size (larger resolutions: a GPU or a cluster)")
    b.add_argument("--compare", nargs=2, metavar=("A.json", "B.json"), help="compare two results.json files")
    b.add_argument("--suite", choices=list(SUITE_FILES), default=LATEST,
                   help=f"the suite's version (default: the newest, {LATEST}); an older one re-runs its cases")
    b.add_argument("--variant", choices=VARIANTS, help="Mitsuba variant (default llvm_ad_rgb)")
    b.add_argument("--force", action="store_true", help="replace the results a previous run left in --out")
    b.add_argument("--cluster", metavar="ADDRESS",
                   help="run each case's map groups as Ray tasks on the cluster at ADDRESS (auto, ray://host:port) "
                        "or on a Ray instance started here (local); needs pip install 'dsm[cluster]'")
    return b


def main(args) -> int:
    """Run ``dsm benchmark`` from its parsed arguments; returns the exit status."""
    out = Path(args.out)
    kept = out / ("compare.json" if args.compare else "results.json")
    if kept.exists() and not args.force:       # a previous run's results are never overwritten silently
        print(f"dsm benchmark: --out {out}: holds {kept.name} of an earlier run; give another --out, or --force "
              "to replace it", file=sys.stderr)
        return 2
    if out.exists() and not out.is_dir():
        print(f"dsm benchmark: --out {out}: is a file, not a folder; choose another --out", file=sys.stderr)
        return 2
    try:
        held = lock.acquire(out)               # one writer per folder, as dsm run
    except (lock.Busy, OSError) as e:
        print(f"dsm benchmark: --out {e}", file=sys.stderr)
        return 2
    with held:
        return _compare(args, out) if args.compare else _run(args, out)


def _compare(args, out: Path) -> int:
    diff = compare.compare(results.read(args.compare[0]), results.read(args.compare[1]))
    print(compare.text(diff))
    print(f"dsm benchmark: wrote {compare.write(diff, out)}")
    return 0


def _run(args, out: Path) -> int:
    size = "full" if args.full else os.environ.get(SIZE_ENV, "default")
    if args.cluster:                   # reach the cluster before any case runs
        from ..experiment import cluster
        from ..core.env import SetupError
        from ..core.types import ConfigError
        try:
            cluster.connect(args.cluster)
        except (SetupError, ConfigError) as e:
            print(f"dsm benchmark: --cluster {args.cluster}: {e}", file=sys.stderr)
            return 3
    doc = results.run_suite(size, args.variant, progress=lambda m: print(m, file=sys.stderr), version=args.suite,
                             out=out, cluster=args.cluster)
    print(f"dsm benchmark: wrote {results.write(doc, out)} and {page.write_page(doc, out)}")
    return 0
