"""The one builder of a case's metrics.csv row, and the columns every kind of case shares.

A row is the case's identity (:func:`identity`), what it measured, and what it cost
(:func:`row`). A still case measures one :class:`dsm.case.evaluation.CaseResult`
(:func:`still_measured`, :func:`still_costs`); a motion case the frames' results summed and
averaged (dsm.experiment.motion). :func:`dsm.core.record.check_row` refuses a row that does not
fit the schema when it is written.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..core import timing
from ..maps import headroom
from ..truth import metrics
from . import cost
from .context import Case, MapContext, Where
from .evaluation import CaseResult


def identity(where: Where, case: Case) -> dict:
    """The columns that name a case: its map's place in the plan, its scheme instance, filter and format."""
    spec = case.spec
    return {"case": case.id, "scene": where.scene, "light": where.light, "view": where.view, "scheme": spec.name,
            "culling": where.culling, "preset": spec.preset or "", "params": spec.label,
            "resolution": where.resolution, "total_texels": where.total_texels, "filter": case.filter,
            "format": case.format, "cascade_layout": where.cascade_layout}


def row(ident: dict, measured: dict, costs: dict) -> dict:
    """A case's row: identity, measured columns and costs (an undefined value is the one UNDEFINED)."""
    out = {**ident, **measured, **costs}
    for k, val in out.items():
        if isinstance(val, float) and not metrics.defined(val):
            out[k] = metrics.UNDEFINED
    return out


def still_measured(ctx: MapContext, result: CaseResult) -> dict:
    """A still case's measured columns: its receivers' exclusions, counts and rates, and its map's
    float32 headroom at the median texel."""
    extent = ctx.setup.max_abs_coordinate if ctx.receivers[result.case.format] is not None else metrics.UNDEFINED
    return {**ctx.setup.exclusions, **result.measured, **headroom.headroom(extent, result.measured["texel_size"])}


@dataclasses.dataclass(frozen=True)
class BuildCost:
    """What building a case's map cost: its own layers (a stacked map's share), the first layer
    alone, and the map's peak bytes and how many maps shared its build."""
    own: timing.Timing
    first_layer: timing.Timing
    peak_bytes: int
    shared: int


def still_costs(ctx: MapContext, result: CaseResult, build: BuildCost) -> dict:
    """A still case's cost columns: its map's build, its lookup, the light's exact reference, and
    its costs in counts (:func:`dsm.case.cost.costs`)."""
    lookup = result.lookup
    return {**cost.costs(ctx, result.case), "build_ms": build.own.ms, "build_first_ms": build.first_layer.ms, "build_compile_ms": build.own.compile_ms,
            "build_peak_mb": build.peak_bytes / 2 ** 20, "build_shared": build.shared,
            "lookup_ms": lookup.ms, "lookup_compile_ms": lookup.compile_ms,
            "lookup_kernels_compiled": lookup.cache_misses, "lookup_shared": result.lookup_shared,
            "reference_ms": ctx.setup.reference_ms}


def map_kind_columns(case: Case, moments_ms: float) -> dict:
    """A run with ``[map] kind`` given: the case's map kind and its moment map's build time
    (undefined for a depth scheme)."""
    return {"map_kind": case.spec.name if case.prefiltered else "depth",
            "moments_ms": moments_ms if case.prefiltered else metrics.UNDEFINED}


def sweep_of(spec, all_specs) -> tuple[str, float]:
    """The numeric parameter a scheme's sweep varies (or its first one) and this case's value of it."""
    fields = [f.name for f in dataclasses.fields(spec.params)
              if isinstance(getattr(spec.params, f.name), (int, float)) or hasattr(getattr(spec.params, f.name), "unit")]
    if not fields:
        return "", 0.0
    siblings = [s.params for s in all_specs if s.name == spec.name and s.preset is None]
    key = next((k for k in fields if len({getattr(p, k) for p in siblings}) > 1), fields[0])
    val = getattr(spec.params, key)
    unit = getattr(val, "unit", "")
    return (f"{key} [{unit}]" if unit else key), float(getattr(val, "value", val))


def sweep_columns(spec, all_specs) -> dict:
    """sweep_key and sweep_value of a case (:func:`sweep_of`)."""
    key, value = sweep_of(spec, all_specs)
    return {"sweep_key": key, "sweep_value": value}


def mean_defined(values) -> float:
    """The mean of the defined values (UNDEFINED when none is)."""
    values = [x for x in values if metrics.defined(x)]
    return float(np.mean(values)) if values else metrics.UNDEFINED


def median_defined(values) -> float:
    """The median of the defined values (UNDEFINED when none is)."""
    values = [x for x in values if metrics.defined(x)]
    return float(np.median(values)) if values else metrics.UNDEFINED
