"""The one place that chooses a Mitsuba variant, after checking Dr.Jit's LLVM backend.

Dr.Jit's LLVM backend aborts the whole process (SIGABRT) on libLLVM 15 and refuses 14, so
the version is checked before the first kernel and a missing or old library becomes a clear
error naming the package to install.
"""
from __future__ import annotations

import functools
import importlib.util
import os
import platform
import subprocess
from pathlib import Path

LLVM_HINT = ("Dr.Jit's LLVM backend needs libLLVM 16 or newer. On Debian 12 run "
             "`apt-get install -y libllvm19` (as root), or set DRJIT_LIBLLVM_PATH to a libLLVM >= 16.")


class SetupError(RuntimeError):
    """The machine's set-up cannot do what was asked (libLLVM missing or too old, no GPU for cuda_ad_rgb, no Ray)."""
    pass


# Dr.Jit starts every thread it is given: 100000 fail with a RuntimeError from its pool, 1024 start
# in 0.05 s; more than 1024 never helps on any machine dsm runs on
MAX_THREADS = 1024


def meshes_folder() -> Path:
    """The kit's real meshes: the checkout's data/meshes, else the installed wheel's copy (package
    ``dsm_meshes``, pyproject's package-data), so dsm benchmark and dsm perf read them either way."""
    checkout = Path(__file__).resolve().parents[2] / "data" / "meshes"
    if checkout.is_dir():
        return checkout
    spec = importlib.util.find_spec("dsm_meshes")
    places = list(spec.submodule_search_locations or []) if spec is not None else []
    return Path(places[0]) if places else checkout


def llvm_version():
    """Dr.Jit's libLLVM version as a tuple, or None when it has none."""
    import drjit as dr
    try:
        ver = dr.detail.llvm_version()
    except Exception:
        return None
    # Dr.Jit 1.0 gives the version as text ("19.1.7"), later releases as a tuple of numbers
    ver = tuple(int(x) for x in ver.split(".")) if isinstance(ver, str) else tuple(ver)
    return None if not ver or min(ver) < 0 else ver         # (-1, -1, -1): no library loaded


def use_variant(variant: str | None = None, threads: int | None = None) -> str:
    """Set the Mitsuba variant (default llvm_ad_rgb) once; later calls must agree."""
    import drjit as dr
    import mitsuba as mi
    from .suggest import valid_words
    from .types import VARIANTS
    variant = variant or os.environ.get("DSM_VARIANT") or "llvm_ad_rgb"
    if variant not in VARIANTS:
        raise SetupError(f"variant {variant!r} is not supported: dsm runs vectorized Dr.Jit code "
                         f"({valid_words(variant, VARIANTS)})")
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int)
                                or not 1 <= threads <= MAX_THREADS):
        raise SetupError(f"threads must be an integer from 1 to {MAX_THREADS}, got {threads!r}")
    if mi.variant() == variant:
        if threads:
            dr.set_thread_count(threads)
        exact_math()
        register_plugins()
        return variant
    if variant.startswith("llvm"):
        ver = llvm_version()
        if ver is None or ver[0] < 16:
            found = "none found" if ver is None else ".".join(map(str, ver))
            given = os.environ.get("DRJIT_LIBLLVM_PATH")
            found += f", DRJIT_LIBLLVM_PATH={given}" if given else ""
            raise SetupError(f"{LLVM_HINT} (found: {found})")
    if variant.startswith("cuda") and not has_cuda():
        raise SetupError(f"variant {variant} needs an NVIDIA GPU with CUDA; none found here: use llvm_ad_rgb")
    if threads:
        dr.set_thread_count(threads)
    try:
        mi.set_variant(variant)
    except Exception as e:
        raise SetupError(f"cannot use Mitsuba variant {variant!r}: {e}") from None
    if variant.startswith("cuda"):
        try:
            dr.zeros(mi.Float, 1).numpy()
        except Exception as e:
            raise SetupError(f"variant {variant} needs an NVIDIA GPU with CUDA: {e}") from None
    exact_math()
    register_plugins()
    return variant


