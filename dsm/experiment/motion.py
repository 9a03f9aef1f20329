"""Motion: camera and light paths over frames, and shimmering measured as a number.

A ``[[motion]]`` path moves the camera (``dolly``: a translation; ``pan``: the view turning
about the camera's up; ``orbit``: the camera turning about its target; ``keyframes``: positions
and targets interpolated linearly) and/or turns a directional light (``turn``: its direction
about ``light_axis``) or moves a spot or point light (``move``: by ``light_offset``;
``keyframes``: along ``light_keys``) over ``frames`` frames. Each frame re-fits its views as an
engine would (its own G-buffer, receivers and view; a cascaded layout re-fitted to the frame's
camera; a spot's or point light's views re-fitted to its position).

**Fixed points**: ``points`` points on the scene's surfaces, sampled once in world space
(area-weighted over every mesh triangle, the experiment's seed), each the hit of a short
probe ray onto its triangle so it carries a surface interaction for its exact shadow ray.
In a frame, a fixed point counts where the camera sees it (inside the frustum, the first hit
of the ray from the camera) and its visible side faces the light: a receiver of that frame.

**Flicker** per pair of consecutive frames (t, t + 1), over the fixed points that are
receivers in both and whose exact visibility V* is the same in both:

- ``flicker_rate``: the fraction whose shadow-map class (lit: V >= 0.5) changes;
- ``flicker_within_rate`` / ``flicker_change_rate``: the same over the points whose cascade is
  the same in both frames / differs (cascaded maps; a single map is one cascade);
- ``flicker_magnitude``: the mean |V(t+1) - V(t)| (meaningful with PCF);
- ``flicker_ever``: the fraction of the points eligible in at least one pair that flicker at
  least once.

The metric counts what a viewer sees as shimmer: a surface point whose shadow state toggles
while the truth does not. Its limits: it samples points, not pixels, so a flicker on a surface
no fixed point lies on is missed (the count sets the resolution); a point whose V* changes
(a moving light crossing a shadow edge) is left out of that pair, so a light path measures the
flicker of the points away from the moving edges; and a change that is correct (a map that was
wrong becoming right) counts as flicker too, since a viewer sees it the same way.
"""
from __future__ import annotations

import dataclasses
import math

import drjit as dr
import mitsuba as mi
import numpy as np

from ..case import Case, MapContext, Where, cost as case_cost, evaluate, row as case_row
from ..case.evaluation import lookup
from ..maps import headroom, shadowmap
from ..scenes import spawn
from .. import lights, pipeline
from ..truth import metrics
from ..scenes.camera import sensor_at
from ..core import timing
from ..scenes.camera import Camera
from ..report.figures import frames_path
from ..core.labels import params_label
from ..report.sections import cache as cache_report
from . import cache
from .casters import KeptTables, Mover
from . import page_cache, texel_recast
from .motion_display import GifFrames, shown_frames, v_image

# ---------------------------------------------------------------- paths

def _rotate(v, axis, deg):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    t = math.radians(deg)
    v = np.asarray(v, float)
    return v * math.cos(t) + np.cross(a, v) * math.sin(t) + a * (a @ v) * (1 - math.cos(t))


def camera_path(spec, base: Camera, bbox, scale: float = 1.0, offset=(0.0, 0.0, 0.0)) -> list:
    """[(origin, target, up)] per frame (world units; the base camera's pose moved along the path)."""
    centre = 0.5 * (np.asarray(bbox[0], float) + np.asarray(bbox[1], float))
    reach = max(float((centre - base.origin) @ base.forward), 10.0 * base.near)
    o0, t0, up = base.origin, base.origin + base.forward * reach, base.up
    out = []
    for i in range(spec.frames):
        f = i / (spec.frames - 1)
        if spec.camera == "dolly":
            d = np.asarray(spec.offset, float) * scale * f
            out.append((o0 + d, t0 + d, up))
        elif spec.camera == "pan":
            out.append((o0, o0 + _rotate(t0 - o0, up, spec.angle * f), up))
        elif spec.camera == "orbit":
            out.append((t0 + _rotate(o0 - t0, up, spec.angle * f), t0, up))
        elif spec.camera == "keyframes":
            keys = [(np.asarray(p, float) * scale + offset, np.asarray(t, float) * scale + offset) for p, t in spec.keys]
            x = f * (len(keys) - 1)
            k = min(int(x), len(keys) - 2)
            w = x - k
            out.append((keys[k][0] * (1 - w) + keys[k + 1][0] * w, keys[k][1] * (1 - w) + keys[k + 1][1] * w, up))
        else:
            out.append((o0, t0, up))
        o, tg, u = out[-1]
        fwd = np.subtract(tg, o)
        if np.linalg.norm(np.cross(fwd, u)) <= 1e-6 * np.linalg.norm(fwd) * np.linalg.norm(u):
            raise ValueError(f"motion {spec.label!r}: frame {i}'s camera looks along its up {tuple(map(float, u))} "
                             "(or from its target); move the keyframes")
    return out


