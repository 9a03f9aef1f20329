"""Command line: ``dsm run``, ``dsm plan``, ``dsm report``, ``dsm schemes``, ``dsm perf``, ``dsm benchmark``, ``dsm tune``.

Every bad input is one or two lines on stderr, never a traceback, before any work starts:
exit 2 for a mistake in the config or the arguments, 3 for the machine's set-up (libLLVM, no
GPU for cuda_ad_rgb), 1 when there is nothing to run, 130 after Ctrl-C.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import re
import shutil
import signal
import sys
import time
from pathlib import Path

from .benchmark import command as benchmark_command
from .grad import command as grad_command
from .config import read as cfgmod
from .config import derived_files
from .report import figures
from .maps import headroom
from .experiment import resume
from .experiment.lock import claim, entries, name_problem, unwritable
from .core.env import MAX_THREADS, SetupError
from .core.labels import params_label
from .core.suggest import valid_words

MAX_MAP = 16384     # the largest map resolution: [map] resolution's maximum (config/read.py)

DEFAULT_CONFIG = Path(__file__).parent / "config" / "default.toml"
# what a dsm run writes into its folder: --force clears a folder holding nothing else
RUN_OUTPUTS = ("run.json", "metrics.csv", "oracle.csv", "table.md", "images", "plots", "report.html",
               "oracle_curves.npz", "cascades.csv", "cascades.md", "frames.csv", "virtual.md", "frontier.csv",
               derived_files.DERIVED_TOML, derived_files.DERIVATION_JSON)
# left by a killed run (report.atomic)
RUN_TEMP = re.compile(r"\.(?:run\.json|metrics\.csv|frontier\.csv|oracle\.csv|table\.md|report\.html|oracle_curves\.npz)\.\d+\.tmp")


def _positive_int(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _thread_count(text):
    # Dr.Jit raises a RuntimeError deep in its pool for counts it cannot start
    value = _positive_int(text)
    if value > MAX_THREADS:
        raise argparse.ArgumentTypeError(f"at most {MAX_THREADS} Dr.Jit threads, got {value}")
    return value


class _Parser(argparse.ArgumentParser):
    """argparse, with a mistake on one line (no usage block) and exit status 2."""

    def error(self, message):
        """Exit with status 2 after one line naming the command and the mistake (no usage block)."""
        bad = re.fullmatch(r"(.*)invalid choice: '(.*)' \(choose from (.*)\)", message)
        if bad:                 # argparse's own list, with the nearest choice as every other error gives it
            choices = re.findall(r"'([^']*)'", bad[3])
            message = f"{bad[1]}invalid choice: {bad[2]!r} ({valid_words(bad[2], choices)})"
        self.exit(2, f"dsm: {self.prog.removeprefix('dsm ') if self.prog != 'dsm' else 'arguments'}: {message} "
                     f"(see {self.prog} --help)\n")


def _parser():
    ap = _Parser(prog="dsm", description="Measure shadow-map bias schemes against exact visibility.")
    sub = ap.add_subparsers(dest="cmd", required=True)
    _run_parser(sub)
    rp = sub.add_parser("report", help="rebuild a run's table.md, plots and report.html from its files (no "
                        "measuring); with two folders, compare the runs")
    rp.add_argument("dirs", nargs="+", metavar="DIR", help="a results folder, or two to compare (A then B)")
    rp.add_argument("--out", help="comparison folder (default: ./compare-<A>-<B>); only with two folders")
    p = sub.add_parser("plan", help="print what a config will compute: cases, maps, rays by kind, memory")
    p.add_argument("config", nargs="?", help="experiment TOML file (default: the built-in default experiment), or a "
                   "Mitsuba scene (.xml): the experiment derived from it")
    p.add_argument("--explain", action="store_true", help="with a scene file: print the measured quantities behind "
                   "each derived choice, and the choices (nothing else is run)")
    sub.add_parser("schemes", help="list bias schemes, their parameters, defaults and sources")
    _bench_parser(sub)
    benchmark_command.add_parser(sub)
    grad_command.add_parser(sub)
    _tune_parser(sub)
    return ap


def parser() -> argparse.ArgumentParser:
    """The ``dsm`` command's argparse parser (its subcommands included; the docs' CLI reference)."""
    return _parser()


def _add_machine(p, variant_help="Mitsuba variant (default llvm_ad_rgb)", threads=True):
    """--variant and (for commands that measure) --threads, alike in every command."""
    p.add_argument("--variant", choices=cfgmod.VARIANTS, help=variant_help)
    if threads:
        p.add_argument("--threads", type=_thread_count, help=f"Dr.Jit worker threads (1 to {MAX_THREADS})")


def _add_again(p, force_help: str, resume_help: str):
    """--force and --resume, which exclude each other, as run and tune take them."""
    again = p.add_mutually_exclusive_group()
    again.add_argument("--force", action="store_true", help=force_help)
    again.add_argument("--resume", action="store_true", help=resume_help)


def _run_parser(sub):
    r = sub.add_parser("run", help="run an experiment config (default: the built-in default experiment)")
    r.add_argument("config", nargs="?", help="experiment TOML file, or a Mitsuba scene (.xml): the experiment "
                   "derived from it (derived.toml beside the results)")
    r.add_argument("--out", help="results folder (default: runs/<name>-<time>)")
    _add_machine(r)
    _add_again(r, "replace a previous dsm run in --out (a folder with its run.json); never other files",
               "go on with the dsm run in --out: skip its finished cases that still match the config, run the "
               "rest (cases the config no longer names are listed, not deleted)")
    r.add_argument("--no-report", action="store_true",
                   help="measure only: metrics.csv, oracle.csv, run.json and the case images, no figures or report.html "
                        "(dsm report OUT draws them later from the folder)")
    r.add_argument("--cluster", metavar="ADDRESS",
                   help="run the map groups as Ray tasks on the cluster at ADDRESS (auto, ray://host:port) or on "
                        "a Ray instance started here (local); needs pip install 'dsm[cluster]'")


def _bench_parser(sub):
    # "bench" is the name before 0.2.0, kept as an alias that says it is one (dsm perf is not dsm benchmark)
    b = sub.add_parser("perf", aliases=["bench"], help="speed: map build against a bare ray cast, lookup cost per "
                       "scheme, memory (dsm bench: its old name)")
    b.add_argument("--out", help="folder for bench.md and bench.json (default: perf/)")
    b.add_argument("--resolutions", default="256,512,1024,2048,4096", help="comma-separated map resolutions")
    b.add_argument("--repeats", type=_positive_int, default=5)
    b.add_argument("--meshes", help="folder of the real test meshes (default: the kit's data/meshes)")
    b.add_argument("--force", action="store_true", help="replace an earlier dsm perf's bench.json and bench.md in --out")
    b.add_argument("--resume", action="store_true", help="go on with the dsm perf interrupted in --out (its finished "
                   "sections kept)")
    _add_machine(b, variant_help=None, threads=False)
    tables = {"--scaling": ("1024,2048,4096,8192", "map resolutions of the cost-against-resolution table, tiled "
                            "within the memory budget ('' to skip; default 1024,2048,4096,8192)"),
              "--geometry": ("", "triangle counts of the cost-against-geometry table (the DEM terrain resampled; "
                             "e.g. 10000,100000,1000000; default '': skipped, it loads each mesh twice)")}
    for flag, (default, text) in tables.items():
        b.add_argument(flag, default=default, help=text)
    skips = {"--no-frame": "skip the one-frame cost (map and every single-layer lookup, kernel and frozen time)",
             "--no-prefilter": "skip the pre-filtered maps' cost (moments, blur and lookup beside PCF at the same width)",
             "--no-sweep": "skip the sweep throughput (local run against a local two-worker Ray cluster)"}
    for flag, text in skips.items():
        b.add_argument(flag, action="store_true", help=text)


def _tune_parser(sub):
    t = sub.add_parser("tune", help="tune scheme parameters (and a learned bias map) by gradient: a config's [tune]")
    t.add_argument("config", help="experiment TOML file with a [tune] table")
    t.add_argument("--out", help="results folder (default: runs/<name>-tune-<time>)")
    _add_again(t, "replace a previous dsm tune in --out (a folder with its tune.json or, stopped, its tune_state.json): "
               "its files only, never others",
               "go on with the dsm tune in --out: keep its finished schemes that still match the config, tune the rest")
    _add_machine(t)


def _err(msg: str):
    print(f"dsm: {msg}", file=sys.stderr)


def _config_error(e: cfgmod.ConfigError, command: str = "run") -> int:
    _err(f"config error: {e}")
    more = getattr(e, "more", None) or []
    if more:
        if command == "plan":
            for m in more:
                _err(f"config error: {m}")
        else:
            _err(f"{len(more)} more: " + ", ".join(m.key for m in more) + " (dsm plan lists each)")
    return 2


def fresh_folder(prefix: str) -> Path:
    """A new folder runs/<prefix>-<time>[-n], made here, so two commands started in the same second
    never share the default folder (mkdir is atomic: the second takes the next suffix)."""
    base = Path("runs") / f"{prefix}-{time.strftime('%Y%m%d-%H%M%S')}"
    base.parent.mkdir(parents=True, exist_ok=True)
    for n in range(1, 1000):
        path = base if n == 1 else base.with_name(f"{base.name}-{n}")
        try:
            path.mkdir()
            return path
        except FileExistsError:
            continue
    return base          # a thousand in one second: the folder lock refuses the rest, naming the holder


def _terminated(signum, frame):
    """SIGTERM (a scheduler's stop, ``kill``) ends a command as Ctrl-C does."""
    raise KeyboardInterrupt


def _interrupted_where(args, out) -> str:
    """What a Ctrl-C leaves and how to go on, for the one line it prints (empty where nothing was written)."""
    where = f" (results so far in {out}/)" if out is not None and entries(out) else ""
    if where and args.cmd == "run" and (out / "run.json").is_file():
        try:
            measured = json.loads((out / "run.json").read_text()).get("state") == "complete"
        except (OSError, ValueError):
            measured = False
        if measured:       # stopped while the report was drawn: every case is measured
            where = (f" while writing the report: every case is measured in {out}/; `dsm report {out}` "
                     "writes table.md, plots/ and report.html")
        else:
            where += f"; `dsm run ... --out {out} --resume` runs the rest"
    elif where and args.cmd == "tune" and (out / "tune_state.json").is_file():
        where = f" (finished schemes in {out}/tune_state.json; `dsm tune ... --out {out} --resume` tunes the rest)"
    return where


def _command_without_config(args) -> int:
    """The commands main hands on whole (schemes, perf or bench, benchmark, grad, report): their exit status."""
    if args.cmd == "schemes":
        print(schemes_text())
        return 0
    if args.cmd in ("perf", "bench"):
        if args.cmd == "bench":
            print("dsm: `dsm bench` is an alias of `dsm perf` (renamed in 0.2.0, so it is not confused with "
                  "`dsm benchmark`); its default --out stays bench/", file=sys.stderr)
        args.out = args.out if args.out is not None else args.cmd
        return _bench(args)
    if args.cmd == "benchmark":
        return benchmark_command.main(args)
    if args.cmd == "grad":
        return grad_command.main(args)
    return _report(args)


def main(argv=None) -> int:
    """Run the ``dsm`` command line on ``argv`` (default: the process's arguments); returns the exit status."""
    try:
        args = _parser().parse_args(argv)
    except SystemExit as e:          # argparse printed its usage line and the error
        return e.code if isinstance(e.code, int) else 2
    if argv is None:                 # as the command: a SIGTERM leaves run.json "interrupted", not "running"
        signal.signal(signal.SIGTERM, _terminated)
    out = None
    try:
        if args.cmd in ("schemes", "perf", "bench", "benchmark", "grad", "report"):
            return _command_without_config(args)
        derived = None
        if args.cmd in ("run", "plan") and is_scene_file(args.config):
            derived, rc = _checked(lambda: derivation_of(args))
            if rc is not None:
                return rc
            if args.cmd == "plan":
                return _plan_derived(derived, args)
        elif getattr(args, "explain", False):
            _err("plan: --explain explains an experiment derived from a scene file (dsm plan SCENE.xml --explain)")
            return 2
        try:
            cfg = None if derived else cfgmod.load(args.config or DEFAULT_CONFIG)
        except cfgmod.ConfigError as e:
            return _config_error(e)
        if args.cmd == "plan":
            return _plan(cfg)
        if getattr(args, "out", None) is not None and not str(args.out).strip():
            _err("--out: an empty path (leave --out out for runs/<name>-<time>/)")
            return 2
        name = derived.tables["experiment"]["name"] if derived else cfg.name
        out = Path(args.out) if args.out else fresh_folder(f"{name}-tune" if args.cmd == "tune" else name)
        if derived:
            cfg, rc = _checked(lambda: derived_files.config_of(derived, out))
            if rc is not None:
                return rc
        return _tune(cfg, args, out) if args.cmd == "tune" else _run(cfg, args, out, derived)
    except KeyboardInterrupt:
        # as the command (not main([...]) from Python): a second Ctrl-C, or one passed on while Ray shuts
        # down, must not break the exit's clean-up (tqdm's and Ray's atexit handlers) into a traceback
        if argv is None:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        print(f"{chr(10) if sys.stderr.isatty() else ''}dsm: interrupted{_interrupted_where(args, out)}",
              file=sys.stderr)
        return 130
    except BrokenPipeError:
        # `dsm ... | head`: the reader of stdout left; every file the command wrote stands. Later
        # writes (Python's own flush at exit) go to /dev/null instead of a second traceback
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


def _bench(args) -> int:
    from .perf.bench import meshes_problem
    try:
        res = [int(x) for x in args.resolutions.split(",")]
        scale = [int(x) for x in args.scaling.split(",") if x.strip()]
        args.geometry_triangles = [int(x) for x in args.geometry.split(",") if x.strip()]
        if any(r < 1 for r in res + scale + args.geometry_triangles):
            raise ValueError
    except ValueError:
        _err(f"--resolutions/--scaling/--geometry: expected positive integers like 256,1024, got "
             f"{args.resolutions!r} / {args.scaling!r} / {args.geometry!r}")
        return 2
    for flag, values in (("--resolutions", res), ("--scaling", scale)):
        if max(values, default=0) > MAX_MAP:     # as dsm run's map.resolution: a map of 2^32 texels or more
            _err(f"{flag}: {max(values)} is above {MAX_MAP}, the largest map resolution (as [map] resolution)")
            return 2
    problem = meshes_problem(args.meshes)
    if problem:
        _err(problem)
        return 2
    held, problem = claim(Path(args.out))
    if problem:
        _err(problem)
        return 2
    with held:
        return _bench_held(args, res, scale)


def _bench_held(args, res, scale) -> int:
    from .perf.bench import Mismatch, kept_sections, run_bench
    out = Path(args.out)
    problem = out_problem(out, force=True, bench=True) or perf_folder_problem(out, args.force, args.resume)
    if problem:
        _err(problem)
        return 2
    try:
        run_bench(out, res, args.repeats, args.meshes, args.variant, scale, not args.no_sweep, not args.no_frame,
                  args.geometry_triangles, not args.no_prefilter, resume=args.resume)
    except SetupError as e:
        _err(f"setup error: {e}")
        return 3
    except Mismatch as e:
        _err(f"--out {out}: cannot resume: {e}; --force starts again")
        return 2
    except KeyboardInterrupt:
        kept = kept_sections(out)
        what = (f"kept in {out / 'bench.json'} and bench.md: {', '.join(kept)}; the rest not measured (the same "
                "command with --resume goes on)" if kept else "no section had finished: nothing kept")
        _err(f"perf interrupted; {what}")
        return 130
    print((Path(args.out) / "bench.md").read_text())
    return 0


PERF_FILES = ("bench.json", "bench.md")     # what dsm perf writes (and --force replaces)


def perf_folder_problem(out: Path, force: bool, resume: bool = False) -> str | None:
    """Why dsm perf may not write into ``out`` (None if it may): a dsm run's folder, or an earlier
    perf without ``force`` (with it, the earlier perf's files are removed) or ``resume``."""
    if force and resume:
        return "--resume goes on with a perf and --force replaces it: give one"
    if (out / "run.json").is_file() or (out / "metrics.csv").is_file():
        return f"--out {out}: holds a dsm run (run.json, metrics.csv), not a dsm perf; choose another --out"
    earlier = [out / f for f in PERF_FILES if (out / f).is_file()]
    if resume:
        return None if (out / "bench.json").is_file() else (
            f"--out {out}: holds no interrupted dsm perf (bench.json) to resume; run without --resume")
    if earlier and not force:
        return (f"--out {out}: holds an earlier dsm perf ({earlier[0].name}); choose another --out, --resume "
                "(goes on with an interrupted one) or --force (replaces it)")
    for f in earlier:
        f.unlink()
    return None


def _report(args) -> int:
    from .report import publish
    dirs = [Path(d) for d in args.dirs]
    if len(dirs) > 2:
        _err(f"report: expected one results folder (rebuild) or two (compare), got {len(dirs)}")
        return 2
    if len(dirs) == 1 and args.out:
        _err("report: --out names the comparison's folder; give two results folders to compare, or none")
        return 2
    problem = next(filter(None, (name_problem(d, "report") for d in dirs)), None)
    if problem:
        _err(problem)
        return 2
    try:
        if len(dirs) == 1:
            t0 = time.perf_counter()
            parts = publish.rebuild(dirs[0])
            for note in parts.get("notes", []):
                _err(f"note: {note}")
            print(f"dsm: report of {dirs[0]}/ rebuilt in {time.perf_counter() - t0:.1f} s ({parts['figures']} "
                  "figures; table.md, plots/, report.html)")
            return 0
        out = Path(args.out) if args.out else Path(f"compare-{dirs[0].resolve().name}-{dirs[1].resolve().name}")
        return _compare(dirs, out)
    except publish.NotARun as e:
        _err(f"report: {e}")
        return 2
    except OSError as e:              # a read-only folder, a full disk: one line, not a traceback
        _err(f"report: cannot write the report: {e.strerror or e} ({e.filename or dirs[0]})")
        return 2


def _compare(dirs, out: Path) -> int:
    from .report import publish
    made = name_problem(out) is None and not out.exists()
    held, problem = claim(out)
    if problem:
        _err(f"report: {problem}")
        return 2
    try:
        with held:
            problem = _compare_out_problem(out)
            if problem:
                _err(f"report: {problem}")
                return 2
            n = publish.compare(dirs[0], dirs[1], out)
    finally:
        if made and entries(out) == []:       # refused or failed: no empty folder left behind
            out.rmdir()
    print(f"dsm: {n['matched']} cases in both runs, {n['only_a']} only in A, {n['only_b']} only in B -> "
          f"{out}/ (compare.md, compare.csv)")
    return 0


COMPARE_OUTPUTS = ("compare.md", "compare.csv")


def _compare_out_problem(out: Path) -> str | None:
    """Why a comparison cannot go into ``out`` (None if it can): a file, a dsm run's folder (its
    files would be mixed with the comparison's) or a folder holding anything but an earlier
    comparison (which is replaced: both runs still hold everything it was made from)."""
    if out.exists() and not out.is_dir():
        return f"--out {out}: is a file, not a folder; choose another --out"
    if not out.is_dir():
        return None
    if (out / "run.json").exists():
        return f"--out {out}: is a dsm run's folder; put the comparison in a folder of its own (another --out)"
    foreign = sorted(p.name for p in entries(out) if p.name not in COMPARE_OUTPUTS)
    if foreign:
        return (f"--out {out}: holds files a comparison does not write ({', '.join(foreign[:3])}"
                f"{', ...' if len(foreign) > 3 else ''}); choose an empty or new --out")
    return None


def is_scene_file(path) -> bool:
    """Whether a command's config argument names a Mitsuba scene, from which the experiment is derived."""
    return path is not None and Path(path).suffix.lower() == ".xml"


def derivation_of(args):
    """The experiment derived from the scene file ``args.config`` (dsm.config.derive), its scene
    measured under the command's variant and threads (a plan's on the CPU)."""
    from .core import env
    from .config import derive, scene_facts
    variant = getattr(args, "variant", None)
    env.use_variant(None if args.cmd == "plan" else variant, getattr(args, "threads", None))
    return derive.derive(scene_facts.measure(args.config))


def _plan_derived(derived, args) -> int:
    """dsm plan SCENE.xml: the derived choices (with --explain the quantities behind them, and nothing else),
    then the derived config's plan."""
    lines = derived_files.explain_lines(derived) if args.explain else []
    for line in lines + derived_files.reason_lines(derived):
        print(line)
    if args.explain:
        return 0
    cfg, rc = _checked(lambda: derived_files.config_of(derived, None, f"{args.config} (derived)"))
    return rc if rc is not None else _plan(cfg)


def _plan(cfg) -> int:
    from .config import plan as planmod
    from .scenes import load as scenes
    # which scenes cannot be read: load them (on the CPU: no GPU needed to plan)
    try:
        from .core import env
        env.use_variant(None if (cfg.variant or "").startswith("cuda") else cfg.variant)
        loadable = True
    except SetupError as e:
        _err(f"note: scenes not loaded, so only checked as text ({e})")
        loadable = False
    try:
        if loadable:
            scenes.check(cfg)
        plan = planmod.make(cfg)
        if "tune" in cfg.raw and loadable:     # what dsm tune would refuse, said by the plan too
            from .tune import tuner as tunemod
            tunemod.parse_tune(cfg)
    except cfgmod.ConfigError as e:
        return _config_error(e, "plan")
    print(plan.text())
    try:
        cfgmod.check_runnable(cfg)
        planmod.check_memory(plan, cfg.source)
    except cfgmod.NothingToRun as e:
        _err(e.problem)
        return 1
    except cfgmod.ConfigError as e:
        return _config_error(e, "plan")
    return 0


def out_problem(out: Path, force: bool, bench: bool = False) -> str | None:
    """Why ``out`` cannot take the results (None if it can); with ``force``, a previous dsm run
    in it is cleared first. Leaves the folder created and empty (or as bench found it)."""
    if out.is_symlink() and not out.is_dir():
        return f"--out {out}: a broken symbolic link"
    if out.exists() and not out.is_dir():
        return f"--out {out}: is a file, not a folder; choose another --out"
    held = entries(out)
    if held and not bench:
        if not force:
            what = " (it holds a dsm run)" if (out / "run.json").is_file() else ""
            return (f"--out {out}: is not empty{what}; choose another --out, or pass --resume (goes on with a dsm "
                    "run there, keeping its finished cases) or --force (replaces a previous dsm run)")
        foreign = sorted(p.name for p in held if p.name not in RUN_OUTPUTS and not RUN_TEMP.fullmatch(p.name))
        if not (out / "run.json").is_file():
            return (f"--force: {out} holds no previous dsm run (no run.json), so it is not cleared; "
                    "choose another --out")
        if foreign:
            return (f"--force: {out} holds files a dsm run does not write ({', '.join(foreign[:3])}"
                    f"{', ...' if len(foreign) > 3 else ''}), so it is not cleared; choose another --out")
        try:
            json.loads((out / "run.json").read_text())
        except (OSError, ValueError):
            return f"--force: {out}/run.json is not a dsm run.json, so {out} is not cleared; choose another --out"
        if out.is_symlink():
            return f"--force: {out} is a symbolic link; clear its target yourself or choose another --out"
        try:
            _clear(held)
        except OSError as e:
            return f"--force: cannot clear {out}: {e.strerror or e}"
    return unwritable(out)


# what a run writes inside images/ (<scene>_<light>/<case>_<kind>, also under stale/) and plots/
# (and a scene and light's display renders), and plots/ (figures, and their case points' .points.json)
WRITTEN = {"images": re.compile(r"\d{4}_(" + "|".join(map(re.escape, figures.CASE_IMAGE_KINDS)) + ")|"
                                + "|".join(map(re.escape, figures.DISPLAY_FILES))),
           "plots": re.compile(r"[^/]+\.png|[^/]+\.points\.json")}


def _clear(paths):
    """Remove a previous run's entries: images/ and plots/ only of what a run writes there
    (a user's own files in them stay, with the folders that hold them)."""
    # entry by entry, not the folder: its lock file is held by this process
    for p in paths:
        if p.name in WRITTEN and p.is_dir() and not p.is_symlink():
            _clear_written(p, WRITTEN[p.name])
        elif p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        else:
            p.unlink()


def _clear_written(folder: Path, pattern):
    """Delete the files under ``folder`` whose names ``pattern`` matches, then the folders left empty."""
    for f in sorted(folder.rglob("*"), reverse=True):        # children before their folders
        if f.is_file() and not f.is_symlink() and pattern.fullmatch(f.name):
            f.unlink()
        elif f.is_dir() and not f.is_symlink() and not any(f.iterdir()):
            f.rmdir()
    if not any(folder.iterdir()):
        folder.rmdir()


def resume_problem(out: Path, cfg=None) -> str | None:
    """Why ``--resume`` cannot go on with the run in ``out`` (None if it can): no dsm run there,
    or the run of another experiment (``[experiment] name`` differs from ``cfg``'s: resuming it
    would set every one of its cases aside as stale)."""
    if not (out / "run.json").is_file():
        return f"--resume: {out} holds no previous dsm run (no run.json); choose another --out"
    try:
        prev = json.loads((out / "run.json").read_text())
    except (OSError, ValueError):
        return f"--resume: {out}/run.json is not a dsm run.json; choose another --out"
    if not isinstance(prev, dict):
        return f"--resume: {out}/run.json is not a dsm run.json; choose another --out"
    problem = resume.metrics_problem(out / "metrics.csv")
    if problem:
        return f"--resume: {problem}; choose another --out, or --force to replace the run"
    if cfg is not None and prev.get("experiment") not in (None, cfg.name):
        return (f"--resume: {out} holds experiment {prev['experiment']!r} (config {prev.get('config_file') or '?'}), "
                f"not {cfg.name!r} ({cfg.source}); resume it with its own config or choose another --out")
    return unwritable(out)


def folder_problem(out: Path, cfg, force: bool = False, resume: bool = False):
    """(why a run of ``cfg`` cannot go into the held ``out`` or None, whether it resumes the run there)."""
    # dsm run's rules for --out, --force and --resume, shared with dsm.run
    resuming = resume and bool(entries(out))
    return (resume_problem(out, cfg) if resuming else out_problem(out, force)), resuming


def _checked(check):
    """``check()``'s result, or the exit code of the problem it raised (said in one line):
    nothing to run 1, a config mistake 2, set-up missing 3."""
    try:
        return check(), None
    except cfgmod.NothingToRun as e:
        _err(e.problem)
        return None, 1
    except SetupError as e:
        _err(f"setup error: {e}")
        return None, 3
    except cfgmod.ConfigError as e:
        return None, _config_error(e)


def _run(cfg, args, out: Path, derived=None) -> int:
    from . import pipeline
    # every check dsm.run makes, before any work
    cfg, rc = _checked(lambda: pipeline.prepare(cfg, args.variant, args.threads))
    if rc is not None:
        return rc
    if "tune" in (cfg.raw or {}):
        print("dsm: note: the [tune] table is read by `dsm tune`; `dsm run` measures the schemes as given",
              file=sys.stderr)
    clustered = bool(args.cluster) or cfg.execution.backend == "ray"
    if clustered:                       # reach the cluster before the folder is touched
        try:
            from .experiment import cluster
            variant = args.variant or cfg.variant
            if (args.cluster or cfg.execution.address or "local") == "local":
                # a task bigger than the instance to be started here is refused before Ray starts (seconds)
                have = cluster.local_resources()
                if have is not None:
                    cluster.check_resources(cfg.execution, variant, cfg.source, have)
            if args.cluster:
                cluster.connect(args.cluster)
            else:
                cluster.connect(cfg.execution.address or "local", source=cfg.source, key="execution.address")
            cluster.check_resources(cfg.execution, variant, cfg.source)
        except SetupError as e:
            _err(f"setup error: {e}")
            return 3
        except cfgmod.ConfigError as e:
            if args.cluster:
                _err(str(e).removeprefix(f"{e.source}: "))
                return 2
            return _config_error(e)
    held, problem = claim(out)
    if problem:
        _err(problem)
        return 2
    with held:
        return _run_held(cfg, args, out, clustered, derived)


def _written(args, derived=None) -> str:
    """What dsm run wrote, as its last line names it."""
    files = ("metrics.csv, oracle.csv, images/, run.json" if getattr(args, "no_report", False) else
             "report.html, table.md, metrics.csv, oracle.csv, images/, plots/, run.json, frontier.csv")
    return files + (", derived.toml" if derived is not None else "") + (
        "; --no-report: dsm report draws the rest" if getattr(args, "no_report", False) else "")


def _run_held(cfg, args, out: Path, clustered: bool, derived=None) -> int:
    problem, resuming = folder_problem(out, cfg, args.force, bool(getattr(args, "resume", False)))
    if problem:
        _err(problem)
        return 2
    if derived is not None:             # beside the results, before any case: the report reads the reasons
        derived_files.write(derived, out)
        for line in derived_files.reason_lines(derived):
            print(f"dsm: {line}")
    try:
        from .experiment.runner import Runner
        t0 = time.perf_counter()
        if clustered:
            from .experiment import cluster
            res = cluster.run(cfg, out, args.cluster, args.variant, progress=True, resume_previous=resuming,
                              report=not getattr(args, "no_report", False))
        else:
            res = Runner(cfg, out, args.variant, progress=True, resume_previous=resuming,
                         report=not getattr(args, "no_report", False)).run()
    except SetupError as e:
        _err(f"setup error: {e}")
        return 3
    except cfgmod.ConfigError as e:
        return _config_error(e)
    failed, empty = res.run["n_failed"], res.run["n_empty"]
    if resuming:
        print(f"dsm: resumed: {res.run['resumed_cases']} finished cases kept, "
              f"{len(res.rows) - res.run['resumed_cases']} run", file=sys.stderr)
        for s in res.run["stale_cases"]:
            print(f"dsm: kept, not in the config any more: case {s['case']} ({s['scene']}, {s['light']}, "
                  f"{s['scheme']} {s['params']}, R={s['resolution']}; see run.json stale_cases)", file=sys.stderr)
    t = res.run["timing"]
    from .report import summary
    for line in summary.terminal_answer(res.rows):      # the first answer, before where the files are
        print(f"dsm: {line}")
    print(f"dsm: {len(res.rows)} case{'' if len(res.rows) == 1 else 's'} in {time.perf_counter() - t0:.1f} s (measuring {t['measure_s']:.1f} s, "
          f"report {t['report_s']:.1f} s) -> {out}/ ({_written(args, derived)})")
    if empty:
        print(f"dsm: {empty} cases are empty (no receiver: nothing faces the light inside its domain); "
              "their rates are undefined (see table.md)", file=sys.stderr)
    for line in reference_notes(res.run.get("reference_regions", [])) + [headroom.summary(res.rows)]:
        if line:
            print(f"dsm: {line}", file=sys.stderr)
    if failed:
        print(f"dsm: {failed} failed (reasons above, in table.md and run.json)", file=sys.stderr)
        return 1
    return 0


def reference_notes(regions: list) -> list:
    """One line per area light whose reference left receivers at max_samples above its tolerance."""
    out = []
    for r in regions:
        n = r.get("capped_above_tolerance", 0)
        if n:
            total = sum(r[k]["receivers"] for k in ("umbra", "penumbra", "lit"))
            out.append(f"area light reference of {r['scene']} {r['light']}: {n} of {total} receivers ended at "
                       f"max_samples with a {r.get('confidence', 0.99):g} interval wider than the tolerance "
                       f"(largest half-width {r['half_width_max']:.3g}); raise max_samples (run.json reference_regions)")
    return out


def _tune(cfg, args, out: Path) -> int:
    from .tune import tuner as tunemod
    from . import pipeline

    def check():
        """The TuneConfig to run: ``[tune]`` checked, then the config prepared (variant, threads)."""
        tc = tunemod.parse_tune(cfg)                 # [tune] checked before any scene loads
        tc.config = pipeline.prepare(cfg, args.variant, args.threads)
        return tc
    tc, rc = _checked(check)
    if rc is not None:
        return rc
    ignored = [k for k, v in (("[contact]", cfg.contact), ("map.shrink", cfg.shrink)) if v is not None]
    if ignored:                          # the tuner's objective is the map's lookup alone
        print(f"dsm: note: {' and '.join(ignored)} are measured by `dsm run`; `dsm tune` tunes without them",
              file=sys.stderr)
    held, problem = claim(out)
    if problem:
        _err(problem)
        return 2
    with held:
        return _tune_held(tc, out, getattr(args, "force", False), getattr(args, "resume", False))


def _tune_held(tc, out: Path, force: bool = False, resume: bool = False) -> int:
    from .tune import tuner as tunemod
    from .tune.folder import tune_folder
    from .tune.output import table_text
    problem, resuming = tune_folder(out, tc.config.name, force, resume)
    if problem:
        _err(problem)
        return 2
    t0 = time.perf_counter()
    try:
        res = tunemod.run_tune(tc, out, progress=True, resume=resuming)
    except cfgmod.ConfigError as e:
        return _config_error(e)
    print(table_text(res))
    if resuming:
        print(f"dsm: resumed: {res.resumed} finished schemes kept, {len(res.schemes) - res.resumed} tuned",
              file=sys.stderr)
    print(f"dsm: {'wrote' if res.resumed else 'tuned'} {len(res.schemes)} scheme{'s' * (len(res.schemes) != 1)}" + (f" and {len(res.moments)} pre-filtered instance{'s' * (len(res.moments) != 1)}" if res.moments else "") + f" in {time.perf_counter() - t0:.1f} s -> {out}/ (tuned.toml, "
          "table.md, steps.csv, tune.json, plots/)")
    return 0


def schemes_text() -> str:
    """``dsm schemes``' text: each scheme's source, layers, parameters and summary, then presets and units."""
    from .schemes import ALL, presets
    lines = []
    for s in ALL:               # the shadow-map schemes, then the VSV lookups (view vsv only)
        needs = ", ".join(sorted(s.NEEDS)) or "first layer only"
        lines.append(f"{s.NAME}  [{s.SOURCE}]  needs: {needs}")
        for f in dataclasses.fields(s.Params):
            shown = params_label(f"{f.name}={f.default}", exact=True).partition("=")[2]
            lines.append(f"    {f.name} = {shown}    {f.metadata.get('doc', '')}")
        lines.append("    " + (s.__doc__ or "").strip().splitlines()[0])
    lines += presets.text()
    from .contact import presets as contact_presets
    lines += contact_presets.text()
    lines.append('lengths: a number (world units), "k texel" (texel widths at the receiver) or "k range" '
                 "(fraction of the view's depth range); 2^k reads as a number (\"2^-24 range\")")
    lines += prefilter_text()
    # a depth step as the report and the run's console name it (2^-24 range); other numbers as written
    return "\n".join(params_label(line, exact=True) for line in lines)


def prefilter_text() -> list:
    """The pre-filtered map kinds of ``[map] kind`` (dsm.prefilter): source, parameters, defaults."""
    from . import prefilter
    lines = ["pre-filtered maps ([map] kind = [...], parameters in [map.<kind>], [map] blur = box widths in texels; "
             "a continuous V per receiver, not a margin per tap):"]
    for k in prefilter.REGISTRY:
        lines.append(f"{k.NAME}  [{k.SOURCE}]")
        lines += [f"    {f.name} = {f.default}" for f in dataclasses.fields(k.Params)]
        lines.append("    " + (k.Params.__doc__ or "").strip().splitlines()[0])
    lines += prefilter.presets.text()
    return lines


if __name__ == "__main__":
    sys.exit(main())
