"""One case's evaluation: its lookup, counts, rates and class image, as a value (no file written).

:func:`evaluate` is the only place a case is looked up, counted and classified: a still map's
cases (the runner), each frame of a motion path (dsm.experiment.motion), a Ray task's map group.
What it measures beyond the counts and rates is the context's ``measures``
(:data:`dsm.case.context.MEASURES`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import pipeline
from ..contact import march as contact
from ..core import timing
from ..hybrid import Inputs as HybridInputs, trace as hybrid
from ..truth import metrics
from .context import Case, MapContext

NO_LOOKUP = timing.Timing(0.0, 0.0, 0.0, 0, 0)     # a case without receivers looks nothing up


@dataclass
class CaseResult:
    """What one case measured: V per receiver, its metrics.csv columns measured on the
    receivers, its class image and its costs."""
    case: Case
    v: np.ndarray                 # V in [0, 1] per receiver
    measured: dict                # counts, rates and the context's measured groups (dsm.core.record's names)
    classes: np.ndarray           # (H, W) uint8: each pixel's class (dsm.truth.metrics.classify), 0 off the receivers
    lookup: timing.Timing         # its lookup's cost (under the wavefront: its kernel's, timed alone)
    lookup_shared: int = 1        # how many of the map's cases that lookup timing stands for
    moments: timing.Timing | None = None   # a pre-filtered instance's moment map build
    occluded: np.ndarray | None = None     # the contact march's occlusion per receiver ([contact])
    cascades: tuple | None = None          # (per-cascade rows, distance curve, cascade per receiver)

    @property
    def n_receivers(self) -> int:
        """The receivers the case was measured on (0: an empty case, which says nothing about its scheme)."""
        return int(self.measured["n_receivers"])


def evaluate(ctx: MapContext, case: Case, looked=None, attached=None) -> CaseResult:
    """Look up, count and classify one case of ``ctx``'s map. ``looked``: its lookups from the
    map's wavefront (dsm.experiment.wavefront.Looked), else looked up and timed here;
    ``attached``: (V of the attached-shadow receivers, plane fallbacks) computed elsewhere."""
    moments_t = ctx.moments(case.spec, case.format)[1] if case.prefiltered else None   # built (timed) first
    look = lookup(ctx, case)
    receivers = ctx.receivers[case.format]
    shared = 1
    if looked is not None:
        v, lookup_t = looked.v, looked.timing
        attached, shared = (looked.v_back, looked.misses), looked.shared
    else:
        v, lookup_t = _looked_up(receivers, look, ctx.repeats)
    measured = pipeline.metrics(v, ctx.setup, _own_surface(ctx, case, receivers), *_seams(ctx))
    result = CaseResult(case, v, measured, None, lookup_t, shared, moments_t)
    if "split" in ctx.measures:         # NaN unless nearest (the oracles' lookup)
        measured.update(pipeline.split(v, ctx.setup.v_star, _wrong(ctx, case)))
    if "contact" in ctx.measures:
        cols, result.occluded = _contact(ctx, receivers, v)
        measured.update(cols)
    if "cascade" in ctx.measures and ctx.view.cascaded:
        cols, per, curve, faces = pipeline.cascade_metrics(ctx.view, receivers, v, ctx.setup.v_star)
        measured.update(cols)
        result.cascades = (per, curve, faces)
        if ctx.view.virtual:
            measured.update(pipeline.virtual_metrics(ctx.view, ctx.depth_map, faces))
    elif "cascade" in ctx.measures and ctx.view.virtual:     # a spot's virtual map: its levels, no cascade rows
        faces = np.asarray(receivers.face.numpy(), int) if receivers is not None else np.zeros(0, int)
        measured.update(pipeline.virtual_metrics(ctx.view, ctx.depth_map, faces))
    if "attached" in ctx.measures:
        measured.update(_attached(ctx, case, look, attached))
    texel_world = receivers.texel_world.numpy() if receivers is not None else np.zeros(0)
    measured["texel_size"] = float(np.median(texel_world)) if receivers is not None else metrics.UNDEFINED
    leak = None
    if "leak" in ctx.measures:
        deep = _deep(ctx, case.format, texel_world)
        measured.update(metrics.leak_split(v, ctx.setup.v_star, deep))
        if receivers is not None and deep is not None:      # the leaks in their own colour
            leak = metrics.leak_mask(v, ctx.setup.v_star, deep)
    shown = v
    if case.hybrid is not None:        # its image shows V after the rays: what the hybrid shows (its hybrid_* counts)
        cols, shown = _hybrid(ctx, case, v)
        measured.update(cols)
    result.classes = _class_image(ctx, shown, _wrong(ctx, case), leak)
    return result


def lookup(ctx: MapContext, case: Case):
    """The case's lookup, receivers -> (V, tap shapes): a depth scheme on its stored map, or a
    pre-filtered instance on its moments (the nearest texel's shape read from the built map)."""
    if case.prefiltered:
        mmap = ctx.moments(case.spec, case.format)[0]
        return lambda r: pipeline.moment_visibility(case.spec, r, mmap, ctx.depth_map)
    return lambda r: pipeline.visibility(case.spec, r, ctx.stored[case.format], case.filter, ctx.seed)


def _looked_up(receivers, look, repeats: int) -> tuple:
    """(V (numpy), the lookup's Timing) of ``receivers``, timed over ``repeats`` calls."""
    if receivers is None:
        return np.zeros(0), NO_LOOKUP
    (v, _), t = timing.measure_kernel(lambda: look(receivers), repeats)
    return v.numpy(), t


def _own_surface(ctx: MapContext, case: Case, receivers) -> np.ndarray:
    """Per receiver, whether the nearest texel the case's lookup reads holds a first hit on the
    receiver's own surface (the acne split's ``self``), outside the timed lookup."""
    if receivers is None:
        return np.zeros(0, bool)
    if case.prefiltered:        # the moments' nearest texel, as pipeline.moment_visibility reads it
        own = pipeline.own_surface(None, receivers, ctx.depth_map, ctx.depth_map)
    else:
        own = pipeline.own_surface(case.spec, receivers, ctx.stored[case.format], ctx.depth_map)
    return own.numpy().astype(bool)


def _seams(ctx: MapContext) -> tuple:
    """(seam distance per receiver, whether the view has seams) as the context measures them."""
    if "seams" not in ctx.measures:
        return None, False
    return ctx.seam_texels, ctx.view.has_seams


def _wrong(ctx: MapContext, case: Case):
    """Per receiver, wrong under the per-texel oracle (a depth case with the nearest filter), else None."""
    if case.prefiltered or case.filter != "nearest":
        return None
    return ctx.wrong.get(case.format)


def _contact(ctx: MapContext, receivers, v) -> tuple:
    """(columns, occluded per receiver) of the contact step after the lookup."""
    setup = ctx.setup
    if receivers is None:
        none = np.zeros(0, bool)
        return {**contact.case_metrics(v, setup.v_star, none), "contact_ms": 0.0}, none
    occluded, t = ctx.march(receivers)
    return {**contact.case_metrics(v, setup.v_star, occluded, setup.v_frac), "contact_ms": t.ms}, occluded


def _attached(ctx: MapContext, case: Case, look, attached) -> dict:
    """Weiskopf & Ertl's self-unshadowing: the pixels in attached shadow (facing away) the map
    calls lit; and the receivers whose texel ray misses their tangent plane (a plane scheme)."""
    uses_plane = not case.prefiltered and pipeline.scheme_module(case.spec.name).USES_PLANE
    if attached is None:
        back, receivers = ctx.backfacing.get(case.format), ctx.receivers[case.format]
        stored = ctx.stored[case.format]
        attached = (look(back)[0].numpy() if back is not None else np.zeros(0),
                    pipeline.plane_fallbacks(case.spec, receivers, stored) if uses_plane and receivers is not None
                    else 0)
    v_back, fallbacks = attached
    return {"n_backfacing": int(v_back.size),
            "backface_lit_rate": float((v_back >= 0.5).mean()) if v_back.size else metrics.UNDEFINED,
            "n_plane_fallback": fallbacks if uses_plane else metrics.UNDEFINED}


def _hybrid(ctx: MapContext, case: Case, v) -> tuple:
    """(the hybrid instance's columns, V after its rays): its rule's rays traced against the exact scene,
    the error left (the case's own columns stay the map's alone, the budget's 0)."""
    return hybrid.measure(case.hybrid, *hybrid_parts(ctx, case, v), ctx.repeats)


def hybrid_parts(ctx: MapContext, case: Case, v) -> tuple:
    """(what the case's hybrid rule reads, the exact side its rays are traced against)."""
    setup = ctx.setup
    if setup.ref is not None:
        raise ValueError("hybrid rays decide a hard light's visibility; this light is an area light")
    light, bbox = pipeline.exact_side(ctx.scene, setup.light)
    exact = hybrid.Exact(ctx.scene.exact, light, setup.si, pipeline.scene_magnitude(bbox))
    inputs = HybridInputs(ctx.receivers[case.format], ctx.stored[case.format], np.asarray(v),
                          setup.v_star.astype(bool), setup.pixels, ctx.image_size[0],
                          not pipeline.is_positional(setup.light))
    return inputs, exact


def _deep(ctx: MapContext, fmt: str, texel_world: np.ndarray):
    """Per receiver, deep in the exact shadow (dsm.truth.leak): probed once per stored format's
    receivers (every case of the map shares them), None for an area light."""
    if fmt not in ctx.deep:
        ctx.deep[fmt] = pipeline.deep_in_shadow(ctx.scene, ctx.setup, texel_world, ctx.leak_texels)
    return ctx.deep[fmt]


def _class_image(ctx: MapContext, v, wrong, leak) -> np.ndarray:
    """(H, W) uint8: each receiver's class, 0 elsewhere."""
    width, height = ctx.image_size
    classes = np.zeros(width * height, np.uint8)
    classes[ctx.setup.pixels] = pipeline.classify(v, ctx.setup.v_star, wrong, leak)
    return classes.reshape(height, width)
