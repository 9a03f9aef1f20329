"""An experiment derived from a scene (``dsm run SCENE.xml``): one rule per decision, each a function
of the measured facts (:mod:`dsm.config.scene_facts`) that returns its config tables and one line
saying what it chose and why. :func:`derive` applies them all; :func:`toml_text` writes the result
as ``derived.toml`` (a config a user can edit and run) with the reasons as comments, and
:func:`record` as ``derivation.json`` (the report's first screen reads it).

The thresholds are stated here, each once: cascades beyond ``CASCADE_RATIO`` (the largest over the
smallest receiver footprint in texels), the precision axis where a texel spans fewer than
``headroom.FEW_STEPS`` float32 steps at the scene's coordinates, stored formats where a unorm
step exceeds ``FORMAT_TEXELS`` texels' depth.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from .. import lights as light_types
from .. import schemes
from ..maps import headroom
from ..schemes import presets
from .scene_facts import AREA_EMITTER, MEASURE_R, POINT_VIEWS, SceneFacts

CASCADE_RATIO = 8.0        # one map cannot hold footprints further apart than this (largest / smallest, texels)
CASCADES = 4               # the cascades derived where it cannot
FORMAT_TEXELS = 1.0        # a unorm step beyond this many texels' depth makes the stored format an axis
MIN_R, MAX_R = 32, 8192    # the derived resolution's bounds (its twice stays within the kit's 16384)
DEFAULT_R = 512            # where no receiver is seen (the kit's [map] resolution default)
TWO_LAYER = ("midpoint", "dual", "second_depth")    # read a second layer (or cull): need closed casters
SOFT_FILTERS = ("nearest", "pcss")                   # an area light's techniques on a depth map
LEFT_OUT = {"combined": "its default is no bias; the engines' presets are its instances"}


@dataclass(frozen=True)
class Choice:
    """One rule's outcome: what it chose and why, in one line each."""
    rule: str
    choice: str
    reason: str


@dataclass(frozen=True)
class Derivation:
    """The derived config's tables, the choices behind them and the quantities measured."""
    tables: dict
    choices: tuple
    measured: dict
    offered: tuple = ()     # (table, line, reason): written commented out in derived.toml


def derive(facts: SceneFacts) -> Derivation:
    """The experiment for the scene of ``facts``: every rule applied, in the order the report lists them."""
    light_tables, c_lights = lights_rule(facts)
    views, c_views = views_rule(facts)
    filters, c_soft = soft_rule(facts)
    medians = light_medians(facts)
    per_light, c_res = resolution_rule(medians)
    rs = resolutions(per_light)
    texels = [texel_at(facts, light, r) for light, (_, r) in per_light.items()]
    texel = min(texels) if texels else math.nan       # the finest: the most demanding of float32
    cascades, c_casc = cascades_rule(facts)
    two_layer, c_cull = culling_rule(facts)
    shrink, c_shrink = shrink_rule(facts, texel)
    precision, c_prec = precision_rule(facts.max_abs_coordinate, texel)
    formats, c_fmt = formats_rule(facts, {k: r for k, (_, r) in per_light.items()})
    scheme_tables, c_schemes = schemes_rule(facts, two_layer)
    m = {"resolution": list(rs)}
    m.update({"view": list(views)} if views else {})
    m.update({"filter": list(filters)} if len(filters) > 1 else {})
    m.update({"format": list(formats)} if len(formats) > 1 else {})
    m.update({"cascades": cascades} if cascades else {})
    scene = {"file": str(facts.path), **({"precision": list(precision)} if len(precision) > 1 else {})}
    tables = {"experiment": {"name": experiment_name(facts.path)}, "scene": [scene], "light": light_tables,
              "map": m, "scheme": scheme_tables}
    offered = (("map", f"shrink = {shrink:.6g}", c_shrink.reason),) if shrink else ()
    measured = measured_quantities(facts, medians, per_light, texel)
    return Derivation(tables, (c_lights, c_views, c_soft, c_res, c_casc, c_cull, c_shrink, c_prec, c_fmt, c_schemes),
                      measured, offered)


def experiment_name(path) -> str:
    """The experiment's name: the scene file's stem in plain characters."""
    return re.sub(r"[^A-Za-z0-9_.-]", "_", path.stem) or "scene"


