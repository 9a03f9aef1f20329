"""Mitsuba's projective-sampling integrators on the gradient test bed: a second reference, checked.

``direct_projective`` and ``prb_projective`` (after Zhang et al., "Projective Sampling for
Differentiable Rendering of Geometry", 2023) differentiate the rendered image through visibility
by sampling silhouette edges. The test bed's scene is rendered as Mitsuba sees it: the same
ground and occluder meshes (the occluder's vertex buffer the same expression of the parameters,
:meth:`OccluderScene.vertex_positions`), a diffuse ground, the light (the kit's LightSpec as Mitsuba's
emitter of strength 1, :func:`dsm.lights.emitter`: the point light a spot with no
falloff inside its cone) and an orthographic camera looking straight down over [-window, window]^2
at ``image_resolution``^2 pixels, direct light only (``max_depth`` 2). V per pixel is the rendered radiance over the radiance of the
ground without the occluder (one more render at the same seed: the same pixel samples), so the
occluder's parameters reach the loss only through I: d loss / dp from the forward-mode tangent
of the image (``dr.forward`` through ``mi.render``), summed in float64. A light's parameters also
change the unshadowed radiance and are not offered here.

The gradient is stochastic: over ``projective_seeds`` seeds its mean, spread and ms per gradient
are reported; it is used as a reference only where its mean agrees with the supersampled
difference within their errors, and the disagreement is a finding otherwise.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import lights
from ..scenes.geometry import make_mesh
from . import light as lightmod
from .occluder import shapes

OCCLUDER_PARAMS = ("occluder_z", "occluder_x", "corner_z")
# the camera's height over the ground in windows: far, so the occluder hides little of its shadow (the
# projective integrators take a perspective camera only; a plane facing it maps linearly to its pixels)
CAMERA_HEIGHT = 40.0
MASK_PIXELS = 2          # the occluder's image is masked with this margin (its own silhouette's gradient)


@dataclass
class ProjectiveResult:
    """One integrator and parameter: the gradient over seeds, its primal's agreement, its cost."""
    integrator: str
    param: str
    spp: int
    grads: tuple                 # d loss / d param per seed
    primal_mismatch: float       # fraction of seen pixels whose V differs from the exact image's by > 0.5
    ms: float                    # one gradient (primal + forward tangent), warm median over the seeds
    image: np.ndarray            # per-pixel dV / d param of the first seed
    seen: np.ndarray = None      # (N, N) bool: the pixels whose V it measures (the camera sees the ground there)
    first_ms: float = 0.0        # the first seed's gradient (its kernels' compile included)

    @property
    def mean(self) -> float:
        """The gradient's mean over seeds."""
        return float(np.mean(self.grads))

    @property
    def spread(self) -> float:
        """The standard error of the mean over seeds (0 with one seed)."""
        n = len(self.grads)
        return float(np.std(self.grads, ddof=1) / math.sqrt(n)) if n > 1 else 0.0


def scene_dict(spec, integrator: str, with_occluder: bool = True) -> dict:
    """The test bed as a Mitsuba scene dict: ground, occluder, light, a camera looking down, ``integrator``."""
    geometry = shapes(spec)
    W, N = spec.window, spec.image_resolution
    cam = mi.ScalarTransform4f().look_at(origin=[0, 0, CAMERA_HEIGHT * W], target=[0, 0, 0], up=[0, 1, 0])
    # max_depth 2: direct light only, as V is (a deeper path adds the ground's light reflected by the occluder)
    d = {"type": "scene", "integrator": {"type": integrator, "max_depth": 2},
         "sensor": {"type": "perspective", "to_world": cam, "fov": 2.0 * math.degrees(math.atan(1.0 / CAMERA_HEIGHT)),
                    "fov_axis": "x",
                    "film": {"type": "hdrfilm", "width": N, "height": N, "rfilter": {"type": "box"},
                             "pixel_format": "rgb", "sample_border": True},
                    "sampler": {"type": "independent"}},
         "light": lights.emitter(lightmod.nominal(spec)), "ground": make_mesh("ground", *geometry["ground"])}
    if with_occluder:
        d["occluder"] = make_mesh("occluder", *geometry["occluder"])
    return d