def light_path(spec, light, scale: float = 1.0, offset=(0.0, 0.0, 0.0)) -> list:
    """The light of each frame: a directional light's direction turned about light_axis (``turn``);
    a spot or point light translated by ``light_offset`` (``move``; a spot keeps its direction) or
    along ``light_keys`` (``keyframes``: positions, and a spot's targets when given, interpolated
    linearly; positions follow the scene's ``scale`` and ``offset`` as a [[light]]'s do). A light
    of another type than the path moves stays still."""
    out = []
    follows = lights.get(light.type).MOTION          # the paths this light's type follows
    moving = light.position is not None
    p0 = np.asarray(light.position, float) if moving else None
    for i in range(spec.frames):
        f = i / (spec.frames - 1)
        if spec.light not in follows:
            out.append(light)
        elif spec.light == "turn":
            d = _rotate(light.direction, spec.light_axis, spec.light_angle * f)
            out.append(dataclasses.replace(light, direction=tuple(float(c) for c in d)))
        elif spec.light == "move" and moving:
            d = np.asarray(spec.light_offset, float) * scale * f
            out.append(_moved(light, p0 + d, None if light.target is None else np.asarray(light.target, float) + d))
        elif spec.light == "keyframes" and moving:
            keys = [(np.asarray(p, float) * scale + offset, None if tg is None else np.asarray(tg, float) * scale + offset)
                    for p, tg in spec.light_keys]
            x = f * (len(keys) - 1)
            k = min(int(x), len(keys) - 2)
            w = x - k
            pos = keys[k][0] * (1 - w) + keys[k + 1][0] * w
            if keys[k][1] is not None and light.type == "spot":
                tgt = keys[k][1] * (1 - w) + keys[k + 1][1] * w
            else:                                   # no targets: a spot keeps its direction
                tgt = None if light.target is None else np.asarray(light.target, float) + (pos - p0)
            out.append(_moved(light, pos, tgt))
        else:
            out.append(light)
    return out


def _moved(light, position, target):
    as_tuple = lambda v: None if v is None else tuple(float(c) for c in v)
    if light.type == "spot" and target is not None and light.target is None:   # a spot given by direction
        return dataclasses.replace(light, position=as_tuple(position), direction=as_tuple(np.subtract(target, position)))
    return dataclasses.replace(light, position=as_tuple(position), target=as_tuple(target))


# ---------------------------------------------------------------- fixed points

@dataclasses.dataclass
class FixedPoints:
    """The fixed points on the scene's surfaces: interactions, positions, wound normals, shapes and triangles."""
    si: object           # mi.SurfaceInteraction3f
    p: object            # mi.Point3f
    n: object            # geometric normal as the mesh winds it
    shape: np.ndarray
    prim: np.ndarray
    table: object         # spawn.shape_table of the scene (None on Embree), made once for every frame

    @property
    def count(self) -> int:
        """The number of fixed points."""
        return len(self.shape)


def sample_points(scene, count: int, seed: int, diagonal: float) -> FixedPoints:
    """``count`` points area-weighted over every mesh triangle (numpy, seeded), each snapped to
    its triangle by a probe ray (kept where the probe hits that triangle)."""
    tris = []
    for k, sh in enumerate(scene.shapes()):
        if not sh.is_mesh():
            continue
        v = np.array(sh.vertex_positions_buffer(), np.float64).reshape(-1, 3)
        f = np.array(sh.faces_buffer(), np.int64).reshape(-1, 3)
        tris.append((k, v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]))
    a = np.concatenate([0.5 * np.linalg.norm(np.cross(b - a_, c - a_), axis=1) for _, a_, b, c in tris])
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(a), size=count, p=a / a.sum())
    v0 = np.concatenate([t[1] for t in tris])[pick]
    v1 = np.concatenate([t[2] for t in tris])[pick]
    v2 = np.concatenate([t[3] for t in tris])[pick]
    r1, r2 = rng.random(count), rng.random(count)
    s = np.sqrt(r1)
    p = v0 * (1 - s)[:, None] + v1 * (s * (1 - r2))[:, None] + v2 * (s * r2)[:, None]
    n = np.cross(v1 - v0, v2 - v0)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    delta = 1e-4 * diagonal
    o = p + n * delta
    ray = mi.Ray3f(mi.Point3f(*(mi.Float(o[:, c].astype(np.float32)) for c in range(3))),
                   mi.Vector3f(*(mi.Float(-n[:, c].astype(np.float32)) for c in range(3))))
    pi = scene.ray_intersect_preliminary(ray, coherent=False)
    si = pi.compute_surface_interaction(ray)
    dr.eval(si)
    ok = si.is_valid().numpy().astype(bool)
    ok &= np.asarray(pi.t.numpy()) < 2 * delta
    idx = mi.UInt32(np.flatnonzero(ok).astype(np.uint32))
    si = dr.gather(mi.SurfaceInteraction3f, si, idx)
    table = spawn.shape_table(scene)
    shape = np.asarray(dr.gather(mi.UInt32, spawn.hit_shape(pi, pi.is_valid(), table), idx).numpy(), np.int64)
    prim = np.asarray(dr.gather(mi.UInt32, pi.prim_index, idx).numpy(), np.int64)
    dr.eval(si)
    return FixedPoints(si, mi.Point3f(si.p), mi.Vector3f(si.n), shape, prim, table)


