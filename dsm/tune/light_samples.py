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
against 39 with front faces only. A surface modelled facing away from its light gets no samples,
so its texels keep the shared threshold. A scene far from the origin is traced in its exact frame,
as the G-buffer is."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import pipeline as pl
from ..maps import spawn
from ..maps.shadowmap import COHERENT
from ..prefilter.base import supersampled_view
from ..scenes import exact_frame
from ..scenes.gbuffer import GBuffer
from .cases import Case

ROLE = "light"                    # the role of a light-sample case (not a camera's train or heldout)


def light_rays(group, samples: int) -> mi.Ray3f:
    """``samples`` x ``samples`` rays through each texel of the group's map (world, or the exact frame of
    a scene far from the origin): the texel centres of a view ``samples`` times finer."""
    fine = supersampled_view(group.view, samples)
    ray = fine.texel_rays(0, fine.n_texels)
    centre = group.scene_data.centre
    if centre is None:
        return ray
    o = pl.points_np(ray.o) - np.asarray(centre, np.float64)
    return mi.Ray3f(mi.Point3f(*(mi.Float(o[:, k].astype(np.float32)) for k in range(3))), ray.d)


def _seen_hits(scene, ray, table):
    """(kept lanes: hits whose face is toward the light, shape index, surface interaction, hit lanes) of one layer."""
    pi = scene.ray_intersect_preliminary(ray, coherent=COHERENT)
    si = pi.compute_surface_interaction(ray)
    valid = si.is_valid()
    shape = spawn.hit_shape(pi, valid, table).numpy()
    front = (dr.dot(si.n, -ray.d) > 0).numpy().astype(bool)
    hit = valid.numpy().astype(bool)
    return hit & front, shape, si, hit


def layer_gbuffers(group, samples: int, layers: int):
    """Per layer (the k-th surface along each light ray) a G-buffer of its hits whose face is toward
    the light, positions in world; yielded one at a time, so a layer's arrays go once used."""
    sd = group.scene_data
    scene = sd.exact
    table = spawn.shape_table(scene)
    ray = light_rays(group, samples)
    for _ in range(layers):
        keep, shape, si, hit = _seen_hits(scene, ray, table)
        idx = np.flatnonzero(keep).astype(np.uint32)
        if len(idx):
            ii = mi.UInt32(idx)
            # the kept rays traced again rather than their interactions gathered: one array per field, and
            # the same hit (a ray's hit does not depend on the rays beside it: COHERENT off)
            sub = mi.Ray3f(dr.gather(mi.Point3f, ray.o, ii), dr.gather(mi.Vector3f, ray.d, ii))
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


def sample_cases(group, g: int, samples: int, layers: int):
    """The light samples of group ``g`` as tune cases (role ``light``, one per layer, yielded one at a
    time), each receiver's V* the kit's exact visibility (dsm tune's lights are hard)."""
    sd, light = group.scene_data, group.light_spec
    smap = group.maps["none"]
    for k, gb in enumerate(layer_gbuffers(group, samples, layers)):
        s = pl.light_setup(sd, gb, light, group.light)
        if s.p is not None:
            s = s.subset(group.view.inside(s.p).numpy().astype(bool))
        if s.p is None or len(s.pixels) == 0:
            continue
        rx = pl.receivers(smap.view, s, sd.diagonal)
        dr.eval(rx.depth, rx.u_map, rx.v_map, rx.face, rx.texel_world, rx.to_light)
        yield Case(group.scene, group.light, f"light layer {k}", ROLE, g, s, rx, s.v_star.copy(),
                   mi.Bool(s.v_star), pl.thresholds(rx, smap))
