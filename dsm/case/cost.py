"""What a case costs, in counts: the bytes its lookup reads, the rays its map took, the taps per lookup.

Counts, not clocks: they come from the plan's choices and the build (a virtual map's pages, a
layered search's rays), so two identical runs give identical costs, on any machine. The measured
build and lookup times stand beside them in the row (``build_ms``, ``lookup_ms``); the frontier
(:mod:`dsm.report.frontier`) decides on these counts and shows the times.

- ``map_bytes``: the layers the lookup reads, at their stored width, over every face of the view
  (a cascaded map's cascades, a cube's 6 faces, a dual paraboloid's 2: the view's ``n_texels``):
  ``z1`` at the case's format (:data:`FORMAT_BYTES`), ``z2`` at the same width where the scheme reads
  it (midpoint, dual, second depth), the ``slope`` layer in float32 (the kit stores it unquantized).
  The ``shape`` layer (shape ids) is the kit's own bookkeeping for the error split, which no engine
  stores: never counted. A pre-filtered instance: its moments x their width (x 4/3 with mip-maps:
  the chain of 2 x 2 means). A virtual map: its built pages x page texels x width, the physical pool
  the build cast; its page table is ``page_table_bytes`` (one 32-bit entry per virtual page of
  every level), stated apart.
- ``map_rays``: the rays cast to build what the case reads: one per texel for the first layer
  alone; the layered search's continuation rays too where the case reads ``z2`` or the map culls;
  a pre-filtered instance's samples^2 per texel; a virtual map's rays over its built pages.
- ``taps``: texels read per lookup, per receiver: nearest 1, pcf_bilinear 4, pcf_jitter4x4 16,
  pcf_wide:K K^2; PCSS as it runs with the blocker search's early exit (Fernando 2005): its
  PCSS_SEARCH^2 search taps, then PCSS_FILTER^2 filter taps only at the receivers whose search
  found a blocker (their mean over the case's receivers); a pre-filtered instance 1 (the moments are
  blurred once at build), 2 with mip-maps (two levels blended). Each tap reads every layer above.
"""
from __future__ import annotations

import numpy as np

from .. import pipeline
from ..maps import lookup as map_lookup
from ..truth import metrics
from .context import Case, MapContext

# bytes per stored depth: a 24-bit depth occupies a 32-bit word on GPUs (D24_UNORM_S8_UINT, X8_D24)
FORMAT_BYTES = {"float32": 4, "float16": 2, "unorm16": 2, "unorm24": 4, "ndc24": 4}
SLOPE_BYTES = 4                 # the slope layer: float32 in every format
PAGE_ENTRY_BYTES = 4            # a virtual map's page table: one uint32 physical page per virtual page
COLUMNS = ("map_bytes", "page_table_bytes", "map_rays", "taps")
FIXED_TAPS = {"nearest": 1, "pcf_bilinear": 4, "pcf_jitter4x4": 16}


def layer_bytes(layers, fmt: str) -> int:
    """Bytes per texel of the depth ``layers`` (``z1``, ``z2``, ``slope``; ``shape`` never) stored in ``fmt``."""
    width = FORMAT_BYTES[fmt]
    return sum(width if k in ("z1", "z2") else SLOPE_BYTES if k == "slope" else 0 for k in layers)


def moment_bytes(moments: int, fmt: str, mipmaps: bool) -> float:
    """Bytes per texel of a pre-filtered map: ``moments`` at ``fmt``'s width, x 4/3 with a mip chain."""
    return moments * FORMAT_BYTES[fmt] * (4 / 3 if mipmaps else 1)


def filter_taps(filt: str) -> int | None:
    """Taps per lookup of a depth filter whose count is fixed (None: pcss, counted as it runs)."""
    if filt in FIXED_TAPS:
        return FIXED_TAPS[filt]
    if filt == "pcf_wide" or filt.startswith("pcf_wide:"):
        k = int(filt.split(":", 1)[1]) if ":" in filt else map_lookup.PCF_WIDE_DEFAULT
        return k * k
    if filt == "pcss":
        return None
    raise ValueError(f"unknown filter {filt!r}")


def pcss_taps(found_fraction: float) -> float:
    """PCSS's taps per lookup when ``found_fraction`` of the receivers find a blocker (the rest stop after the search)."""
    return map_lookup.PCSS_SEARCH ** 2 + map_lookup.PCSS_FILTER ** 2 * found_fraction


def case_layers(case: Case, culling: str) -> tuple:
    """(the depth layers a depth case reads, whether its map's rays include the layered search)."""
    needs = pipeline.needs_of([case.spec])
    layers = ("z1",) + tuple(k for k in ("z2", "slope") if k in needs)
    return layers, ("z2" in needs or culling != "none")


def costs(ctx: MapContext, case: Case) -> dict:
    """The case's cost columns (:data:`COLUMNS`): bytes read, page table, build rays, taps per lookup."""
    view, smap = ctx.view, ctx.depth_map
    texels = view.n_texels
    table = view.page_table_entries * PAGE_ENTRY_BYTES
    if case.prefiltered:
        spec = case.spec
        per = moment_bytes(pipeline.moment_count(spec), case.format, spec.mipmaps)
        return {"map_bytes": int(round(texels * per)), "page_table_bytes": table,
                "map_rays": texels * spec.samples ** 2, "taps": 2.0 if spec.mipmaps else 1.0}
    layers, searched = case_layers(case, ctx.where.culling)
    rays = smap.rays.get("map_texel", texels) + (smap.rays.get("map_continue", 0) if searched else 0)
    fixed = filter_taps(case.filter)
    taps = float(fixed) if fixed is not None else _pcss_taps(ctx, case)
    return {"map_bytes": texels * layer_bytes(layers, case.format), "page_table_bytes": table,
            "map_rays": int(rays), "taps": taps}


def _pcss_taps(ctx: MapContext, case: Case) -> float:
    """PCSS's mean taps over the case's receivers (UNDEFINED without receivers)."""
    rx = ctx.receivers[case.format]
    if rx is None:
        return metrics.UNDEFINED
    found = pipeline.pcss_blockers_found(case.spec, rx, ctx.stored[case.format])
    return pcss_taps(float(np.mean(found)))


def over_frames(frame_costs: list) -> dict:
    """A motion case's costs from its frames': the largest map's bytes and rays, the mean taps per lookup."""
    out = {k: max(c[k] for c in frame_costs) for k in ("map_bytes", "page_table_bytes", "map_rays")}
    taps = [c["taps"] for c in frame_costs if metrics.defined(c["taps"])]
    return {**out, "taps": float(np.mean(taps)) if taps else metrics.UNDEFINED}