def points_seen(scene, fp: FixedPoints, cam: Camera):
    """(seen by the camera, the normal turned toward the camera) of each fixed point."""
    p = pipeline.points_np(fp.p)
    q = p - cam.origin
    depth = q @ cam.forward
    x, y = q @ cam.left, q @ cam.up
    in_frustum = (depth > cam.near) & (depth < cam.far) & (np.abs(x) <= cam.tan_x * depth) & \
        (np.abs(y) <= cam.tan_y * depth)
    dist = np.linalg.norm(q, axis=1)
    o = mi.Point3f(*(dr.opaque(mi.Float, float(c)) for c in cam.origin))
    d = dr.normalize(fp.p - o)
    pi = scene.ray_intersect_preliminary(mi.Ray3f(o + d * 0, d), coherent=False)
    t = np.asarray(pi.t.numpy(), np.float64)
    # the same triangle (shape and primitive index together), not the same shape: merged meshes hold
    # many surfaces in one shape
    same = (np.asarray(spawn.hit_shape(pi, pi.is_valid(), fp.table).numpy(), np.int64) == fp.shape) & \
        (np.asarray(pi.prim_index.numpy(), np.int64) == fp.prim)
    seen = in_frustum & pi.is_valid().numpy().astype(bool) & (same | (t >= dist * (1 - 1e-4)))
    oc = mi.Vector3f(*(dr.opaque(mi.Float, float(c)) for c in cam.origin))
    n = fp.n * dr.sign(dr.dot(fp.n, oc - fp.p))
    dr.eval(n)
    return seen, n


def points_frame(scene, fp: FixedPoints, cam: Camera, light, view, magnitude: float, vstar=None):
    """One frame of the fixed points: (receiver: seen, facing the light and inside the view; exact
    visibility V*; the normal turned toward the camera). V* depends on the light alone (``vstar``:
    the one computed for this light in an earlier frame)."""
    seen, n_cam = points_seen(scene, fp, cam)
    n_np = pipeline.points_np(n_cam)
    if not lights.get(light.type).POSITIONAL:
        facing = n_np @ (-np.asarray(light.direction, float) / np.linalg.norm(light.direction)) > 0
    else:
        facing = ((np.asarray(light.position, float) - pipeline.points_np(fp.p)) * n_np).sum(1) > 0
    if vstar is None:
        vstar = np.asarray(pipeline.exact_visibility(scene, fp.si, light, magnitude)[0].numpy(), bool)
    inside = view.inside(fp.p).numpy().astype(bool)
    return seen & facing & inside, vstar, n_cam


# ---------------------------------------------------------------- flicker

def flicker(v, vstar, eligible, face) -> tuple:
    """Per pair of consecutive frames and overall, from per-frame arrays (frames, points):
    V, V*, receiver (eligible), cascade. Returns (per-pair dicts, flicker_ever)."""
    F = len(v)
    pairs, ever, seen = [], np.zeros(v.shape[1], bool), np.zeros(v.shape[1], bool)
    for t in range(1, F):
        e = eligible[t - 1] & eligible[t] & (vstar[t - 1] == vstar[t])
        flip = e & ((v[t - 1] >= 0.5) != (v[t] >= 0.5))
        same = face[t - 1] == face[t]
        rate = lambda num, den: float(num) / float(den) if den else metrics.UNDEFINED
        pairs.append({"n_pairs_eligible": int(e.sum()), "n_flicker": int(flip.sum()),
                      "flicker_rate": rate(flip.sum(), e.sum()),
                      "n_eligible_within": int((e & same).sum()), "flicker_within_rate": rate((flip & same).sum(),
                                                                                             (e & same).sum()),
                      "n_eligible_change": int((e & ~same).sum()), "flicker_change_rate": rate((flip & ~same).sum(),
                                                                                               (e & ~same).sum()),
                      "flicker_magnitude": float(np.abs(v[t] - v[t - 1])[e].mean()) if e.any() else metrics.UNDEFINED})
        ever |= flip
        seen |= e
    return pairs, (float(ever[seen].mean()) if seen.any() else metrics.UNDEFINED)


# ---------------------------------------------------------------- the frame loop

def _view_signature(view, frame_only: bool = False) -> bytes:
    """What a map's texels depend on: the frame, extents, offsets, depth origin and far bound
    (``frame_only``: what every page of a paged view depends on, its pages and their levels' places left out)."""
    parts = [np.asarray(view.origin_np, np.float32), np.asarray(view.axes_np, np.float32),
             np.float32([view.far, view.near, view.resolution])]
    parts += view.frame_signature_arrays() if frame_only else view.signature_arrays()
    return b"".join(p.tobytes() for p in parts)


@dataclasses.dataclass
class SceneFrames:
    """What every motion path over one scene shares."""
    data: object              # dsm.scenes.data.SceneData
    base: Camera              # the scene's camera, which the paths move
    points: FixedPoints       # the most points any path asks for
    closed: list              # per-shape closedness (culling)
    extents: object           # per-shape error extents (map builds)
    magnitude: float          # the scene's magnitude (exact shadow rays)
    moved: object = None      # KeptTables: the spawn tables of each moved geometry, shared by the paths


