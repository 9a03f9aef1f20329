"""``dsm benchmark``: run the suite (or compare two results, or rebuild the page) and write
results.json, leaderboard.html, scale.png, the contender pages and the case images.

Exit status as ``dsm run``'s: 0 done, 2 a user's mistake (a flag, a file, a folder), 3 a missing
set-up (a variant this machine cannot run, Ray's client), 130 interrupted (its finished cases
kept: ``--resume`` goes on).
"""
from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

from ..config.read import VARIANTS
from ..experiment import lock
from . import case_images, caselog, compare, contenders, costs, document, page, results
from .suite import LATEST, SUITE_FILES

SIZE_ENV = "DSM_BENCHMARK_SIZE"     # a hidden size for tests: DSM_BENCHMARK_SIZE=test
# what a run writes into --out: --force removes these (and nothing else a user keeps there)
WRITTEN = ("results.json", "leaderboard.html", "frontier.csv", "scale.png", "flicker", caselog.FOLDER, case_images.FOLDER,
           contenders.FOLDER)


def add_parser(sub):
    """Add the ``benchmark`` subcommand to an argparse subparsers object."""
    b = sub.add_parser("benchmark", help=f"run the frozen shadow-bias suite ({LATEST}): results.json and a "
                       "leaderboard page; or compare two results")
    b.add_argument("--out", default=None, help="folder for results.json and leaderboard.html (default: benchmark/)")
    b.add_argument("--full", action="store_true", help="the full size (larger resolutions: a GPU or a cluster)")
    b.add_argument("--compare", nargs=2, metavar=("A.json", "B.json"), help="compare two results.json files")
    b.add_argument("--page", metavar="DIR", help="rebuild leaderboard.html, scale.png and the contender pages in DIR "
                   "from its results.json")
    b.add_argument("--suite", choices=list(SUITE_FILES), default=None,
                   help=f"the suite's version (default: the newest, {LATEST}); an older one re-runs its cases")
    b.add_argument("--variant", choices=VARIANTS, help="Mitsuba variant (default llvm_ad_rgb)")
    b.add_argument("--force", action="store_true", help="replace everything a previous run left in --out")
    b.add_argument("--resume", action="store_true", help="go on with the run interrupted in --out (its finished "
                   "cases kept)")
    b.add_argument("--cluster", metavar="ADDRESS",
                   help="run each case's map groups as Ray tasks on the cluster at ADDRESS (auto, ray://host:port) "
                        "or on a Ray instance started here (local); needs pip install 'dsm[cluster]'")
    return b


def _err(msg: str) -> int:
    print(f"dsm benchmark: {msg}", file=sys.stderr)
    return 2


def flag_problem(args) -> str | None:
    """The first flag that cannot be used as given, in one line; None when they can."""
    if str(args.out) == "":
        return "--out is empty: give a folder"
    if args.cluster is not None and not args.cluster.strip():
        return "--cluster is empty: give local, auto or a Ray address host:port"
    run_flags = [f for f, on in (("--full", args.full), ("--suite", args.suite is not None),
                                 ("--cluster", args.cluster is not None), ("--variant", args.variant is not None),
                                 ("--resume", args.resume)) if on]
    for mode, on in (("--compare", args.compare), ("--page", args.page)):
        if on and run_flags:
            return f"{mode} runs no case: {run_flags[0]} does not apply to it"
    if args.compare and args.page:
        return "--compare and --page are two commands: give one"
    if args.page and args.out is not None:
        return f"--page rewrites the page in its own folder ({args.page}): --out does not apply to it"
    if args.page and args.force:
        return "--page rewrites only the page: --force does not apply to it"
    if args.resume and args.force:
        return "--resume goes on with a run and --force replaces it: give one"
    return None


def main(args) -> int:
    """Run ``dsm benchmark`` from its parsed arguments; returns the exit status."""
    problem = flag_problem(args)
    if problem:
        return _err(problem)
    if args.page:
        return _page(Path(args.page))
    out = Path(args.out if args.out is not None else "benchmark")
    if out.exists() and not out.is_dir():
        return _err(f"--out {out}: is a file, not a folder; choose another --out")
    if args.compare:
        problem = foreign_problem(out)          # its two files never land among another command's either
        return _err(problem) if problem else _held(out, lambda: _compare(args, out))
    problem = folder_problem(out, args.force, args.resume)
    if problem:
        return _err(problem)
    if args.variant:                 # a variant this machine cannot run: one line before any work
        from ..core import env
        try:
            env.use_variant(args.variant)
        except env.SetupError as e:
            print(f"dsm benchmark: setup error: {e}", file=sys.stderr)
            return 3
    if args.cluster:                   # reach the cluster before the folder is touched
        problem = _connect(args.cluster)
        if problem is not None:
            return problem
    return _held(out, lambda: _run(args, out))


