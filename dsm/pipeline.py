"""The kit's stages, one public function each, in the order of the data flow.

    scene -> G-buffer -> light set-up (receivers, exact reference) -> view -> map (the layers
    the plan names) -> stored format -> visibility per scheme and filter -> classification
    and metrics

The runner, the Mitsuba plugins (``dsm_plugins``), ``dsm bench``, the notebooks and every
later capability call these and nothing private. Stage by stage::

    import dsm.pipeline as pl
    sd = pl.load_scene(pl.scene_spec({"builtin": "plane_box"}), (256, 256))
    gb = pl.gbuffer(sd)
    setup = pl.light_setup(sd, gb, pl.LightSpec("directional", direction=(-0.4, -0.3, -1.0)), "sun")
    view = pl.make_view(setup.light, 1024, pl.points_np(setup.p), sd.bbox)
    smap = pl.store(pl.build_map(sd.scene, view, pl.needs_of([spec])), "float32")
    rx = pl.receivers(smap.view, setup, sd.diagonal)
    v, _ = pl.visibility(spec, rx, smap)
    m = pl.metrics(v.numpy(), setup, pl.own_surface(spec, rx, smap, smap).numpy())
"""
from __future__ import annotations

from dataclasses import dataclass

import functools
import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .maps import cascades as cascades_mod
from .truth import area, reference
from .scenes import exact_frame, load as scenes
from .scenes.emitters import emitter_lights, emitter_to_light
from .lights import area_surface
from .scenes.spec import parse_scene
from .maps import formats, lookup, shadowmap, smrt
from .scenes import spawn
from . import lights, prefilter, schemes
from .core import timing
from .truth import oracle as oracle_mod
from .scenes import gbuffer as gbuffer_mod
from .maps import shrink as shrink_mod
from .truth import leak as leak_mod, metrics as metrics_mod
from .truth import cascades as cascade_metrics_mod
from .truth import virtual as virtual_metrics_mod
from .scenes.camera import Camera
from .scenes.closedness import shape_closedness
from .core.env import exact_math
from .config.read import parse_scheme
from .maps.receiver import Receiver
from .core.types import VARIANTS, ConfigError, LightSpec, SchemeSpec

# ---------------------------------------------------------------- config

def prepare(config, variant: str | None = None, threads: int | None = None):
    """A Config from a Config, a dict of tables or a TOML path, checked before any work: every
    scene readable, something to run, the estimated memory within this machine's. Sets the
    Mitsuba variant (and Dr.Jit's thread count, before any scene loads). Raises ConfigError
    (one line naming file, key and choices; NothingToRun), SetupError or TypeError."""
    from .config import read as cfgmod
    from .core import env
    from .config import plan as planmod
    config = cfgmod.coerce(config)
    cfgmod.check_runnable(config)            # NothingToRun: every scene an absent optional file
    if variant is not None and variant not in VARIANTS:     # an argument's mistake, as the TOML key's
        raise ConfigError("<arguments>", "variant", f"unknown variant {variant!r}", VARIANTS, got=variant)
    env.use_variant(variant or config.variant, threads)
    scenes.check(config)                     # unreadable scenes
    planmod.check_memory(planmod.make(config), config.source)
    return config


# ---------------------------------------------------------------- scenes

load_scene = scenes.load                  # (SceneSpec, camera resolution or None) -> SceneData
load_checked_scene = scenes.load_checked  # the same, taken from prepare's check where it loaded it last
scene_from_mitsuba = scenes.from_mitsuba  # an already loaded mi.Scene (the plugins' entry)
emitter_light = emitter_to_light           # a Mitsuba emitter as a LightSpec (None: not mapped)
scene_magnitude = reference.scene_magnitude
exact_visibility = reference.visibility   # (scene, interactions, light, magnitude) -> (V*, occluder distance)
area_emitter_lights = emitter_lights  # (mi.Scene, area LightSpec) -> one area light per area emitter
area_geometry = area_surface.geometry              # (area LightSpec, mi.Scene) -> its surface (sampling)
area_sample_visibility = area.sample_visibility   # one area sample's visibility per interaction


def scene_spec(table: dict, source: str = "<pipeline>"):
    """One ``[[scene]]`` table (no sweeps) as a SceneSpec."""
    specs = parse_scene(table, source, "scene", None)
    if len(specs) != 1:
        raise ConfigError(source, "scene", "give one value per parameter (no sweeps)")
    return specs[0]


