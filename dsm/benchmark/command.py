"""``dsm benchmark``: run the suite (or compare two results, or rebuild the page) and write
results.json, leaderboard.html, scale.png, the contender pages and the case images.

Exit status as ``dsm run``'s: 0 done, 2 a user's mistake (a flag, a file, a folder), 3 a missing
set-up (a variant this machine cannot run, Ray's client), 130 interrupted (its finished cases
kept: ``--resume`` goes on).
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import textwrap
from pathlib import Path

from ..config.read import VARIANTS
from ..experiment import lock
from . import case_images, caselog, compare, contenders, costs, document, page, results
from .suite import LATEST, SIZES, SUITE_FILES, load_suite, size_summary

SIZE_ENV = "DSM_BENCHMARK_SIZE"     # deprecated (the tests' hidden size before --size): an alias that says so
# Wall seconds of a whole run at each size on 2 cores (llvm_ad_rgb, AMD EPYC), by suite version, as (quiet,
# with other jobs beside): the one place --help reads them from. dsm-bench-5:
# - test: quiet 40 s is docs/design.md's for dsm-bench-4's test size (c7ccbee; dsm-bench-5's adds the 2 virtual
#   maps); 69 s (28 CPU s) at a688b50 with load 5 to 6.
# - default: quiet 190 s (224 CPU s) at 31ed51c, docs/bench/benchmark-default/README.md (load 1 to 3); 1355 s
#   (788 CPU s) at a688b50 with load 2 to 7.
# - full: not measured on 2 cores (its 2048^2 maps and 256^2 camera are meant for a GPU or a cluster).
# dsm-bench-6 (quiet None: not measured on a quiet machine; every run shared its 2 cores with other jobs):
# - test: 62 s (30 CPU s) at 12e01d1 with load 5 to 6.
# - default: 2285 s (614 CPU s) at 12e01d1 under nice 10 with load 5 to 15 (docs/benchmark.md).
MEASURED_WALL_S = {"dsm-bench-5": {"test": (40.0, 69.0), "default": (190.0, 1355.0)},
                   "dsm-bench-6": {"test": (None, 62.0), "default": (None, 2285.0)}}
# what a run writes into --out: --force removes these (and nothing else a user keeps there)
WRITTEN = ("results.json", "leaderboard.html", "frontier.csv", "scale.png", "flicker", caselog.FOLDER, case_images.FOLDER,
           contenders.FOLDER)


def add_parser(sub):
    """Add the ``benchmark`` subcommand to an argparse subparsers object."""
    b = sub.add_parser("benchmark", help=f"run the frozen shadow-bias suite ({LATEST}): results.json and a "
                       "leaderboard page; or compare two results", epilog=sizes_text(),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    b.add_argument("--out", default=None, help="folder for results.json and leaderboard.html (default: benchmark/)")
    b.add_argument("--size", choices=SIZES, action=EverySize, help="the suite's cases and resolutions (default: "
                   "default; each size's cases and time below)")
    b.add_argument("--full", action="store_true", help="an alias for --size full (kept for old scripts; says so)")
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


def sizes_text(version: str = LATEST) -> str:
    """The --help lines on the sizes: each one's cases (counted from the suite's definition) and wall time."""
    suite = load_suite(SUITE_FILES[version])
    lines = [f"sizes of {version} (--size), with the wall time of a run on 2 cores:"]
    return "\n".join(lines + [textwrap.fill(f"{size_summary(suite, size)}; {wall_words(version, size)}", 96,
                                            initial_indent=f"  {size:<8}", subsequent_indent=" " * 10)
                              for size in SIZES])


def wall_words(version: str, size: str) -> str:
    """A size's wall time on 2 cores in words, quiet and loaded, as measured (MEASURED_WALL_S), or that it was not
    (quiet or at all)."""
    walls_s = MEASURED_WALL_S.get(version, {}).get(size)
    if walls_s is None:
        return "not measured on 2 cores" + (" (meant for a GPU or a cluster)" if size == "full" else "")
    quiet_s, loaded_s = walls_s
    if quiet_s is None:
        return f"about {_duration(loaded_s)} with other jobs beside (not measured quiet)"
    return f"about {_duration(quiet_s)} quiet, {_duration(loaded_s)} with other jobs beside"


def _duration(wall_s: float) -> str:
    """Seconds in words: seconds under two minutes, else minutes."""
    return f"{wall_s:.0f} s" if wall_s < 120 else f"{wall_s / 60:.0f} minutes"


class EverySize(argparse.Action):
    """``--size``, each value given kept in ``sizes``: a second that disagrees is refused as ``--size`` with
    ``--full`` is (argparse alone keeps the last silently)."""

    def __call__(self, parser, namespace, values, option_string=None):
        namespace.size = values
        namespace.sizes = [*(vars(namespace).get("sizes") or []), values]


def size_spellings(args, environ=os.environ) -> list:
    """Each way the run's size was given, as (spelling, size): --size (each time), --full, the deprecated
    DSM_BENCHMARK_SIZE."""
    sizes = vars(args).get("sizes") or ([args.size] if args.size is not None else [])
    given = [(f"--size {size}", size) for size in sizes]
    if args.full:
        given.append(("--full", "full"))
    if environ.get(SIZE_ENV):
        given.append((f"{SIZE_ENV}={environ[SIZE_ENV]}", environ[SIZE_ENV]))
    return given


def size_problem(given: list) -> str | None:
    """Why the run's size cannot be told from its spellings ``given`` (one line), None when it can."""
    for spelling, size in given:
        if size not in SIZES:
            return f"{spelling}: not a size (one of {', '.join(SIZES)}); give --size"
    for spelling, size in given[1:]:
        if size != given[0][1]:
            return f"{given[0][0]} and {spelling} disagree: give one --size"
    return None


def alias_lines(given: list) -> list:
    """One line for each old spelling of the size among ``given``, saying what it is an alias of."""
    lines = {"--full": "--full is an alias for --size full (kept for old scripts): give --size full"}
    return [lines.get(spelling, f"{SIZE_ENV} is deprecated, an alias for --size {size}: give --size {size}")
            for spelling, size in given if not spelling.startswith("--size")]


def _err(msg: str) -> int:
    print(f"dsm benchmark: {msg}", file=sys.stderr)
    return 2


def flag_problem(args) -> str | None:
    """The first flag that cannot be used as given, in one line; None when they can."""
    if str(args.out) == "":
        return "--out is empty: give a folder"
    if args.cluster is not None and not args.cluster.strip():
        return "--cluster is empty: give local, auto or a Ray address host:port"
    run_flags = [f for f, on in (("--size", args.size is not None), ("--full", args.full),
                                 ("--suite", args.suite is not None),
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
    return None if args.compare or args.page else size_problem(size_spellings(args))


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
        if problem:
            return _err(problem)
        try:                                    # both read before --out is made or locked
            a, b = (document.read(p) for p in args.compare)
        except document.NotResults as e:
            return _err(f"--compare {e}")
        return _held(out, lambda: _compare(a, b, out))
    return _start(args, out)


def _start(args, out: Path) -> int:
    """A run into ``out``, once the folder, the variant and the cluster can serve it (else one line and its status)."""
    problem = folder_problem(out, args.force, args.resume)
    if problem:
        return _err(problem)
    given = size_spellings(args)
    for line in alias_lines(given):
        print(f"dsm benchmark: {line}", file=sys.stderr)
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
    return _held(out, lambda: _run(args, out, given[0][1] if given else "default"))


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


def _compare(a: dict, b: dict, out: Path) -> int:
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


def _run(args, out: Path, size: str) -> int:
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
