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
  found a blocker (their mean over the case's receivers); SMRT (dsm.maps.smrt) rays x samples;
  a pre-filtered instance 1 (the moments are
  blurred once at build), 2 with mip-maps (two levels blended). Each tap reads every layer above.
"""
from __future__ import annotations

import numpy as np

from .. import pipeline
from ..maps import costs as rules
from ..truth import metrics
from .context import Case, MapContext

COLUMNS = ("map_bytes", "page_table_bytes", "map_rays", "taps")


def case_layers(case: Case, culling: str) -> tuple:
    """(the depth layers a depth case reads, whether its map's rays include the layered search)."""
    needs = pipeline.needs_of([case.spec])
    layers = ("z1",) + tuple(k for k in ("z2", "slope") if k in needs)
    return layers, ("z2" in needs or culling != "none")


def costs(ctx: MapContext, case: Case) -> dict:
    """The case's cost columns (:data:`COLUMNS`): bytes read, page table, build rays, taps per lookup."""
    view, smap = ctx.view, ctx.depth_map
    texels = view.n_texels
    table = view.page_table_entries * rules.PAGE_ENTRY_BYTES
    if case.prefiltered:
        spec = case.spec
        per = rules.moment_bytes(pipeline.moment_count(spec), case.format, spec.mipmaps)
        return {"map_bytes": int(round(texels * per)), "page_table_bytes": table,
                "map_rays": texels * spec.samples ** 2, "taps": 2.0 if spec.mipmaps else 1.0}
    layers, searched = case_layers(case, ctx.where.culling)
    rays = smap.rays.get("map_texel", texels) + (smap.rays.get("map_continue", 0) if searched else 0)
    fixed = rules.filter_taps(case.filter)
    taps = float(fixed) if fixed is not None else _pcss_taps(ctx, case)
    return {"map_bytes": texels * rules.layer_bytes(layers, case.format), "page_table_bytes": table,
            "map_rays": int(rays), "taps": taps}


def _pcss_taps(ctx: MapContext, case: Case) -> float:
    """PCSS's mean taps over the case's receivers (UNDEFINED without receivers)."""
    rx = ctx.receivers[case.format]
    if rx is None:
        return metrics.UNDEFINED
    found = pipeline.pcss_blockers_found(case.spec, rx, ctx.stored[case.format])
    return rules.pcss_taps(float(np.mean(found)))


def over_frames(frame_costs: list) -> dict:
    """A motion case's costs from its frames': the largest map's bytes and rays, the mean taps per lookup."""
    out = {k: max(c[k] for c in frame_costs) for k in ("map_bytes", "page_table_bytes", "map_rays")}
    taps = [c["taps"] for c in frame_costs if metrics.defined(c["taps"])]
    return {**out, "taps": float(np.mean(taps)) if taps else metrics.UNDEFINED}