@dataclasses.dataclass
class PathFrames:
    """One [[motion]] path over one light: the camera pose and the light of each frame, and its fixed points."""
    motion: object            # MotionSpec
    poses: list               # (origin, target, up) per frame
    lights: list              # LightSpec per frame
    points: FixedPoints


def run_scene(runner, scene, maps, closed, extents):
    """The frame loop of every [[motion]] path over one scene's maps of the plan (called by the
    runner for a config with [[motion]]; ``scene``: its SceneRun): rows of metrics.csv (per-case
    means) into the runner's sink and of frames.csv into its record, an animated error image per
    case (images/<scene>_<light>/<case>_frames.gif, drawn in the report's time from the GifFrames
    kept in the run record: dsm.experiment.motion_display; none with [report] images = "none")."""
    cfg, data = runner.cfg, scene.data
    fp = sample_points(data.scene, max(mo.points for mo in cfg.motion), cfg.seed, data.diagonal)
    shared = SceneFrames(data, Camera.from_sensor(data.sensor), fp, closed, extents,
                         pipeline.scene_magnitude(data.bbox), KeptTables(pipeline.spawn_extents))
    movers = [Mover(data, mo.casters, mo.frames, cfg.source, f"motion[{i}]")      # the shapes' names checked first
              for i, mo in enumerate(cfg.motion)]
    for mo, mover in zip(cfg.motion, movers):
        pts = _first_points(fp, min(mo.points, fp.count))
        poses = camera_path(mo, shared.base, data.bbox, data.scale, data.offset)
        for m in maps:
            if m.light_index >= len(scene.lights):
                continue
            path = PathFrames(mo, poses, light_path(mo, scene.lights[m.light_index], data.scale, data.offset), pts)
            try:
                _run_map(runner, shared, path, m, mover)
            finally:                 # the scene is shared by the next path and map: its casters back in place
                mover.restore()


def _first_points(fp: FixedPoints, use: int) -> FixedPoints:
    """The first ``use`` fixed points (a path asking for fewer than the scene sampled)."""
    if use >= fp.count:
        return fp
    idx = mi.UInt32(np.arange(use, dtype=np.uint32))
    return FixedPoints(dr.gather(mi.SurfaceInteraction3f, fp.si, idx), dr.gather(mi.Point3f, fp.p, idx),
                       dr.gather(mi.Vector3f, fp.n, idx), fp.shape[:use], fp.prim[:use], fp.table)


@dataclasses.dataclass
class _CaseFrames:
    """One motion case's frames as they come: the fixed points' V, V*, eligibility and cascade,
    the frame rows, class images, evaluated metrics and lookup times."""
    v: list = dataclasses.field(default_factory=list)
    vstar: list = dataclasses.field(default_factory=list)
    eligible: list = dataclasses.field(default_factory=list)
    face: list = dataclasses.field(default_factory=list)
    frames: list = dataclasses.field(default_factory=list)
    images: list = dataclasses.field(default_factory=list)       # the shown frames' class images
    v_images: list = dataclasses.field(default_factory=list)     # the shown frames' V per camera pixel
    cache_images: list = dataclasses.field(default_factory=list)  # the shown frames' ghosts and missing shadows
    metrics: list = dataclasses.field(default_factory=list)
    lookup_ms: list = dataclasses.field(default_factory=list)
    costs: list = dataclasses.field(default_factory=list)        # each frame's costs in counts (dsm.case.cost)


@dataclasses.dataclass
class _MapFrames:
    """What the frames of one planned map share while camera, light or projection stay: the
    G-buffer, the receivers' set-up, the fixed points' V*, the map; and what they add up."""
    scene: SceneFrames
    path: PathFrames
    map_plan: object
    cases: dict                                               # Case (its id given when written) -> _CaseFrames
    gb: dict = dataclasses.field(default_factory=dict)        # {camera pose: G-buffer}
    setup: dict = dataclasses.field(default_factory=dict)     # {(camera pose, light): LightSetup}
    vstar: dict = dataclasses.field(default_factory=dict)     # {light: the fixed points' V*}
    signature: object = None                                  # the last map's projection
    smap: object = None
    moments: dict = dataclasses.field(default_factory=dict)   # {moment key: MomentMap} of the current map
    moments_ms: dict = dataclasses.field(default_factory=dict)  # {moment key: [build ms per map built]}
    built: list = dataclasses.field(default_factory=list)     # per frame: the map was built (not reused)
    build_ms: list = dataclasses.field(default_factory=list)
    tight: dict = dataclasses.field(default_factory=lambda: headroom.headroom(math.nan, math.nan))
    shown: frozenset = frozenset()                             # the frames the case's GIF shows
    mover: object = None                                      # the path's moving casters (dsm.experiment.casters)
    policy: object = None                                     # the path's cache rule (dsm.experiment.cache)
    cast_frame: int = 0                                       # the frame the kept map was cast at, whole
    map_frame: int = 0                                        # the frame whose casters the kept map holds
    partial: bool = False                                     # the policy re-casts the texels moved casters touch
    recast: list = dataclasses.field(default_factory=list)    # per frame: texels cast over the map's texels
    geometry: tuple = ()                                      # the frame's casters' translations
    map_geometry: object = None                               # the casters' translations the kept map was cast with
    bbox: tuple = ()                                          # the scene's bounds over the path (views fit to them)
    extents: object = None                                    # the frame's per-shape spawn extents (map builds)
    fresh: object = None                                      # this frame's map where the kept one is stale, else None
    pages: object = None                                      # a virtual map's page cache (dsm.experiment.page_cache)
    page_keys: list = dataclasses.field(default_factory=list)  # the last frame's pages (View.page_keys)
    frame_ms: list = dataclasses.field(default_factory=list)  # per frame: its build's kernel time (frame_build_ms)


