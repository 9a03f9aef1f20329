"""Screen-space contact shadows: a march through the camera's depth buffer toward the light.

Engines restore the contact shadow a shadow map's bias removes (peter-panning) with a short
ray march in the camera's depth buffer after the shadow lookup: Unreal's contact shadows
(and the screen ray of its virtual shadow maps), Unity HDRP's contact shadows, Bevy's
(bevyengine/bevy#22382). This module is that step, applied after any scheme's lookup
(``[contact]``, :class:`dsm.core.types.ContactSpec`):

- the depth buffer is the G-buffer's: per camera pixel, the view depth (along the camera's
  axis) of its primary hit through the pixel centre; a pixel without a hit holds +inf;
- from each receiver ``p`` the march takes ``steps`` samples ``p + l t_k`` toward the light
  (``l``: the view's unit vector toward the light), ``t_k = length (k - j) / steps``,
  ``k = 1 .. steps``, ``j`` the receiver's jitter in ``[0, jitter)`` (0 without jitter;
  seeded from the receiver's own position, as the PCF jitter is);
- a sample projects to the pixel containing it (nearest; off screen or in front of the
  camera's plane: no occlusion). It is occluded where its view depth ``z`` is behind the
  buffer's ``z_b`` by less than ``thickness``: ``0 < z - z_b < thickness``;
- an occluded receiver is shadowed: ``V_contact = 0`` there, else the scheme's ``V``
  (every filter; the lit threshold stays ``V >= 0.5``).

The buffer holds only what the camera sees: a caster hidden from the camera (behind
another surface, or off screen) is not in it, and the march misses its shadow. The metrics
count what the step darkens wrongly (``n_contact_false``), the peter-panned receivers it
recovers (``n_contact_recovered``) and those it leaves (``n_contact_missed``).

Unity HDRP's ray grows with depth (``[contact] length_depth_scale``, off by default): the length
is ``length max(length_depth_min, length_depth_scale z_view)``, ``z_view`` the receiver's view depth
in world units, and ``thickness_per_length > 0`` replaces the thickness by that fraction of the
receiver's (scaled) length (HDRP's depth-compare threshold scales with its ray length;
dsm.contact.presets says how far the rest of HDRP's march maps).

Lengths in ``"k texel"`` are the shadow map's texel at the receiver (the kit's one meaning of
a texel length); ``"k range"`` a fraction of the view's depth range. Perspective cameras only
(the projection is the pinhole's).
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..truth import metrics as metrics_mod
from ..scenes.camera import Camera
from ..maps.lookup import position_rng, resolve
from ..maps.receiver import Receiver


@dataclass
class DepthBuffer:
    """The camera's depth buffer: per pixel (y * width + x) the view depth of its primary hit (+inf: no hit)."""
    camera: Camera
    depth: object          # mi.Float, world units along the camera's axis
    width: int
    height: int


def depth_buffer(gb) -> DepthBuffer:
    """The depth buffer of a G-buffer (cast from a perspective sensor: ``gb.camera``); ValueError for
    any other camera."""
    cam = gb.camera
    if cam is None:
        raise ValueError("contact shadows need a perspective camera (the scene's sensor has no field of view)")
    o, f = _vec(cam.origin), _vec(cam.forward)
    z = dr.dot(gb.p - o, f)
    z = dr.select(mi.Bool(gb.hit), z, dr.inf)
    dr.eval(z)
    return DepthBuffer(cam, z, gb.width, gb.height)


def _vec(a) -> mi.Vector3f:
    return mi.Vector3f(*(float(c) for c in a))


def project(db: DepthBuffer, p_world):
    """(x, y, z) of world points: film position in pixels (x right, y down, as the G-buffer's
    pixel index) and view depth; Mitsuba's perspective camera maps camera x = left, y = up."""
    cam = db.camera
    q = p_world - _vec(cam.origin)
    z = dr.dot(q, _vec(cam.forward))
    x_cam, y_cam = dr.dot(q, _vec(cam.left)), dr.dot(q, _vec(cam.up))
    sx = 0.5 - 0.5 * x_cam / (z * cam.tan_x)
    sy = 0.5 - 0.5 * y_cam / (z * cam.tan_y)
    return sx * db.width, sy * db.height, z


def sample_distances(spec, length, rx: Receiver, seed: int) -> list:
    """The march's distances t_k along the ray toward the light, one Float per step."""
    n = dr.width(rx.p_world)
    back = dr.zeros(mi.Float, n)
    if spec.jitter > 0:
        rng = position_rng(rx.p_world, seed)
        back = rng.next_float32() * dr.opaque(mi.Float, spec.jitter)
    inv = dr.opaque(mi.Float, 1.0 / spec.steps)
    return [length * (dr.opaque(mi.Float, float(k)) - back) * inv for k in range(1, spec.steps + 1)]


