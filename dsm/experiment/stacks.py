"""A stack's build stage (``[timing] builds = "together"``): a sweep's small maps built as one wavefront.

The plan (:func:`dsm.config.plan.stacks`) names the maps built together; the runner builds a
stack when the first of its maps comes up (:mod:`dsm.maps.stacked`, the same bits as each map
alone) and keeps each map until its cases have run. A stack is timed as a whole, as the runner
times a map alone: once for the layers its maps store, once for every other set of layers one of
their scheme instances needs (that instance's ``build_ms``), and once for the first layer without
culling (``build_first_ms``).

**How a map's time is attributed:** a stack's timed call is one launch (a culled search: one a
round), which no clock can split by map. Each map's ``build_ms``, ``build_first_ms`` and
``build_compile_ms`` are the stack's times times the map's share of the stack's texels (its
first-layer rays; a continuation ray is cast for a hit texel of either map alike), and its row's
``build_shared`` says how many maps shared the launch (1: built and timed alone). A user comparing
the cost of resolutions measures them alone (the default, ``builds = "alone"``), where
``build_ms`` is each map's own kernel time.
"""
from __future__ import annotations

import dataclasses
from typing import NamedTuple

from ..maps import stacked
from ..core import timing


class Built(NamedTuple):
    """One map of a stack: the map, its attributed build times, and its stack's size."""
    smap: object
    times: dict                 # frozenset of layers -> attributed Timing, under the stack's culling
    first: object               # attributed Timing of the first layer without culling
    shared: int                 # maps built in the stack


def share(t: timing.Timing, fraction: float) -> timing.Timing:
    """``t`` attributed to a map holding ``fraction`` of a stack's texels (kernel counts are the stack's)."""
    return dataclasses.replace(t, ms=t.ms * fraction, compile_ms=t.compile_ms * fraction,
                               cold_ms=t.cold_ms * fraction)


def build(scene, views, needs, modes: tuple, own_sets, extents, repeats: int) -> list:
    """Build ``views`` (one kind) together with layers ``needs``, timed; time the stacked build of
    every layer set in ``own_sets`` and of the first layer without culling too. ``modes``: (culling,
    its per-shape cull modes, the cull modes without culling: an area light's luminaire stepped
    over, else None). One :class:`Built` per view, in order."""
    culling, cull_modes, plain_modes = modes
    lane = stacked.stack_view(views)

    def timed(layers, modes_):
        """(arrays by name, Timing) of the stack's build of ``layers`` under ``modes_``."""
        out, t = timing.measure_kernel(lambda: _arrays(scene, lane, layers, modes_, extents), repeats)
        return out[-1], t
    timing.reset_peak()
    result, t_full = timed(set(needs), cull_modes)
    peak = timing.peak_bytes()
    times = {frozenset(needs): t_full}
    for own in own_sets:
        if own not in times:
            times[own] = timed(set(own), cull_modes)[1]
    first = times[frozenset()] if culling == "none" and frozenset() in times else timed(set(), plain_modes)[1]
    total = sum(v.n_texels for v in views)
    out = []
    for v, smap in zip(views, stacked.split(views, result, culling)):
        smap.peak_bytes = peak          # the stack's: its maps are built at once
        part = v.n_texels / total
        out.append(Built(smap, {k: share(t, part) for k, t in times.items()}, share(first, part), len(views)))
    return out


def _arrays(scene, lane, layers, cull_modes, extents) -> tuple:
    arrays = stacked.build_arrays(scene, lane, layers, cull_modes, extents)
    return (*arrays.values(), arrays)