def _run_map(runner, shared: SceneFrames, path: PathFrames, m, mover: Mover):
    """Every frame of a path on planned map ``m`` (its casters placed per frame by ``mover``), then
    one case row per scheme instance, filter and format (its counts summed over the frames, rates
    and flicker averaged)."""
    cfg = runner.cfg
    specs = [pipeline.preset_for_light(s, path.lights[0].type) for s in m.specs]
    keys = [(s, filt, fmt) for s in specs for filt in cfg.map.filter for fmt in cfg.map.format]
    keys += [(s, s.filter, fmt) for s in m.moments for fmt in cfg.map.format]     # pre-filtered instances
    state = _MapFrames(shared, path, m, {Case("", *k): _CaseFrames() for k in keys},
                       shown=frozenset(shown_frames(len(path.poses))), mover=mover,
                       policy=cache.rule(path.motion.cache), partial=cache.partial_recast(path.motion.cache),
                       extents=shared.extents, pages=page_cache.PagePool(),
                       bbox=mover.swept_bbox() if mover.moving else shared.data.bbox)
    for t in range(len(path.poses)):
        if mover.place(t):           # a caster moved: the continuation rays' triangle tables follow it
            moved = any(mover.key(t))
            state.extents = shared.moved.at(mover.signature(t), shared.data.scene) if moved else shared.extents
        state.geometry = mover.key(t)
        _run_frame(runner, state, t)
    for case, frames in state.cases.items():
        _write_case(runner, state, dataclasses.replace(case, id=runner.next_case()), frames)


def _frame_view(state: _MapFrames, t: int):
    """(camera, G-buffer, receivers' set-up inside the view, view) of frame ``t``."""
    data, m, light = state.scene.data, state.map_plan, state.path.lights[t]
    o, tg, up = state.path.poses[t]
    pose_key = (tuple(np.round(o, 12)), tuple(np.round(tg, 12)), tuple(np.round(up, 12)))
    sensor = sensor_at(state.scene.base, o, tg, up)
    cam = Camera.from_sensor(sensor)
    pose_key = (pose_key, state.geometry)        # ... and the casters
    if pose_key not in state.gb:                 # the G-buffer is shared while the camera and the casters stay
        state.gb = {pose_key: pipeline.gbuffer(data, sensor=sensor)}
    gb = state.gb[pose_key]
    if (pose_key, light) not in state.setup:     # receivers and their V*: shared while camera, casters and light stay
        state.setup = {(pose_key, light): pipeline.light_setup(data, gb, light, m.light)}
    setup = state.setup[(pose_key, light)]
    rpts = pipeline.points_np(setup.p) if setup.p is not None else np.zeros((0, 3))
    view = pipeline.make_view(light, m.resolution, rpts, state.bbox, m.view, m.cascade, sensor, data.scale)
    setup = setup.subset(view.inside(setup.p).numpy().astype(bool)) if setup.p is not None else setup
    return cam, gb, setup, view


def _cast(state: _MapFrames, view):
    """The frame's map cast as the plan says (its layers, culling and tile) on the frame's geometry."""
    m, shared = state.map_plan, state.scene
    return pipeline.build_map(shared.data.scene, view, set(m.needs), m.culling,
                              shared.closed if m.culling != "none" else None, m.tile, state.extents)


def _frame_map(runner, state: _MapFrames, view):
    """The frame's ShadowMap: cast again where the cache policy says (its view's projection changed,
    or under ``none`` a caster moved), else the last one re-viewed; where the map kept is stale,
    this frame's map is cast too (untimed, ``state.fresh``) to count ghosts and missing shadows."""
    if view.virtual and state.path.motion.cache != "none":     # a page cache: the policy acts on pages
        return _frame_pages(runner, state, view)
    sig = _view_signature(view)
    view_changed, geometry_changed = sig != state.signature, state.geometry != state.map_geometry
    state.fresh = None
    if state.smap is None or state.policy(view_changed, geometry_changed, len(state.built) - state.cast_frame):
        state.smap = _timed_cast(runner, state, view)
        state.moments = {}                        # a new first layer: new moments
        state.build_ms.append(state.frame_ms[-1])
        state.built.append(True)
        state.map_geometry, state.cast_frame = state.geometry, len(state.built) - 1
        state.map_frame = state.cast_frame
        state.recast.append(1.0)
    else:
        state.smap = dataclasses.replace(state.smap, view=view)
        state.built.append(False)
        state.recast.append(0.0)
        state.frame_ms.append(0.0)
        if geometry_changed:
            state.fresh = _cast(state, view)
        if geometry_changed and state.partial:    # re-cast where a caster was or is: the map kept is right again
            _recast_touched(state, view)
    state.signature = sig
    return state.smap


