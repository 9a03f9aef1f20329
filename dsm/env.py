"""The one place that chooses a Mitsuba variant, after checking Dr.Jit's LLVM backend.

Dr.Jit's LLVM backend aborts the whole process (SIGABRT) on libLLVM 15 and refuses 14, so
the version is checked before the first kernel and a missing or old library becomes a clear
error naming the package to install.
"""
from __future__ import annotations

import os

LLVM_HINT = ("Dr.Jit's LLVM backend needs libLLVM 16 or newer. On Debian 12 run "
             "`apt-get install -y libllvm19` (as root), or set DRJIT_LIBLLVM_PATH to a libLLVM >= 16.")


class SetupError(RuntimeError):
    pass


def llvm_version():
    import drjit as dr
    try:
        return tuple(dr.detail.llvm_version())
    except Exception:
        return None


def use_variant(variant: str | None = None, threads: int | None = None) -> str:
    """Set the Mitsuba variant (default llvm_ad_rgb) once; later calls must agree."""
    import drjit as dr
    import mitsuba as mi
    variant = variant or os.environ.get("DSM_VARIANT") or "llvm_ad_rgb"
    if mi.variant() == variant:
        _register_plugins()
        return variant
    if variant.startswith("llvm"):
        ver = llvm_version()
        if ver is None or ver[0] < 16:
            found = "none found" if ver is None else ".".join(map(str, ver))
            raise SetupError(f"{LLVM_HINT} (found: {found})")
    if threads:
        dr.set_thread_count(int(threads))
    try:
        mi.set_variant(variant)
    except Exception as e:
        raise SetupError(f"cannot use Mitsuba variant {variant!r}: {e}") from None
    if variant.startswith("cuda"):
        try:
            dr.zeros(mi.Float, 1).numpy()
        except Exception as e:
            raise SetupError(f"variant {variant!r} needs a CUDA GPU: {e}") from None
    _register_plugins()
    return variant


def _register_plugins():
    from .plugins import register
    register()