def march(db: DepthBuffer, rx: Receiver, spec, seed: int = 7, light_world=None):
    """Per receiver (mi.Bool): some march sample lies behind the depth buffer by less than ``thickness``.
    ``light_world``: a positional light's position (its samples stop short of it), None for a direction."""
    prm = resolve(spec, rx)           # length and thickness in world units (texels per receiver)
    length, thickness = march_extent(db, rx, spec, prm)
    occluded = dr.zeros(mi.Bool, dr.width(rx.p_world))
    W, H = db.width, db.height
    reach = dr.full(mi.Float, dr.inf, dr.width(rx.p_world))
    if light_world is not None:       # nothing beyond the light can shadow the receiver
        reach = dr.norm(_vec(light_world) - rx.p_world)
    for t in sample_distances(spec, length, rx, seed):
        x, y, z = project(db, rx.p_world + rx.to_light * t)
        inside = (z > 0) & (x >= 0) & (x < W) & (y >= 0) & (y < H) & (t < reach)
        i = dr.clip(mi.Int32(dr.floor(x)), 0, W - 1)
        j = dr.clip(mi.Int32(dr.floor(y)), 0, H - 1)
        z_b = dr.gather(mi.Float, db.depth, mi.UInt32(j * W + i), inside)
        behind = z - z_b
        occluded |= inside & (behind > 0) & (behind < thickness)
    return occluded


def march_extent(db: DepthBuffer, rx: Receiver, spec, prm):
    """(length, thickness) of each receiver's march in world units: ``length`` times
    ``max(length_depth_min, length_depth_scale z_view)`` where ``length_depth_scale > 0`` (``z_view``
    the receiver's view depth), and ``thickness_per_length`` times that length where it is > 0."""
    length, thickness = prm.length, prm.thickness
    # both options are skipped when off, so the default march's kernel (and its numbers) is unchanged
    if spec.length_depth_scale > 0:
        z_view = dr.dot(rx.p_world - _vec(db.camera.origin), _vec(db.camera.forward))
        length = length * dr.maximum(prm.length_depth_min, prm.length_depth_scale * z_view)
    if spec.thickness_per_length > 0:
        thickness = prm.thickness_per_length * length
    return length, thickness


def case_metrics(v: np.ndarray, v_star: np.ndarray, occluded: np.ndarray, v_frac=None) -> dict:
    """The contact step's columns of one case: what it darkens wrongly, recovers and leaves, and
    the error after it (rates as metrics.csv's; NaN where a denominator is empty). ``v_frac``: an
    area light's V* fraction, whose lit (1) and umbra (0) receivers are the core metrics' (penumbra
    receivers count in neither, as in :func:`dsm.truth.metrics.soft`)."""
    v = np.asarray(v, float)
    occ = np.asarray(occluded, bool)
    if v_frac is None:
        gt = np.asarray(v_star, bool)
        sh = ~gt
    else:
        ref = np.asarray(v_frac, float)
        gt, sh = ref == 1.0, ref == 0.0
    lit_map = v >= 0.5
    v_c = visibility_after(v, occ)
    lit_c = v_c >= 0.5
    acne, pp = gt & ~lit_c, sh & lit_c
    n, n_lit, n_sh = len(v), int(gt.sum()), int(sh.sum())
    ref = gt.astype(float) if v_frac is None else np.asarray(v_frac, float)
    rate = lambda k, d: k / d if d else metrics_mod.UNDEFINED
    return {"n_contact_false": int((gt & lit_map & occ).sum()),
            "n_contact_recovered": int((sh & lit_map & occ).sum()),
            "n_contact_missed": int(pp.sum()),
            "contact_acne_rate": rate(int(acne.sum()), n_lit),
            "contact_peterpan_rate": rate(int(pp.sum()), n_sh),
            "contact_error_rate": rate(int(acne.sum() + pp.sum()), n),
            "contact_mean_abs_error": float(np.abs(v_c - ref).mean()) if n else metrics_mod.UNDEFINED}


def visibility_after(v: np.ndarray, occluded: np.ndarray) -> np.ndarray:
    """V after the contact step: 0 where the march is occluded, else the scheme's V."""
    return np.where(np.asarray(occluded, bool), 0.0, np.asarray(v, float))