def scheme_specs(table: dict, source: str = "<pipeline>", where: str = "scheme") -> list:
    """The scheme instances of one ``[[scheme]]`` table (its list-valued parameters swept)."""
    return parse_scheme(table, source, where, schemes.REGISTRY, schemes.PRESETS)


def scheme_spec(table: dict, source: str = "<pipeline>", where: str = "scheme") -> SchemeSpec:
    """One ``[[scheme]]`` table (a name and its parameters, or a preset; no sweeps)."""
    specs = scheme_specs(table, source, where)
    if len(specs) != 1:
        raise ConfigError(source, where, "give one value per parameter (no sweeps)")
    return specs[0]


# ---------------------------------------------------------------- G-buffer

def gbuffer(sd, width: int | None = None, height: int | None = None, sensor=None):
    """One primary hit per camera pixel through pixel centres (the scene's sensor and its film's
    size unless given)."""
    sensor = sensor or sd.sensor
    W, H = (int(x) for x in sensor.film().size())
    if sd.centre is None:
        gb = gbuffer_mod.cast(sd.scene, sensor, width or W, height or H)
    else:
        # far from the origin: hits in the frame centred on the scene, world positions from them
        pose = sd.camera_pose if sensor is sd.sensor else None
        gb = gbuffer_mod.cast(sd.exact, exact_frame.sensor_in(sensor, sd.centre, pose), width or W, height or H)
        gb.p = exact_frame.to_world(gb.p, sd.centre)
        dr.eval(gb.p)
    gb.camera = pinhole_camera(sensor)
    return gb


# ---------------------------------------------------------------- light set-up and reference

@dataclass
class LightSetup:
    """Receivers and exact visibility of one scene from one light."""
    label: str
    light: object                 # LightSpec
    pixels: np.ndarray            # pixel index of each receiver
    p: object                     # receiver positions (mi.Point3f), normals, shapes
    n: object
    shape: np.ndarray
    v_star: np.ndarray
    occluder_dist: np.ndarray
    exclusions: dict
    reference_ms: float
    si: object = None
    back_p: object = None         # hit pixels facing away from the light (attached shadow), inside its domain
    back_n: object = None
    ref: object = None            # area lights: the Monte Carlo reference (area.Reference); v_star = V* >= 0.5

    @functools.cached_property
    def max_abs_coordinate(self) -> float:
        """The receivers' largest absolute coordinate in the map's frame (NaN without receivers):
        what every case on them shares for its float32 headroom (dsm.maps.headroom), read once."""
        if self.p is None or not len(self.pixels):
            return math.nan
        return float(np.abs(points_np(self.p)).max())
    camera: Camera | None = None  # the pinhole camera of the G-buffer; None: not a perspective sensor

    @property
    def v_frac(self):
        """V* as a fraction of the light's area (area lights), else None."""
        return None if self.ref is None else self.ref.v

    @property
    def reference_rays(self) -> int:
        """Shadow rays the reference cast: one per receiver, or the area light's samples."""
        return len(self.pixels) if self.ref is None else self.ref.rays

    def backfacing_inside(self, view):
        """(positions, normals) of the back-facing pixels inside ``view``, or (None, None)."""
        if self.back_p is None:
            return None, None
        keep = view.inside(self.back_p).numpy().astype(bool)
        if not keep.any():
            return None, None
        idx = mi.UInt32(np.flatnonzero(keep).astype(np.uint32))
        p, n = dr.gather(mi.Point3f, self.back_p, idx), dr.gather(mi.Vector3f, self.back_n, idx)
        dr.eval(p, n)
        return p, n

    def subset(self, keep: np.ndarray) -> "LightSetup":
        """The receivers ``keep`` selects; the others count as outside the view's domain."""
        if keep.all():
            return self
        ex = dict(self.exclusions)
        ex["n_excluded_outside"] += int((~keep).sum())
        ref = None if self.ref is None else self.ref.take(keep)
        if not keep.any():
            return LightSetup(self.label, self.light, self.pixels[keep], None, None, self.shape[keep],
                              self.v_star[keep], self.occluder_dist[keep], ex, self.reference_ms, ref=ref,
                              camera=self.camera)
        idx = mi.UInt32(np.flatnonzero(keep).astype(np.uint32))
        p, n = dr.gather(mi.Point3f, self.p, idx), dr.gather(mi.Vector3f, self.n, idx)
        si = None if self.si is None else dr.gather(mi.SurfaceInteraction3f, self.si, idx)
        dr.eval(p, n, si)
        return LightSetup(self.label, self.light, self.pixels[keep], p, n, self.shape[keep], self.v_star[keep],
                          self.occluder_dist[keep], ex, self.reference_ms, si, ref=ref, camera=self.camera)