def _recast_touched(state: _MapFrames, view):
    """The kept map's texels whose rays meet a moved caster's bounds (at the map's frame or this
    one) taken from this frame's cast (dsm.experiment.texel_recast); the fraction re-cast recorded."""
    t = len(state.built) - 1
    mask = texel_recast.touched(view, state.mover.bounds(state.map_frame, True) + state.mover.bounds(t, True))
    state.smap = texel_recast.compose(state.smap, state.fresh, mask)
    state.moments = {}                            # a new first layer: new moments
    # a caster flagged static left its old texels: the map is this frame's no more (a fresh map every frame)
    state.map_geometry = None if state.mover.any_flagged else state.geometry
    state.map_frame = t
    state.recast[-1] = float(mask.mean())
    # composed from an untimed whole cast: not a partial cast's cost (nothing re-cast: nothing to time)
    state.frame_ms[-1] = metrics.UNDEFINED if mask.any() else 0.0


def _timed_cast(runner, state: _MapFrames, view):
    """The map of ``view`` cast, its kernel time appended to ``state.frame_ms``, its rays to the record."""
    def build():
        """The map built: its arrays, then the ShadowMap."""
        sm = _cast(state, view)
        return (*shadowmap.arrays(sm), sm)       # the arrays, so the timing waits for them
    out, tm = timing.measure_kernel(build, 1)      # a frame's build once, in kernel time (as a still map's)
    state.frame_ms.append(tm.ms)
    runner.record.add_rays({"map_texel": out[-1].rays.get("map_texel", 0)})
    return out[-1]


def _frame_pages(runner, state: _MapFrames, view):
    """A virtual map's frame under a page cache (dsm.experiment.page_cache): the pages the policy or the pool
    says cast (timed, a map of those pages alone), the others kept; where a kept page was cast with the casters
    elsewhere, this frame's whole map is cast too (untimed, ``state.fresh``) to count ghosts and missing shadows."""
    t, pool = len(state.built), state.pages
    sig = _view_signature(view, frame_only=True)
    if sig != pool.signature:
        pool.reset(sig)
    cast = page_cache.plan(pool, view, t, state.geometry, state.policy, state.partial,
                           lambda f: state.mover.bounds(f, True))
    whole = bool(cast.all())
    part = _timed_cast(runner, state, view if whole else view.with_pages(view.pages[cast])) if cast.any() else None
    if not cast.any():
        state.frame_ms.append(0.0)
    state.fresh = _cast(state, view) if page_cache.stale(pool, view, cast, state.geometry) else None
    keys = view.page_keys()
    if cast.any() or keys != state.page_keys:     # another map: new moments
        state.moments = {}
    state.smap = page_cache.compose(pool, view, cast, part, t, state.geometry,
                                      part if part is not None else state.smap)
    if whole:
        state.build_ms.append(state.frame_ms[-1])
    state.built.append(whole)
    state.recast.append(float(cast.mean()))
    state.page_keys = keys
    return state.smap


def _frame_moments(state: _MapFrames, spec, fmt: str) -> tuple:
    """(MomentMap, None) of pre-filtered instance ``spec`` on the frame's map, built (timed) once
    per map and moment key; its build time is kept per key (a motion case's is their median)."""
    key = pipeline.moment_key(spec, fmt)
    if key not in state.moments:
        def build():
            """The moment map's arrays (evaluated by the clock) and the map."""
            mm = pipeline.moment_map(spec, state.smap, fmt)
            return (*mm.b, mm)
        out, tm = timing.measure(build, 0)
        state.moments[key] = out[-1]
        state.moments_ms.setdefault(key, []).append(tm.ms)
    return state.moments[key], None


def _where(state: _MapFrames) -> Where:
    """The planned map's place in the plan, as its cases' rows name it."""
    m = state.map_plan
    return Where(state.scene.data.label, m.light, m.view, m.resolution, m.texels, m.culling,
                 m.cascade.label if m.cascade else "")


def _frame_context(runner, state: _MapFrames, t: int) -> tuple:
    """(the frame's MapContext, its camera): view, map and receivers of frame ``t`` (a lookup timed
    once, the counts and the leak split as a still case's)."""
    cfg, data = runner.cfg, state.scene.data
    cam, gb, setup, view = _frame_view(state, t)
    smap = _frame_map(runner, state, view)
    stored = {fmt: pipeline.store(smap, fmt) for fmt in cfg.map.format}
    has_rx = setup.p is not None and len(setup.pixels)
    receivers = {fmt: pipeline.receivers(sm.view, setup, data.diagonal) if has_rx else None
                 for fmt, sm in stored.items()}
    ctx = MapContext(_where(state), data, gb, setup, view, smap, stored, receivers, cfg.seed, 1,
                     frozenset({"leak"}) if cfg.map.leak_split else frozenset(), leak_texels=cfg.map.leak_texels,
                     moments=lambda spec, fmt: _frame_moments(state, spec, fmt))
    return ctx, cam


def _fresh_context(state: _MapFrames, ctx: MapContext):
    """The frame's context on this frame's map (``state.fresh``) where the kept map is stale, else None."""
    if state.fresh is None:
        return None
    fresh = state.fresh
    stored = {fmt: pipeline.store(fresh, fmt) for fmt in ctx.stored}
    return dataclasses.replace(ctx, depth_map=fresh, stored=stored,
                               moments=lambda spec, fmt: (pipeline.moment_map(spec, fresh, fmt), None))