def lights_rule(facts: SceneFacts) -> tuple:
    """[[light]] tables: the scene's own point, spot and directional emitters, and its area emitters
    (each luminaire a Monte Carlo reference); a scene without either gets the kit's default light."""
    tables, said = [], []
    if facts.delta_lights or not facts.area_lights:
        tables.append({"type": "scene"})
        said.append(", ".join(f"{l.type}" for l in facts.delta_lights) or f"the kit's default ({facts.default_light})")
    if facts.area_lights:
        tables.append(dict(AREA_EMITTER))
        said.append(f"{len(facts.area_lights)} area emitter{'s' if len(facts.area_lights) > 1 else ''} "
                    "(the Monte Carlo reference)")
    why = "the scene's emitters" if facts.delta_lights or facts.area_lights else "no emitter in the file"
    return tables, Choice("lights", "; ".join(said), f"{why}: each light as the file gives it")


def views_rule(facts: SceneFacts) -> tuple:
    """[map] view: both point-light views where a point light is present (a spot is perspective, a
    directional light orthographic: their one view each, nothing to write)."""
    kinds = {}
    for v in facts.views:
        kinds.setdefault(v.light_type, []).append(v.kind)
    said = "; ".join(f"{t}: {' and '.join(dict.fromkeys(k))}" for t, k in kinds.items())
    points = any(tuple(light_types.get(l.type).views(POINT_VIEWS, l.shape)) == POINT_VIEWS
                 for l in facts.delta_lights)
    return (POINT_VIEWS if points else ()), Choice("views", said or "none", "each light type's views: directional "
                                                   "orthographic, spot perspective, point cube and dual paraboloid")


def soft_rule(facts: SceneFacts) -> tuple:
    """[map] filter: PCSS beside the nearest lookup only where an area emitter casts soft shadows."""
    if not facts.area_lights:
        return ("nearest",), Choice("soft shadows", "none (nearest lookups)", "no area emitter: every shadow is "
                                    "hard, so no Monte Carlo reference, PCSS or pre-filtered kind")
    return SOFT_FILTERS, Choice("soft shadows", "Monte Carlo reference, filter " + " and ".join(SOFT_FILTERS),
                                "an area emitter casts soft shadows; the pre-filtered kinds are left out: the kit "
                                "measures them against one exact ray per receiver and refuses them beside an area light")


def light_medians(facts: SceneFacts) -> dict:
    """Per light, the median footprint (texels per pixel at MEASURE_R) over its views' receivers; NaN without one."""
    out = {}
    for v in facts.views:
        out.setdefault(v.light, []).append(v.footprint_texels)
    return {k: (float(np.median(np.concatenate(f))) if sum(map(len, f)) else math.nan) for k, f in out.items()}


def resolution_for(median_texels: float, measure_r: int = MEASURE_R) -> float:
    """The resolution at which the median receiver's pixel spans one texel (texels scale as the resolution)."""
    return measure_r / median_texels


def power_of_two(median_texels: float) -> tuple:
    """(exact resolution, the nearest power of two within MIN_R to MAX_R): one texel per pixel at the
    median receiver; (NaN, DEFAULT_R) without one."""
    if not median_texels > 0:
        return math.nan, DEFAULT_R
    exact = resolution_for(median_texels)
    return exact, int(min(MAX_R, max(MIN_R, 2 ** round(math.log2(exact)))))


def resolution_rule(medians: dict) -> tuple:
    """({light: (exact resolution, its power of two)}, the choice): per light, one texel per pixel at its
    median receiver, rounded to the nearest power of two; the config sweeps each with half and twice it."""
    per_light = {k: power_of_two(m) for k, m in medians.items()}
    said = "; ".join(f"{k}: one texel per pixel at {e:.0f}, so {r}" if e == e else f"{k}: no receiver seen, the "
                     f"kit's default {r}" for k, (e, r) in per_light.items())
    rs = resolutions(per_light)
    return per_light, Choice("resolution", ", ".join(map(str, rs)), f"{said or 'no light'} (the median receiver's "
                             f"pixel, rounded to a power of two within {MIN_R} to {MAX_R}), with half and twice it")