def make_view(light, R, receivers_world, bbox, kind=None, cascade=None, sensor=None, scale: float = 1.0):
    """The view of ``light`` at resolution R. A directional light with ``cascade`` (a CascadeSpec)
    gets a cascaded view for the camera ``sensor`` (dsm.maps.cascades; ``scale``: the scene's, which
    multiplies the layout's distances), else one map fitted to the receivers; an area light
    its view from its centre (:func:`dsm.lights.area_surface.make_view`)."""
    return lights.get(light.type).make_view(light, R, receivers_world, bbox, kind, cascade, sensor, scale)


def is_positional(light) -> bool:
    """Whether ``light`` sits at a point (its shadow rays end there; dsm.lights)."""
    return lights.get(light.type).POSITIONAL


def light_setup(sd, gb, light, label, repeats: int = 0, seed: int = 7) -> LightSetup:
    """Receivers of one light (hit pixels facing it, inside its domain), their exact visibility
    (an area light: :func:`area_setup`) and the camera that sees them (perspective sensors)."""
    setup = _light_setup(sd, gb, light, label, repeats, seed)
    setup.camera = gb.camera
    return setup


def pinhole_camera(sensor):
    """The pinhole camera of a perspective sensor (dsm.scenes.camera.Camera; at its film's size), None for any other."""
    return Camera.from_sensor(sensor) if "x_fov" in mi.traverse(sensor) else None


def _light_setup(sd, gb, light, label, repeats: int = 0, seed: int = 7) -> LightSetup:
    """:func:`light_setup` without the camera."""
    if lights.is_soft(light):
        return area_setup(sd, gb, light, label, repeats, seed)
    light_x, bbox_x = exact_side(sd, light)
    p_all, n_all = gb.si.p, gb.n                  # the exact frame's hit points
    probe = make_view(light_x, 1, np.zeros((1, 3)), bbox_x, "cube")   # a point light lights every direction
    to_light = probe.to_light(p_all)
    facing = (dr.dot(n_all, to_light) > 0).numpy().astype(bool)
    inside = probe.inside(p_all).numpy().astype(bool) if lights.get(light.type).POSITIONAL else np.ones_like(facing)
    hit = gb.hit
    mask = hit & facing & inside
    pixels = np.flatnonzero(mask).astype(np.uint32)
    exclusions = {"n_pixels": int(mask.size), "n_excluded_nohit": int((~hit).sum()),
                  "n_excluded_backfacing": int((hit & ~facing).sum()),
                  "n_excluded_outside": int((hit & facing & ~inside).sum())}
    back = np.flatnonzero(hit & ~facing & inside).astype(np.uint32)
    back_p = back_n = None
    if len(back):
        bidx = mi.UInt32(back)
        back_p, back_n = dr.gather(mi.Point3f, gb.p, bidx), dr.gather(mi.Vector3f, gb.n, bidx)
        dr.eval(back_p, back_n)
    if len(pixels) == 0:      # nothing faces this light: an empty case, no zero-sized kernels
        empty = np.zeros(0)
        return LightSetup(label, light, pixels, None, None, empty.astype(np.uint32), empty.astype(bool),
                          empty, exclusions, 0.0, None, back_p, back_n)
    idx = mi.UInt32(pixels)
    si = dr.gather(mi.SurfaceInteraction3f, gb.si, idx)
    p = dr.gather(mi.Point3f, gb.p, idx)
    n = dr.gather(mi.Vector3f, gb.n, idx)
    magnitude = scene_magnitude(bbox_x)
    (vis, dist), t = timing.measure_kernel(lambda: reference.visibility(sd.exact, si, light_x, magnitude), repeats)
    dr.eval(p, n)
    return LightSetup(label, light, pixels, p, n, gb.shape.numpy()[pixels], vis.numpy().astype(bool),
                      dist.numpy(), exclusions, t.ms, si, back_p, back_n)


def exact_side(sd, light) -> tuple:
    """(light, bounding box) in the frame the exact side is traced in (:mod:`dsm.scenes.exact_frame`)."""
    if sd.centre is None:
        return light, sd.bbox
    return exact_frame.light_in(light, sd.centre), exact_frame.bbox_in(sd.bbox, sd.centre)