def exact_math():
    """Turn Dr.Jit's fast math off for this thread (the flag is per thread).

    With it on, Dr.Jit's LLVM backend computes ``rsqrt`` and ``rcp`` (hence every
    ``normalize``) with the CPU's approximate instructions where the vector width matches
    them (AVX's 8 lanes, AVX-512's 16) and lets LLVM contract and reassociate: a texel ray's
    direction then differs in its last bits between an AVX2 and an AVX-512 machine, and
    between AMD's and Intel's approximation tables. Off, every operation is IEEE rounded, so
    a value's bits do not depend on the CPU or on the vector width (docs/design.md,
    *Results that do not depend on the machine*)."""
    import drjit as dr
    dr.set_flag(dr.JitFlag.FastMath, False)


def has_cuda() -> bool:
    """Whether Dr.Jit found a CUDA driver and device (it initializes its backends on import)."""
    import drjit as dr
    try:
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:
        return False


PLUGIN_GROUP = "dsm.plugins"      # entry points: callables that register Mitsuba plugins


def register_plugins() -> list:
    """Register the Mitsuba plugins installed with the kit (entry-point group ``dsm.plugins``;
    ``dsm_plugins`` gives dsm_shadow and dsm_error) for the current variant; their names.
    The kit imports no plugin statically: a plugin depends on ``dsm.pipeline``, not the reverse."""
    names = []
    for register in plugin_registrars():
        names += list(register() or ())
    return names


@functools.cache
def plugin_registrars() -> tuple:
    """The installed ``dsm.plugins`` entry points, loaded: found once per process, since reading every
    installed package's metadata took about 10 ms a call and use_variant registers at each run's start."""
    from importlib.metadata import entry_points
    return tuple(ep.load() for ep in entry_points(group=PLUGIN_GROUP))


def git_commit() -> str:
    """The kit's git commit (``+dirty`` with uncommitted changes to tracked files), or ``unknown`` (not
    a checkout of dsm: the repository holding the package is not the one whose top holds ``dsm/``)."""
    try:
        here = Path(__file__).resolve().parent
        top = subprocess.run(["git", "rev-parse", "--show-toplevel"], cwd=here, capture_output=True, text=True,
                             timeout=5).stdout.strip()
        # an installed dsm inside another project's repository is not that repository's commit
        if not top or Path(top).resolve() != here.parents[1]:
            return "unknown"
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5)
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=here,
                               capture_output=True, text=True, timeout=5).stdout.strip()
        return out.stdout.strip() + ("+dirty" if dirty else "") if out.returncode == 0 else "unknown"
    except Exception:
        return "unknown"


def dsm_version() -> str:
    """The installed dsm's version (its package metadata), or ``unknown`` for a copy not installed."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("dsm")
    except PackageNotFoundError:
        return "unknown"


def machine() -> dict:
    """The machine a run measured on: CPU model, core count, OS."""
    model = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": model, "cores": os.cpu_count(), "system": platform.platform()}


def versions() -> dict:
    """Python, Mitsuba, Dr.Jit, libLLVM, dsm and its git commit (read once per run: git is a subprocess)."""
    import drjit as dr
    import mitsuba as mi
    return {"python": platform.python_version(), "mitsuba": mi.__version__, "drjit": dr.__version__,
            "libllvm": ".".join(map(str, llvm_version() or ())) or "unavailable", "dsm": dsm_version(),
            "dsm_git_commit": git_commit()}


# The versions a result's bits depend on: Mitsuba and Dr.Jit change a count between releases (a
# kernel's rounding, Embree's build), and dsm changes what it measures. They enter every case's
# resume key and are compared when a run is resumed or two benchmark results are compared.
ENGINE = ("dsm", "mitsuba", "drjit")


def engine(versions_: dict) -> dict:
    """The ENGINE part of a ``versions()`` record (an absent one, as an older dsm wrote it: None)."""
    return {k: (versions_ or {}).get(k) for k in ENGINE}


def engine_change(before: dict, after: dict) -> str | None:
    """The ENGINE versions that differ between two ``versions()`` records, as one phrase
    (``mitsuba 3.9.0 -> 3.9.1, drjit 1.4.0 -> 1.5.0``), or None when they agree."""
    a, b = engine(before), engine(after)
    moved = [f"{k} {a[k] or 'unrecorded'} -> {b[k] or 'unrecorded'}" for k in ENGINE if a[k] != b[k]]
    return ", ".join(moved) or None
