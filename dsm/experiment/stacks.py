"""A stack's build stage (``[timing] builds = "together"``): a sweep's small maps built as one wavefront.

The plan (:func:`dsm.experiment.plan.stacks`) names the maps built together; here each stack is
built (:mod:`dsm.maps.stacked`, the same bits as each map alone) and timed as a whole, once for the
layers its maps store and once for every smaller set of layers one of their scheme instances
needs (that instance's ``build_ms``), as the runner times a map alone.

**How a map's time is attributed:** a stack is one launch a timed call, which no clock can split
by map. Each map's ``build_ms``, ``build_first_ms`` and ``build_compile_ms`` are the stack's times
times the map's share of the stack's texels (its first-layer rays; a continuation ray is cast
for a hit texel of either map alike), and its row's ``build_shared`` says how many maps shared
the launch (1: built and timed alone). A user comparing the cost of resolutions measures them
alone (the default, ``builds = "alone"``), where ``build_ms`` is each map's own kernel time.
"""
from __future__ import annotations

import dataclasses
from typing import NamedTuple

from ..maps import stacked
from ..tools import timing


class Built(NamedTuple):
    """One map of a stack: the map, its attributed build time per set of layers, and its stack's size."""
    smap: object
    times: dict                 # frozenset of layers -> attributed Timing (frozenset(): the first layer)
    shared: int                 # maps built in the stack


def share(t: timing.Timing, fraction: float) -> timing.Timing:
    """``t`` attributed to a map holding ``fraction`` of a stack's texels (kernel counts are the stack's)."""
    return dataclasses.replace(t, ms=t.ms * fraction, compile_ms=t.compile_ms * fraction,
                               cold_ms=t.cold_ms * fraction)


def build(scene, views, needs, culling: str, cull_modes, own_sets, extents, repeats: int) -> list:
    """Build ``views`` (one kind) together with layers ``needs`` under ``culling`` (per-shape
    ``cull_modes``), timed; time the stacked build of every layer set in ``own_sets`` too (under
    the same culling, as the runner times an instance's own layers). One :class:`Built` per view."""
    if not stacked.stackable(views[0]):
        raise ValueError(f"a {views[0].kind} view with cascades is built alone")
    lane = stacked.stack_view(views)

    def cast(layers):
        """The stack's arrays for ``layers``, and the arrays by name (the timed call's result)."""
        out = stacked.build_arrays(scene, lane, layers, cull_modes, extents)
        return (*out.values(), out)
    timing.reset_peak()
    result, t_full = timing.measure_kernel(lambda: cast(set(needs)), repeats)
    peak = timing.peak_bytes()
    times = {frozenset(needs): t_full}
    for own in own_sets:
        if own not in times:
            times[own] = timing.measure_kernel(lambda: cast(set(own)), repeats)[1]
    maps = stacked.split(views, result[-1], culling)
    total = sum(v.n_texels for v in views)
    out = []
    for v, smap in zip(views, maps):
        smap.peak_bytes = peak
        out.append(Built(smap, {k: share(t, v.n_texels / total) for k, t in times.items()}, len(views)))
    return out