def cache_errors(v_cached: np.ndarray, v_fresh: np.ndarray) -> dict:
    """Ghosts (shadowed by the cached map where this frame's map says lit: V >= 0.5) and missing
    shadows (lit where this frame's map shadows), with their rates over the receivers this frame's
    map leaves lit and shadowed (undefined where there are none)."""
    lit_c, lit_f = v_cached >= 0.5, v_fresh >= 0.5
    ghost, missing = int((~lit_c & lit_f).sum()), int((lit_c & ~lit_f).sum())
    n_lit, n_shadowed = int(lit_f.sum()), int((~lit_f).sum())
    rate = lambda num, den: num / den if den else metrics.UNDEFINED
    return {"n_ghost": ghost, "n_missing": missing, "ghost_rate": rate(ghost, n_lit),
            "missing_rate": rate(missing, n_shadowed)}


def cache_image(shape, pixels: np.ndarray, v_cached, v_fresh) -> np.ndarray:
    """Per camera pixel, 1 where the receiver there is a ghost, 2 a missing shadow (:func:`cache_errors`), else 0."""
    lit_c, lit_f = np.asarray(v_cached) >= 0.5, np.asarray(v_fresh) >= 0.5
    out = np.zeros(shape[0] * shape[1], np.uint8)
    out[np.asarray(pixels)[~lit_c & lit_f]] = cache_report.GHOST
    out[np.asarray(pixels)[lit_c & ~lit_f]] = cache_report.MISSING
    return out.reshape(shape)


def _run_frame(runner, state: _MapFrames, t: int):
    """Frame ``t``: its view and map, then every case evaluated at the frame's receivers
    (dsm.case.evaluate) and looked up at the fixed points, into ``state.cases``."""
    ctx, cam = _frame_context(runner, state, t)
    fresh_ctx = _fresh_context(state, ctx)
    pts, light = state.path.points, state.path.lights[t]
    elig, vstar_pts, n_cam = points_frame(state.scene.data.scene, pts, cam, light, ctx.view, state.scene.magnitude,
                                          state.vstar.get((light, state.geometry)))
    state.vstar = {(light, state.geometry): vstar_pts}   # the fixed points' V*: shared while light and casters stay
    if state.mover.moving:       # a point sampled on a moving caster stays where it was sampled: left out
        elig = elig & ~np.isin(pts.shape, list(state.mover.shapes()))
    rx_pts = {fmt: pipeline.receivers(sm.view, dataclasses.replace(ctx.setup, p=pts.p, n=n_cam), ctx.scene.diagonal)
              for fmt, sm in ctx.stored.items()}
    first = ctx.receivers[runner.cfg.map.format[0]]
    if first is not None:         # the map's float32 headroom at this frame's receivers (dsm.maps.headroom)
        hr = headroom.headroom(ctx.setup.max_abs_coordinate, float(np.median(first.texel_world.numpy())))
        if math.isnan(state.tight["texel_f32_steps"]) or hr["texel_f32_steps"] < state.tight["texel_f32_steps"]:
            state.tight = hr
    for case, frames in state.cases.items():
        result = evaluate(ctx, case)
        frames.v.append(np.asarray(lookup(ctx, case)(rx_pts[case.format])[0].numpy(), np.float64))
        frames.face.append(np.asarray(rx_pts[case.format].face.numpy(), np.int64))
        frames.vstar.append(vstar_pts)
        frames.eligible.append(elig)
        if runner.sink.images_mode != "none" and t in state.shown:    # [report] images = "none": no GIF either
            frames.images.append(result.classes)          # the GIF's frames, drawn in the report's time
            if runner.sink.images_mode == "all":
                frames.v_images.append(v_image(result.classes.shape, ctx.setup.pixels, result.v))
        mt = result.measured
        v_fresh = result.v if fresh_ctx is None else evaluate(fresh_ctx, case).v
        stale = cache_errors(np.asarray(result.v), np.asarray(v_fresh))
        if state.mover.moving and runner.sink.images_mode != "none" and t in state.shown:
            frames.cache_images.append(cache_image(result.classes.shape, ctx.setup.pixels, result.v, v_fresh))
        frames.metrics.append(mt)
        frames.lookup_ms.append(result.lookup.ms if ctx.receivers[case.format] is not None else math.nan)
        frames.costs.append(case_cost.costs(ctx, case))
        frames.frames.append({"frame": t, "map_built": state.built[-1], "n_points_visible": int(elig.sum()),
                              "n_receivers": mt["n_receivers"], "acne_rate": mt["acne_rate"],
                              "peterpan_rate": mt["peterpan_rate"], "error_rate": mt["error_rate"],
                              "cache": state.path.motion.cache, **stale,
                              "recast_fraction": state.recast[-1],
                              "frame_build_ms": _frame_build_ms(state)})


def _frame_build_ms(state: _MapFrames) -> float:
    """The frame's build time: its whole cast's, 0 where the map was kept as it was, a virtual map's re-cast
    pages' cast, undefined where texels were re-cast (composed from an untimed whole cast: not their cost)."""
    return state.frame_ms[-1]