def _connect(address: str) -> int | None:
    """Join (or start) the Ray cluster; the exit status of a failure (2: the address, 3: Ray's set-up), else None."""
    from ..core.env import SetupError
    from ..core.types import ConfigError
    from ..experiment import cluster
    try:
        cluster.connect(address)
    except SetupError as e:
        print(f"dsm benchmark: setup error: {e}", file=sys.stderr)
        return 3
    except ConfigError as e:
        return _err(str(e).removeprefix(f"{e.source}: "))
    return None


def folder_problem(out: Path, force: bool, resume: bool) -> str | None:
    """Why a run may not write into ``out`` as asked (in one line), None when it may."""
    foreign = foreign_problem(out)
    if foreign:
        return foreign
    done = (out / "results.json").exists()
    partial = caselog.progress(out)
    if resume:
        if done:
            return (f"--out {out}: its run is complete (results.json); --page {out} rebuilds the page, --force "
                    "runs it again")
        if partial is None:
            return f"--out {out}: holds no interrupted run to resume; run without --resume"
        return None
    if force:
        return None
    if done:
        return f"--out {out}: holds results.json of an earlier run; give another --out, or --force to replace it"
    if partial is not None:
        return (f"--out {out}: holds an interrupted run ({partial[0]} of {partial[1]} cases finished); --resume "
                "goes on with it, --force starts again")
    return None


def foreign_problem(out: Path) -> str | None:
    """Why ``out`` is not the benchmark's to write into (another command's or a user's files), None
    when it is empty or a benchmark's own: its files never mix with others', --force or not."""
    held = sorted(p.name for p in lock.entries(out) or [])
    if (out / "run.json").is_file() or (out / "metrics.csv").is_file():
        return f"--out {out}: holds a dsm run (run.json, metrics.csv), not a dsm benchmark; choose another --out"
    if held and not any(name in held for name in WRITTEN + ("compare.json", "compare.txt")):   # --compare's too
        more = ", ..." if len(held) > 3 else ""
        return (f"--out {out}: holds files that are not a dsm benchmark's ({', '.join(held[:3])}{more}); "
                "choose another --out (an empty folder or a benchmark's)")
    return None


def _held(out: Path, fn) -> int:
    """``fn()`` holding the folder's lock (one writer per folder, as dsm run)."""
    try:
        held = lock.acquire(out)
    except (lock.Busy, OSError) as e:
        return _err(f"--out {e}")
    with held:
        return fn()


def _compare(args, out: Path) -> int:
    try:
        a, b = (document.read(p) for p in args.compare)
    except document.NotResults as e:
        return _err(f"--compare {e}")
    diff = compare.compare(a, b)
    print(compare.text(diff))
    print(f"dsm benchmark: wrote {compare.write(diff, out)}")
    return 0


def _page(folder: Path) -> int:
    """leaderboard.html, scale.png and the contender pages rebuilt from ``folder``'s results.json alone."""
    try:
        doc = document.read(folder / "results.json")
    except document.NotResults as e:
        return _err(f"--page {e}")
    missing = [k for k in ("suite_sha256", "size", "dsm_version", "versions", "variant", "machine") if k not in doc]
    if missing:
        return _err(f"--page {folder / 'results.json'}: has no {missing[0]} (the page states it)")
    costs.write_frontier(doc, folder)
    print(f"dsm benchmark: wrote {page.write_page(doc, folder)}")
    return 0


def _run(args, out: Path) -> int:
    size = "full" if args.full else os.environ.get(SIZE_ENV, "default")
    if args.force:
        _clear(out)
    try:
        doc = results.run_suite(size, args.variant, progress=lambda m: print(m, file=sys.stderr),
                                version=args.suite or LATEST, out=out, cluster=args.cluster, resume=args.resume)
    except caselog.Mismatch as e:
        return _err(f"--out {out}: cannot resume: {e}; --force starts again")
    except KeyboardInterrupt:
        kept = caselog.progress(out)
        n = f"{kept[0]} of {kept[1]} cases" if kept else "no case"
        print(f"dsm benchmark: interrupted; {n} finished and kept in {out / caselog.FOLDER}/: "
              f"dsm benchmark --out {out} --resume goes on", file=sys.stderr)
        return 130
    written = results.write(doc, out)
    caselog.clear(out)
    for line in costs.answer_lines(doc):     # what accuracy costs: the leaderboard's headline, the same words
        print(f"dsm benchmark: {line}")
    try:
        costs.write_frontier(doc, out)
        print(f"dsm benchmark: wrote {written} and {page.write_page(doc, out)}")
    except KeyboardInterrupt:
        print(f"dsm benchmark: interrupted while writing the page; {written} is whole: dsm benchmark --page {out} "
              "rebuilds the page", file=sys.stderr)
        return 130
    return 0


def _clear(out: Path):
    """--force: everything an earlier run wrote into ``out`` removed (its results, page, figure,
    flicker runs, finished cases, case images and contender pages), so no stale file sits beside the new results."""
    for name in WRITTEN:
        path = out / name
        if path.is_dir():
            shutil.rmtree(path)
        elif path.exists():
            path.unlink()