def hiders(spec) -> np.ndarray:
    """(k, 3) points whose convex hull's projection hides the ground from the camera: the occluder's
    vertices, its top raised by the reference's step, and an area light's square (between camera and ground)."""
    ov = np.asarray(shapes(spec)["occluder"][0], float).reshape(-1, 3)
    raised = ov + np.array([0.0, 0.0, spec.reference_step_of("occluder_z")])
    pts = [ov, raised]
    if spec.light == "area":
        h = spec.light_size / 2.0
        pts.append(np.array([[x, y, spec.light_height] for x in (-h, h) for y in (-h, h)]))
    return np.concatenate(pts)


def visible_ground(problem, param: str | None = None) -> np.ndarray:
    """(N, N) bool: pixels where the camera sees the ground, not the occluder or an area light (at the nominal
    values; the hiders' projections grown by MASK_PIXELS, and by the reference's step where ``param`` moves
    the occluder sideways)."""
    return ground_seen(problem.spec, param)


def ground_seen(spec, param: str | None = None) -> np.ndarray:
    """visible_ground of a GradSpec alone (before any work: dsm grad --compare refuses a scene it sees none of)."""
    pts = hiders(spec)
    # each point projects from the camera onto the ground: scaled about the camera's foot by its height's ratio
    flat = pts[:, :2] * (CAMERA_HEIGHT * spec.window / (CAMERA_HEIGHT * spec.window - pts[:, 2:3]))
    N, W = spec.image_resolution, spec.window
    grow = MASK_PIXELS * 2.0 * W / N + (spec.reference_step_of(param) if param == "occluder_x" else 0.0)
    lo, hi = flat.min(axis=0) - grow, flat.max(axis=0) + grow
    c = -W + (np.arange(N) + 0.5) * (2.0 * W / N)
    xx, yy = np.meshgrid(c, c)
    return ~((xx > lo[0]) & (xx < hi[0]) & (yy > lo[1]) & (yy < hi[1]))


def gradient(problem, integrator: str, param: str, spp: int, seeds: int) -> ProjectiveResult:
    """``integrator``'s d loss / d ``param`` (an occluder parameter) over ``seeds`` seeds."""
    if param not in OCCLUDER_PARAMS:
        raise ValueError(f"the projective reference takes an occluder parameter ({', '.join(OCCLUDER_PARAMS)}), "
                         f"not {param!r}")
    level = mi.log_level()
    # its warnings (no indirect silhouette found under a point light) are this module's finding, reported
    mi.set_log_level(mi.LogLevel.Error)
    try:
        return _gradient(problem, integrator, param, spp, seeds)
    finally:
        mi.set_log_level(level)


def _gradient(problem, integrator: str, param: str, spp: int, seeds: int) -> ProjectiveResult:
    spec = problem.spec
    scene = mi.load_dict(scene_dict(spec, integrator), optimize=False)
    bare = mi.load_dict(scene_dict(spec, integrator, with_occluder=False), optimize=False)
    params = mi.traverse(scene)
    grads, walls, image, mismatch = [], [], None, 0.0
    exact = problem.exact_image(problem.values())
    seen = visible_ground(problem, param)
    for seed in range(seeds):
        I0 = orient(mi.render(bare, spp=spp, seed=seed))
        vals = {k: dr.opaque(mi.Float, float(v), 1) for k, v in problem.values().items()}
        dr.enable_grad(vals[param])
        params["occluder.vertex_positions"] = problem.scene.vertex_positions(vals)
        params.update()
        dr.sync_thread()
        t0 = time.perf_counter()
        img = mi.render(scene, params, spp=spp, seed=seed)
        dr.forward(vals[param])
        dI = dr.grad(img)
        I, dI = orient(dr.detach(img)), orient(dI)
        dr.sync_thread()
        walls.append((time.perf_counter() - t0) * 1e3)
        params["occluder.vertex_positions"] = dr.detach(params["occluder.vertex_positions"])   # leave no graph
        params.update()
        with np.errstate(divide="ignore", invalid="ignore"):     # I0 is 0 where the camera sees an area light's back
            V, dV = np.where(seen, I / I0, exact), np.where(seen, dI / I0, 0.0)
        grads.append(problem.loss_tangent(V, dV) + 0.0)
        if seed == 0:
            image, mismatch = dV, float(np.mean(np.abs(V - exact)[seen] > 0.5))
    warm = walls[1:] or walls
    return ProjectiveResult(integrator, param, spp, tuple(grads), mismatch, float(np.median(warm)), image, seen,
                            walls[0])


def orient(img) -> np.ndarray:
    """Mitsuba's film as the kit's image (row y increasing, column x increasing), first channel, float64."""
    a = np.asarray(img, np.float64)[:, :, 0]
    return a[::-1, :]