def _write_case(runner, state: _MapFrames, case: Case, frames: _CaseFrames):
    """One motion case: its frames into frames.csv, its row (frames summed and averaged), its GIF."""
    mo, m = state.path.motion, state.map_plan
    pairs, ever = flicker(np.array(frames.v), np.array(frames.vstar), np.array(frames.eligible),
                          np.array(frames.face))
    ident = case_row.identity(_where(state), case)
    meta = {"motion": mo.label, **{k: ident[k] for k in FRAME_KEYS}}
    for fr, pr in zip(frames.frames, [{}] + pairs):          # frame t carries the pair (t - 1, t)
        runner.record.motion_frames.append({**meta, **fr, **pr})
    measured = _over_frames(frames.metrics)
    if runner.cfg.map.leak_split:
        measured.update(_leak_columns(frames.metrics))
        ms = state.moments_ms.get(pipeline.moment_key(case.spec, case.format)) if case.prefiltered else None
        measured.update(case_row.map_kind_columns(case, float(np.median(ms)) if ms else metrics.UNDEFINED))
    measured.update(_flicker_columns(pairs, ever))
    measured.update(_cache_columns(mo.cache, frames.frames))
    costs = {"maps_built": int(sum(state.built)), "build_ms": float(np.median(state.build_ms)),
             "build_first_ms": float("nan"), "lookup_ms": case_row.median_defined(frames.lookup_ms),
             "reference_ms": float("nan"), "sweep_key": "", "sweep_value": float("nan"), "texel_size": float("nan"),
             **state.tight, **case_cost.over_frames(frames.costs)}
    row = case_row.row({**ident, "motion": mo.label, "frames": mo.frames}, measured, costs)
    if frames.images:
        runner.record.motion_gifs.append(_gif_frames(state, ident, frames))
    runner.case_done(row, {"what": f"case {case.id}", "scene": ident["scene"], "light": m.light, "view": m.view,
                           "scheme": case.spec.name, "params": case.spec.label, "resolution": m.resolution,
                           "status": "ok" if row["n_receivers"] else "empty"})


FRAME_KEYS = ("case", "scene", "light", "cascade_layout", "scheme", "params", "resolution", "filter", "format")
SUMMED = ("n_receivers", "n_gt_lit", "n_gt_shadowed", "n_acne", "n_acne_self", "n_acne_edge", "n_peterpan")
AVERAGED = ("acne_rate", "peterpan_rate", "error_rate", "mean_abs_error")


def _over_frames(frame_metrics: list) -> dict:
    """A motion case's measured columns: the last frame's, with the counts summed over the frames
    and the rates their mean."""
    out = dict(frame_metrics[-1])
    for k in SUMMED:
        out[k] = int(sum(x[k] for x in frame_metrics))
    for k in AVERAGED:
        out[k] = case_row.mean_defined([x[k] for x in frame_metrics])
    return out


def _flicker_columns(pairs: list, ever: float) -> dict:
    """A motion case's flicker: each rate the mean over the pairs of frames, and flicker_ever."""
    out = {k: case_row.mean_defined([p[k] for p in pairs])
           for k in ("flicker_rate", "flicker_magnitude", "flicker_within_rate", "flicker_change_rate")}
    return {**out, "flicker_ever": ever}


def _cache_columns(policy: str, frame_rows: list) -> dict:
    """A motion case's cache: its policy, the ghost and missing rates' mean over the frames and
    their worst frame (undefined where no frame defines them), the mean fraction of texels re-cast."""
    worst = lambda vals: max(v for v in vals if metrics.defined(v)) if any(map(metrics.defined, vals)) \
        else metrics.UNDEFINED
    out = {"cache": policy, "recast_fraction": float(np.mean([f["recast_fraction"] for f in frame_rows]))}
    for k in ("ghost_rate", "missing_rate"):
        vals = [f[k] for f in frame_rows]
        out[k], out[f"{k}_worst"] = case_row.mean_defined(vals), worst(vals)
    return out


def _leak_columns(frame_metrics: list) -> dict:
    """A motion case's leak split: counts summed over the frames, rates their mean."""
    out = {}
    for k in metrics.LEAK_COLUMNS:
        vals = [x[k] for x in frame_metrics]
        out[k] = int(sum(vals)) if k.startswith("n_") else case_row.mean_defined(vals)
    return out


def _gif_frames(state: _MapFrames, ident: dict, frames: _CaseFrames) -> GifFrames:
    """What the case's GIF needs, kept for the report (dsm.experiment.motion_display draws it)."""
    m, path = state.map_plan, state.path
    index = sorted(state.shown)
    instance = f"{ident['scheme']} {ident['preset'] or params_label(ident['params'])}".strip()
    view = f"{m.view} {ident['cascade_layout']}".strip()         # a cascaded map: its layout too
    title = f"case {ident['case']}: {instance}, {view} R = {m.resolution}, {ident['filter']}, {ident['format']}"
    return GifFrames(frames_path(ident), state.scene.data.label, m.light, path.motion.label, title,
                     len(path.poses), index, [path.poses[t] for t in index], [path.lights[t] for t in index],
                     frames.images, frames.v_images or None, frames.cache_images or None)
