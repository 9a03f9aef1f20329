"""Pre-filtered shadow maps: one module per map kind, each meeting :class:`base.MapKind`.

VSM (Donnelly & Lauritzen 2006), ESM (Annen et al. 2008), EVSM (Lauritzen & McCool 2008) and
MSM (Peters & Klein 2015, Hamburger 4MSM). A ``[map] kind`` other than ``depth`` builds the
kind's moments from the depth map's z1 (:func:`build`), blurs them and looks them up per
receiver (:func:`visibility`): a continuous V, not a margin per tap (:mod:`dsm.prefilter.base`).
"""
from __future__ import annotations

import dataclasses
from types import SimpleNamespace

from . import esm, evsm, msm, presets, vsm
from .base import (LOG_MAX, MOMENT_FORMATS, MapKind, build as build_map, fetch, formats_of, normalized_depth, restored,
                   supersampled_view)
from ..maps.lookup import resolve
from ..core.types import ConfigError
from ..core.suggest import unknown

REGISTRY = (vsm, esm, evsm, msm)
_broken = [m.NAME for m in REGISTRY if not isinstance(m, MapKind)]
assert not _broken, f"map kind modules not meeting the MapKind contract: {_broken}"
NAMES = tuple(m.NAME for m in REGISTRY)


def get(name: str):
    """The map kind module named ``name``; KeyError listing the valid names."""
    for m in REGISTRY:
        if m.NAME == name:
            return m
    raise KeyError(unknown("map kind", name, NAMES))


def check(name: str, params, formats, source: str, where: str):
    """ConfigError for a parameter above its ``max``, not above the field its ``above`` names, or
    outside its ``choices`` (the min is the sweep's), or an exponential moment that overflows one of the stored ``formats``."""
    for f in dataclasses.fields(params):
        val = getattr(params, f.name)
        hi = f.metadata.get("max")
        if hi is not None and val > hi:
            raise ConfigError(source, f"{where}.{f.name}", f"must be <= {hi:g}, got {val!r}")
        below = f.metadata.get("above")
        if below is not None and not val > getattr(params, below):
            raise ConfigError(source, f"{where}.{f.name}", f"must be > {below} ({getattr(params, below)!r}), "
                              f"got {val!r}")
        if "choices" in f.metadata and val not in f.metadata["choices"]:
            raise ConfigError(source, f"{where}.{f.name}", f"unknown value {val!r}", f.metadata["choices"],
                              got=val)
    log_max = get(name).log_max(params)
    for fmt in formats:
        if log_max is not None and fmt in LOG_MAX and log_max > LOG_MAX[fmt]:
            raise ConfigError(source, where, f"{params}: its largest moment exp({log_max:g}) overflows "
                              f"{fmt} (at most exp({LOG_MAX[fmt]:.2f})); lower the exponent")


def build(spec, z1_world, view, fmt: str):
    """The MomentMap of one instance (``spec``: a MomentSpec) from a depth map's z1 (numpy, world;
    ``spec.samples`` squared values a texel of ``view`` where it supersamples: base.supersampled_view)."""
    return build_map(get(spec.name), spec.params, z1_world, view, fmt, spec.blur, spec.kernel, spec.samples,
                     spec.mipmaps)


def build_key(spec, fmt: str) -> tuple:
    """What a MomentMap of ``spec`` depends on besides its depth map: instances sharing it share a build."""
    return (spec.name, get(spec.name).moment_key(spec.params), spec.blur, spec.kernel, spec.samples, spec.mipmaps, fmt)


def visibility(spec, rx, mmap, values=None):
    """V in [0, 1] per receiver of one instance on its built MomentMap (parameters opaque;
    ``values``: parameters replaced by these Dr.Jit values, as dsm tune differentiates them)."""
    module = get(spec.name)
    prm = resolve(spec.params, rx)
    if values:
        prm = SimpleNamespace(**{**vars(prm), **values})
    b = restored(module, fetch(mmap, rx), mmap.fmt)
    return module.visibility(b, normalized_depth(rx.depth, mmap.view), prm)