def area_setup(sd, gb, light, label, repeats: int = 0, seed: int = 7) -> LightSetup:
    """Receivers of an area light (hit pixels with part of the light above their tangent plane,
    in front of a one-sided light) and the Monte Carlo reference V* (:mod:`dsm.truth.area`). No
    attached-shadow pixels are kept (``backface_lit_rate`` is undefined for area lights)."""
    light_x, bbox_x = exact_side(sd, light)
    geom = area_surface.geometry(light_x, sd.exact)
    hit = gb.hit
    idx_hit = np.flatnonzero(hit).astype(np.uint32)
    keep = np.zeros(hit.shape, bool)
    if len(idx_hit):
        ih = mi.UInt32(idx_hit)
        ph, nh = points_np(dr.gather(mi.Point3f, gb.si.p, ih)), points_np(dr.gather(mi.Vector3f, gb.n, ih))
        keep[idx_hit] = geom.receivers(ph, nh)
    pixels = np.flatnonzero(keep).astype(np.uint32)
    exclusions = {"n_pixels": int(keep.size), "n_excluded_nohit": int((~hit).sum()),
                  "n_excluded_backfacing": int((hit & ~keep).sum()), "n_excluded_outside": 0}
    if len(pixels) == 0:
        empty = np.zeros(0)
        return LightSetup(label, light, pixels, None, None, empty.astype(np.uint32), empty.astype(bool), empty,
                          exclusions, 0.0, ref=area.empty_reference(light.confidence))
    idx = mi.UInt32(pixels)
    si = dr.gather(mi.SurfaceInteraction3f, gb.si, idx)
    p = dr.gather(mi.Point3f, gb.p, idx)
    n = dr.gather(mi.Vector3f, gb.n, idx)
    dr.eval(p, n)
    magnitude = scene_magnitude(bbox_x)
    # timed once (cold): repeating a Monte Carlo reference costs as much again each time
    out, t = timing.measure(lambda: (area.reference(sd.exact, si, n, geom, magnitude, seed, light.min_samples,
                                                    light.max_samples, light.tolerance,
                                                    confidence=light.confidence, replicates=light.replicates),), 0)
    ref = out[-1]
    return LightSetup(label, light, pixels, p, n, gb.shape.numpy()[pixels], ref.v >= 0.5,
                      np.full(len(pixels), np.inf), exclusions, t.ms, si, ref=ref)


def closedness(sd) -> tuple[list, list]:
    """(closed, reason) per shape of a scene (index of ``scene.shapes()``): detected from the
    mesh, or set by the config's ``closed`` override. A closed mesh wound inward (a room) is
    open to culling: its solid is everything outside it, so a light outside (a spot above a
    room) would see through its back faces."""
    over = dict(sd.closed_override)
    closed, reasons = [], []
    for name, shape in zip(sd.shape_names, sd.scene.shapes()):
        c, why = shape_closedness(shape)
        if c and "wound inward" in why:
            c, why = False, why + "; culling treats it as open"
        if name in over:
            c, why = over[name], f"set by the config (detected: {why})"
        closed.append(c)
        reasons.append(why)
    return closed, reasons


def points_np(p) -> np.ndarray:
    """A Dr.Jit point array as an (n, 3) float64 numpy array."""
    return np.stack([np.asarray(c, np.float64) for c in (p.x.numpy(), p.y.numpy(), p.z.numpy())], axis=1)


# ---------------------------------------------------------------- map

def cull_modes(culling: str, closed) -> np.ndarray | None:
    """Per-shape culling of a map build (None for ``none``), given each shape's closedness."""
    return None if culling == "none" else shadowmap.cull_modes_for(culling, closed)


spawn_extents = spawn.shape_extents     # scene -> per-shape error extents, once per scene for build_map


def build_map(scene, view, needs=(), culling: str = "none", closed=None, tile: int | None = None, extents=None):
    """The map of ``view``: z1 and shape ids, plus the layers ``needs`` names (slope, z2),
    under ``culling`` (``closed``: per-shape closedness, see :func:`closedness`; ``extents``:
    :func:`spawn_extents` of the scene, else computed in each layered build)."""
    return shadowmap.build(scene, view, set(needs), culling, map_cull_modes(scene, view, culling, closed), tile, extents)


def map_cull_modes(scene, view, culling: str = "none", closed=None):
    """Per-shape CULL_* of a map of ``view`` under ``culling`` (None: nothing culled), an area
    light's own luminaire (``view.exclude``) stepped over."""
    modes = cull_modes(culling, closed) if culling != "none" else None
    exclude = view.exclude      # an area light's own luminaire: stepped over
    if exclude:
        modes = np.zeros(len(scene.shapes()), np.uint32) if modes is None else np.array(modes, np.uint32)
        modes[list(exclude)] = shadowmap.CULL_ALL
    return modes


