"""Receivers sampled from the light, for the edge map's per-texel offsets (dsm.tune.edge_map):
``samples`` x ``samples`` rays through each texel of a light's map, every surface each ray meets
up to ``layers`` hits, each labelled by the kit's exact visibility (pipeline.light_setup).

**Why.** Where an occluder's edge crosses a texel, which side of it a receiver lies on is what a
shadow map cannot store and what the edge map's shared threshold guesses from the 3 x 3 taps. The
light's own rays through the texel say where the edge passes, for every surface under it, whatever
camera looks later: the offsets they fit are a property of the scene and light, not of a view
(Sen, Cammarano and Hanrahan 2003, *Shadow silhouette maps*, store the edge's position in each
texel for the same reason). The training cameras never enter these samples, so their errors
judge the offsets out of sample.

A hit counts where its face is toward the light (its geometric normal's side): a camera's receivers
face the light, and the light-facing side of a back face is the inside of a shell, which no camera
above a ground sees. That holds for open meshes too: the bunny's base is open, and counting the
inside of its shell (in shadow, and thin at the silhouette, where the grazing texels are) moved the
offsets of those texels: on experiments/tune_meshes.toml 47 held-out errors in trained blocks
against 39 with front faces only. A surface modelled facing away from its light gets no samples:
its receivers take the offsets other surfaces' samples fitted in their texels, and the shared
threshold where none fell. A scene far from the origin is traced in its exact frame,
as the G-buffer is, from rays made in world float32 as the map's own texel rays are."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import pipeline as pl
from ..scenes import spawn
from ..scenes.spawn import COHERENT
from ..prefilter.base import supersampled_view
from ..scenes import exact_frame
from ..scenes.gbuffer import GBuffer
from ..core.types import ConfigError
from .cases import Case

ROLE = "light"                    # the role of a light-sample case (not a camera's train or heldout)


CHUNK_RAYS = 1 << 19              # light rays traced at once, whatever the map and samples; no result depends on it
MAX_RAYS = 1 << 26                # light rays of one tune: the exact per-texel fit sorts every sample kept (a ray
                                  # keeps one a light-facing surface it meets: about one on these scenes), 150 to 200
                                  # bytes of peak memory a ray (tune.toml: 11.5 M rays, 2.3 GB), so 10 to 13 GB here


def check_budget(groups, samples: int, source: str):
    """Refuse, before the tuning, a ``samples`` whose light rays over every map exceed MAX_RAYS (ConfigError
    naming tune.bias_map.samples and the most that fits)."""
    texels = sum(g.view.n_texels for g in groups)
    if texels * samples * samples > MAX_RAYS:
        fits = int((MAX_RAYS / texels) ** 0.5)
        raise ConfigError(source, "tune.bias_map.samples", f"{samples} x {samples} light rays a texel over the maps' "
                          f"{texels} texels is {texels * samples * samples} rays, above the {MAX_RAYS} a tune traces "
                          f"(its exact per-texel fit holds every sample in memory): give samples = {fits} or fewer, "
                          "or a smaller [map] resolution")


def chunks(group, samples: int) -> list:
    """(first, count) of each chunk of the group's ``samples`` x ``samples`` rays a texel (fine texels, face then row-major)."""
    n = group.view.n_texels * samples * samples
    return [(f, min(CHUNK_RAYS, n - f)) for f in range(0, n, CHUNK_RAYS)]


def light_rays(group, samples: int, first: int, count: int) -> mi.Ray3f:
    """Rays ``first .. first + count - 1`` of ``samples`` x ``samples`` through each texel of the group's map:
    the texel centres of a view ``samples`` times finer, made in world float32 as the map's own texel rays
    are (far from the origin their origins are rounded like the map's), moved into the exact frame there."""
    ray = supersampled_view(group.view, samples).texel_rays(first, count)
    centre = group.scene_data.centre
    o = pl.points_np(ray.o) - (0.0 if centre is None else np.asarray(centre, np.float64))
    return spawn.rays_np(o, pl.points_np(ray.d))


def _seen_hits(scene, ray, table):
    """(kept lanes: hits whose face is toward the light, shape index, surface interaction, hit lanes) of one layer."""
    pi = scene.ray_intersect_preliminary(ray, coherent=COHERENT)
    si = pi.compute_surface_interaction(ray)
    valid = si.is_valid()
    shape = spawn.hit_shape(pi, valid, table).numpy()
    front = (dr.dot(si.n, -ray.d) > 0).numpy().astype(bool)
    hit = valid.numpy().astype(bool)
    return hit & front, shape, si, hit


def layer_gbuffers(group, samples: int, layers: int, first: int, count: int):
    """Per layer (the k-th surface along each light ray of one chunk) a G-buffer of its hits whose face is
    toward the light, positions in world; yielded one at a time, so a layer's arrays go once used."""
    sd = group.scene_data
    scene = sd.exact
    table = spawn.shape_table(scene)
    ray = light_rays(group, samples, first, count)
    for _ in range(layers):
        keep, shape, si, hit = _seen_hits(scene, ray, table)
        idx = np.flatnonzero(keep)
        if len(idx):
            # the kept rays traced again rather than their interactions gathered: one array per field, and
            # the same hit (a ray's hit does not depend on the rays beside it: COHERENT off)
            sub = spawn.rays_np(pl.points_np(ray.o)[idx], pl.points_np(ray.d)[idx])
            si_k = scene.ray_intersect_preliminary(sub, coherent=COHERENT).compute_surface_interaction(sub)
            n = mi.Vector3f(si_k.n)
            p = si_k.p if sd.centre is None else exact_frame.to_world(si_k.p, sd.centre)
            dr.eval(si_k, n, p)
            yield GBuffer(len(idx), 1, si_k, mi.Point3f(p), n, n, mi.UInt32(shape[idx].astype(np.uint32)),
                          np.ones(len(idx), bool))
        if not hit.any():
            break
        ray = si.spawn_ray(ray.d)
        ray.maxt = dr.select(mi.Bool(hit), ray.maxt, 0.0)     # a ray that left the scene stays out
        dr.eval(ray)


def sample_cases(group, g: int, samples: int, layers: int, tick=None):
    """The light samples of group ``g`` as tune cases (role ``light``, one per chunk and layer, yielded one
    at a time), each receiver's V* the kit's exact visibility (dsm tune's lights are hard); ``tick``
    called after each chunk."""
    sd, light = group.scene_data, group.light_spec
    smap = group.maps["none"]
    for first, count in chunks(group, samples):
        for k, gb in enumerate(layer_gbuffers(group, samples, layers, first, count)):
            s = pl.light_setup(sd, gb, light, group.light)
            if s.p is not None:
                s = s.subset(group.view.inside(s.p).numpy().astype(bool))
            if s.p is None or len(s.pixels) == 0:
                continue
            rx = pl.receivers(smap.view, s, sd.diagonal)
            dr.eval(rx.depth, rx.u_map, rx.v_map, rx.face, rx.texel_world, rx.to_light)
            yield Case(group.scene, group.light, f"light layer {k}", ROLE, g, s, rx, s.v_star.copy(),
                       mi.Bool(s.v_star), pl.thresholds(rx, smap))
        if tick:
            tick()