def resolutions(per_light: dict) -> tuple:
    """The resolutions swept: each light's power of two with half and twice it (DEFAULT_R's without a light)."""
    rs = {r for _, p in per_light.values() for r in (p // 2, p, 2 * p)}
    return tuple(sorted(rs)) or (DEFAULT_R // 2, DEFAULT_R, 2 * DEFAULT_R)


def texel_at(facts: SceneFacts, light: str, r: int) -> float:
    """The median receiver's texel width (world units) of ``light`` at resolution ``r`` over its views."""
    tw = np.concatenate([v.texel_world for v in facts.views if v.light == light] + [np.zeros(0)])
    return float(np.median(tw)) * MEASURE_R / r if len(tw) else math.nan


def footprint_ratio(footprints: np.ndarray) -> float:
    """The largest receiver footprint over the smallest (NaN without receivers)."""
    f = np.asarray(footprints, float)
    return float(f.max() / f.min()) if len(f) and f.min() > 0 else math.nan


def cascades_rule(facts: SceneFacts) -> tuple:
    """[map] cascades: CASCADES where a directional light's receivers' footprints span more than
    CASCADE_RATIO (one map cannot hold the camera's depth range); else one map."""
    ratios = {v.light: footprint_ratio(v.footprint_texels) for v in facts.views if v.kind == "orthographic"}
    wide = {k: r for k, r in ratios.items() if r > CASCADE_RATIO}
    others = [footprint_ratio(v.footprint_texels) for v in facts.views if v.kind != "orthographic"]
    said = ", ".join(f"{k} {r:.3g}" for k, r in ratios.items())
    if wide:
        return CASCADES, Choice("cascades", f"{CASCADES} cascades", f"footprint ratio (largest / smallest) {said}: "
                                f"above {CASCADE_RATIO:g}, one map cannot cover the camera's depth range (a virtual map is the "
                                "other answer: add [map.virtual])")
    note = (f" (other views {max(others):.3g}: the kit cascades directional lights only)"
            if others and max(others) > CASCADE_RATIO else "")
    return 0, Choice("cascades", "one map", f"footprint ratio (largest / smallest) {said or 'no directional light'}: "
                     f"not above {CASCADE_RATIO:g}{note}")


def culling_rule(facts: SceneFacts) -> tuple:
    """Whether the culling and two-layer schemes (TWO_LAYER) run: only where a caster is a closed mesh."""
    if facts.closed:
        return True, Choice("culling", ", ".join(TWO_LAYER) + " at their defaults",
                            f"closed meshes: {', '.join(facts.closed)} (back faces of a solid can be culled)")
    why = "; ".join(f"{n}: {w}" for n, w in facts.open[:3]) + (" ..." if len(facts.open) > 3 else "")
    return False, Choice("culling", "no culling or two-layer scheme", f"no closed mesh ({why})")


def shrink_rule(facts: SceneFacts, texel: float) -> tuple:
    """[map] shrink, offered (commented out: it is not swept, it would replace the plain map) where a
    caster is open: half a median texel, below a quarter of the thinnest closed mesh."""
    if not facts.open:
        return 0.0, Choice("shrink", "not offered", "every caster is closed")
    if facts.analytic:
        return 0.0, Choice("shrink", "not offered", f"open casters, but {', '.join(facts.analytic)} are not meshes "
                           "(caster shrinking moves mesh vertices)")
    if not texel > 0:
        return 0.0, Choice("shrink", "not offered", "no receiver seen")
    d = min(0.5 * texel, 0.25 * facts.thinnest_closed)
    return d, Choice("shrink", f"offered: shrink = {d:.3g} (commented out in derived.toml)",
                     f"open casters ({', '.join(n for n, _ in facts.open[:3])}); half a median texel ({texel:.3g}); "
                     "[map] shrink is not swept: it would replace the plain map's answer")


def precision_rule(max_abs_coordinate: float, texel: float) -> tuple:
    """[[scene]] precision: world and camera_relative where float32's step at the scene's largest
    coordinate exceeds 1/FEW_STEPS of the median texel; else world alone."""
    if not texel > 0:
        return ("world",), Choice("precision", "world", "no receiver seen: no texel to hold float32's step against")
    h = headroom.headroom(max_abs_coordinate, texel)
    step, steps = h["f32_step"], h["texel_f32_steps"]
    said = f"float32 step {step:.3g} at |x| = {max_abs_coordinate:.3g}, a texel {texel:.3g}: {steps:.3g} steps a texel"
    if steps < headroom.FEW_STEPS:
        return ("world", "camera_relative"), Choice("precision", "world and camera_relative",
                                                    f"{said}, fewer than {headroom.FEW_STEPS:g}")
    return ("world",), Choice("precision", "world", f"{said}, not fewer than {headroom.FEW_STEPS:g}")


def unorm_steps(near: float, far: float) -> dict:
    """The depth step of each unorm format over [near, far] (world units)."""
    return {"unorm16": (far - near) / (2 ** 16 - 1), "unorm24": (far - near) / (2 ** 24 - 1)}


def formats_rule(facts: SceneFacts, r: dict) -> tuple:
    """[map] format: float32, and each unorm format whose step over a view's depth range exceeds
    FORMAT_TEXELS of its median texel's depth (a texel's width at its light's resolution ``r[light]``)."""
    chosen, said = ["float32"], []
    for v in facts.views:
        texel = float(np.median(v.texel_world)) * MEASURE_R / r[v.light] if len(v.texel_world) else math.nan
        steps = unorm_steps(v.near, v.far)
        said.append(f"{v.light} {v.kind}: depth {v.far - v.near:.3g}, unorm16 step {steps['unorm16']:.3g} "
                    f"against a texel {texel:.3g}")
        chosen += [f for f, s in steps.items() if s > FORMAT_TEXELS * texel and f not in chosen]
    verdict = " and ".join(chosen) if len(chosen) > 1 else "float32 only"
    return tuple(chosen), Choice("formats", verdict, "; ".join(said) + f" (a unorm format where its step exceeds "
                                 f"{FORMAT_TEXELS:g} texel)")


def schemes_rule(facts: SceneFacts, two_layer: bool) -> tuple:
    """[[scheme]] tables: every bias scheme once at its defaults (two-layer ones only with closed
    casters) and every engine preset (each resolves to its values for each light present)."""
    names = [m.NAME for m in schemes.REGISTRY if m.NAME not in LEFT_OUT and (two_layer or m.NAME not in TWO_LAYER)]
    kept = presets.names()
    types = sorted({v.light_type for v in facts.views})
    tables = [{"name": n} for n in names] + [{"preset": p} for p in kept]
    left = [f"{n} ({why})" for n, why in LEFT_OUT.items()]
    return tables, Choice("schemes", f"{len(names)} schemes at their defaults, {len(kept)} engine presets",
                          f"every family once, so the first run answers which family; presets for "
                          f"{', '.join(types) or 'no light'} (an area light's are a spot light's); "
                          f"left out: {'; '.join(left)}")


def measured_quantities(facts: SceneFacts, medians: dict, per_light: dict, texel: float) -> dict:
    """The quantities behind the rules, per view and for the scene (derivation.json, ``--explain``)."""
    views = [{"light": v.light, "view": v.kind, "receivers": int(len(v.footprint_texels)),
              "footprint_median": _f(np.median(v.footprint_texels)) if len(v.footprint_texels) else None,
              "footprint_min": _f(v.footprint_texels.min()) if len(v.footprint_texels) else None,
              "footprint_max": _f(v.footprint_texels.max()) if len(v.footprint_texels) else None,
              "footprint_ratio": _f(footprint_ratio(v.footprint_texels)), "depth_near": _f(v.near),
              "depth_far": _f(v.far)}
             for v in facts.views]
    return {"scene": str(facts.path), "film": list(facts.film), "measure_resolution": MEASURE_R, "views": views,
            "lights": [{"light": k, "footprint_median": _f(medians[k]), "resolution_exact": _f(e), "resolution": r}
                       for k, (e, r) in per_light.items()], "texel_world_finest": _f(texel),
            "closed_meshes": list(facts.closed), "open_meshes": [n for n, _ in facts.open],
            "max_abs_coordinate": facts.max_abs_coordinate,
            "f32_step": float(np.spacing(np.float32(facts.max_abs_coordinate))), "diagonal": facts.diagonal}


def _f(x) -> float | None:
    """A float for JSON (None for NaN: undefined)."""
    x = float(x)
    return x if math.isfinite(x) else None