def shrunk_scene(scene, distance: float):
    """A copy of ``scene`` whose meshes moved ``distance`` inward along their welded vertex normals
    (``[map] shrink``, :mod:`dsm.maps.shrink`): what a map is cast against, the rest using ``scene``."""
    return shrink_mod.shrunk_scene(scene, distance)


store = formats.store                     # (map, format) -> the map as that format stores it


# ---------------------------------------------------------------- schemes and lookup

scheme_module = schemes.get
needs_of = schemes.needs_of
preset_for_light = schemes.preset_for_light     # (spec, light type) -> the combined instance of a preset
culling_of = schemes.culling_of


def receivers(view, setup, diagonal: float) -> Receiver:
    """The set-up's receivers as a view sees them (depth in the view's one depth function)."""
    return Receiver.make(view, setup.p, setup.n, diagonal, setup.camera)


def visibility(spec: SchemeSpec, rx: Receiver, smap, filt: str = "nearest", seed: int = 7):
    """(V in [0, 1] per receiver, shape index of the nearest texel) of one scheme instance (on a
    cascaded view with a blend band, mixed with the next cascade's over the band; ``smrt``: shadow-map
    ray tracing, :mod:`dsm.maps.smrt`, which reads the receiver's own cascade)."""
    if smrt.is_smrt(filt):
        return smrt.visibility(schemes.get(spec.name), spec.params, rx, smap, smrt.settings(filt), seed)
    if rx.view.blend > 0:
        return cascades_mod.blended_visibility(schemes.get(spec.name), spec.params, rx, smap, filt, seed)
    return lookup.visibility(schemes.get(spec.name), spec.params, rx, smap, filt, seed)


def own_surface(spec: SchemeSpec | None, rx: Receiver, smap, built):
    """Per receiver (lazy Bool), whether the nearest texel the lookup of ``spec`` reads on ``smap``
    holds a first hit on the receiver's own surface (:func:`dsm.maps.lookup.on_own_surface`: the
    acne split's ``self``); ``built``: the float32 map ``smap`` was stored from; ``spec`` None: a
    pre-filtered instance's (no shift, ``smap`` the built map)."""
    scheme = None if spec is None else schemes.get(spec.name)
    return lookup.nearest_on_own_surface(scheme, None if spec is None else spec.params, rx, smap, built)


def pcss_blockers_found(spec: SchemeSpec, rx: Receiver, smap) -> np.ndarray:
    """Per receiver (numpy bool), whether PCSS's blocker search on ``smap`` finds a blocker."""
    return lookup.pcss_found(schemes.get(spec.name), spec.params, rx, smap).numpy().astype(bool)


# ---------------------------------------------------------------- pre-filtered maps (dsm.prefilter)

moment_key = prefilter.build_key          # (MomentSpec, format) -> what its moment map depends on


def moment_count(spec) -> int:
    """Moments per texel one pre-filtered instance stores."""
    return prefilter.get(spec.name).count(spec.params)


def moment_map(spec, smap, fmt: str, fine=None):
    """The MomentMap of one pre-filtered instance from a depth map's z1 (its float32 build), stored in
    ``fmt``; ``fine``: the map of supersampled_map, whose z1 the moments average where ``spec.samples`` > 1."""
    z1 = (smap if spec.samples == 1 else fine).z1.numpy()
    return prefilter.build(spec, z1, smap.view, fmt)


def supersampled_map(scene, view, samples: int, extents=None):
    """The first-layer map of ``view`` with ``samples`` x ``samples`` rays a texel (the same frame
    and extent at ``samples`` times its resolution): the rays a supersampled moment map averages."""
    return build_map(scene, prefilter.supersampled_view(view, samples), (), "none", None, None, extents)


def moment_visibility(spec, rx: Receiver, mmap, smap):
    """(continuous V per receiver, shape index of the nearest texel of ``smap``) of one
    pre-filtered instance on its MomentMap."""
    return prefilter.visibility(spec, rx, mmap), lookup.nearest_tap(rx, smap).shape


cascade_metrics = cascade_metrics_mod.case_metrics     # (view, rx, v, V*) -> (columns, per-cascade rows, curve, faces)
virtual_metrics = virtual_metrics_mod.case_metrics     # (virtual view, built map, faces) -> its columns
split_distances = cascades_mod.split_distances


def plane_misses(spec: SchemeSpec, rx: Receiver, smap):
    """Per receiver (lazy Bool), whether its texel ray misses its tangent plane; None without a plane."""
    return lookup.plane_misses(schemes.get(spec.name), spec.params, rx, smap)


def plane_fallbacks(spec: SchemeSpec, rx: Receiver, smap) -> int:
    """Receivers whose texel ray misses their tangent plane (receiver_plane, adaptive)."""
    return lookup.plane_fallbacks(schemes.get(spec.name), spec.params, rx, smap)


# ---------------------------------------------------------------- oracles (nearest lookup)

@dataclass
class Thresholds:
    """Per receiver of one map and stored format: the smallest float32 world bias ``tau`` and
    texel-unit bias ``kappa`` that light it (nearest texel, no shift), and that texel's index."""
    tau: np.ndarray
    kappa: np.ndarray
    texel: np.ndarray
    z1: np.ndarray
    depth: np.ndarray
    texel_world: np.ndarray


def thresholds(rx: Receiver, smap) -> Thresholds:
    """The oracles' thresholds of the receivers ``rx`` (built for the stored format of
    ``smap``) against ``smap``'s nearest texels, in the lookup's float32 comparison."""
    tap = lookup.nearest_tap(rx, smap)
    dr.eval(tap.z1, tap.idx, rx.depth, rx.texel_world)
    z1 = np.asarray(tap.z1.numpy(), np.float32)
    d = np.asarray(rx.depth.numpy(), np.float32)
    tw = np.asarray(rx.texel_world.numpy(), np.float32)
    tau = oracle_mod.thresholds(z1, d)
    return Thresholds(tau, oracle_mod.texel_thresholds(z1, d, tw, tau), tap.idx.numpy().astype(np.int64), z1, d, tw)


def oracles(th: Thresholds, v_star: np.ndarray, lam: float = 1.0) -> dict:
    """The world, texel and per-texel oracles at ``lam`` (see :mod:`dsm.truth.oracle`): ``row`` (best
    b and k, objectives and rates), ``curve_world``, ``curve_texel`` and ``wrong`` (per receiver,
    wrong under the per-texel oracle: the resolution's share of the errors)."""
    return oracle_mod.oracles(th.tau, th.kappa, v_star, th.texel, lam)


# ---------------------------------------------------------------- light leaking

def deep_in_shadow(sd, setup: LightSetup, texel_world: np.ndarray, k_texels: float):
    """Per receiver of ``setup``: whether it lies at least ``k_texels`` texels (``texel_world``:
    a texel's size at each receiver) inside the exact shadow on its own surface (:mod:`dsm.truth.leak`,
    traced on the exact side); False where V* lights it. None for an area light: a soft shadow's
    inside is not one ray's."""
    if setup.ref is not None:
        return None
    out = np.zeros(len(setup.pixels), bool)
    idx = np.flatnonzero(~np.asarray(setup.v_star, bool))
    if not len(idx) or setup.si is None:
        return out
    light_x, bbox_x = exact_side(sd, setup.light)
    sel = mi.UInt32(idx.astype(np.uint32))
    p_exact = points_np(dr.gather(mi.Point3f, setup.si.p, sel))
    normal = points_np(dr.gather(mi.Vector3f, setup.n, sel))
    out[idx] = leak_mod.deep_in_shadow(sd.exact, p_exact, normal, np.asarray(setup.shape)[idx],
                                       np.asarray(texel_world)[idx], k_texels, light_x, scene_magnitude(bbox_x))
    return out


# ---------------------------------------------------------------- classification and metrics

CLASS_COLORS = metrics_mod.CLASS_COLORS
CLASS_NAMES = metrics_mod.CLASS_NAMES
classify = metrics_mod.classify
split = metrics_mod.split                 # (v, V*, wrong under the per-texel oracle) -> resolution / bias counts


def metrics(v: np.ndarray, setup: LightSetup, own: np.ndarray, seam=None, has_seams=None) -> dict:
    """Counts and rates of one case (undefined values are NaN; ``own``: per receiver, its nearest
    texel's hit on its own surface, :func:`own_surface`); an area light's soft metrics
    (:func:`dsm.truth.metrics.soft`) replace the hard ones they redefine."""
    m = metrics_mod.compute(v, setup.v_star, own, setup.occluder_dist, seam, has_seams)
    if setup.ref is not None:
        m.update(metrics_mod.soft(v, setup.ref.hits, setup.ref.samples, setup.ref.half, own))
    return m
