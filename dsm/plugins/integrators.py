"""``dsm_shadow`` (direct light with shadow-map visibility) and ``dsm_error`` (classification).

Properties (both): ``scheme`` (a scheme name, default ``adaptive``) and that scheme's own
parameters under their names (``bias = "1 texel"``, ``K = 0.0001``, ``culling = "back_closed"``;
or ``preset``), ``resolution`` (per face, default 1024), ``view`` (point lights:
``paraboloid``, ``dual_paraboloid`` or ``cube``; default ``cube``), ``filter`` (``nearest``,
``pcf_bilinear``, ``pcf_jitter4x4``), ``format`` (``float32``, ``unorm16``, ``unorm24``,
``ndc24``), ``seed`` (jitter of pcf_jitter4x4). ``light``: which of the scene's point, spot
and directional emitters (an index; ``dsm_shadow`` uses all of them by default, ``dsm_error``
the first). ``dsm_shadow`` with ``aovs = true`` adds two channels per sample: ``dsm.V`` (the
map's visibility) and ``dsm.Vstar`` (exact visibility), so a user can see where they differ.

Before rendering, each plugin casts the same pixel-centre G-buffer as the runner (a
directional light's map is fitted to those receivers), builds the map with exactly the
layers the scheme needs, and (``dsm_error``) classifies each receiver pixel as the runner
does: the image's class counts are the runner's counts for that case.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import config as cfgmod
from .. import formats, gbuffer, metrics, reference, scenes, schemes, shadowmap
from ..lookup import Receiver, visibility

MAP_KEYS = ("resolution", "view", "filter", "format", "light", "seed", "aovs")


class Options:
    """The plugin's properties, checked like a config (clear errors naming the property)."""

    def __init__(self, props, plugin: str, all_lights: bool):
        source = f"<integrator type=\"{plugin}\">"
        d = {k: props[k] for k in props.keys()}
        table = {k: v for k, v in d.items() if k not in MAP_KEYS and k != "scheme"}
        if "preset" not in table:
            table["name"] = d.get("scheme", "adaptive")
        specs = cfgmod._parse_scheme(table, source, "integrator", schemes.REGISTRY, schemes.PRESETS)
        if len(specs) != 1:
            raise cfgmod.ConfigError(source, "integrator", "give one value per parameter (no sweeps)")
        self.spec = specs[0]
        self.resolution = cfgmod._number(d.get("resolution", 1024), source, "resolution", integer=True, minimum=1,
                                         maximum=16384)
        self.view = cfgmod._choice(d.get("view", "cube"), source, "view", cfgmod.POINT_VIEWS)
        self.filter = cfgmod._choice(d.get("filter", "nearest"), source, "filter", cfgmod.FILTERS)
        self.format = cfgmod._choice(d.get("format", "float32"), source, "format", cfgmod.FORMATS)
        self.seed = cfgmod._number(d.get("seed", 7), source, "seed", integer=True, minimum=0)
        self.light = cfgmod._number(d.get("light", -1 if all_lights else 0), source, "light", integer=True,
                                    minimum=-1)
        self.aovs = bool(d.get("aovs", False))
        self.source = source


class Prepared:
    """One light's receivers, exact visibility, view and stored map for a scene and sensor."""

    def __init__(self, sd, gb, light, label, opts: Options):
        from ..runner import _points_np, closed_flags, light_setup, make_view
        self.light, self.label = light, label
        setup = light_setup(sd, gb, light, label)
        pts = _points_np(setup.p) if setup.p is not None else np.zeros((0, 3))
        self.view = make_view(light, opts.resolution, pts, sd.bbox, opts.view)
        if setup.p is not None:
            setup = setup.subset(self.view.inside(setup.p).numpy().astype(bool))
        self.setup = setup
        module = schemes.get(opts.spec.name)
        culling = schemes.culling_of(opts.spec.params)
        modes = shadowmap.cull_modes_for(culling, closed_flags(sd)) if culling != "none" else None
        smap = shadowmap.build(sd.scene, self.view, set(module.NEEDS), culling, modes)
        self.smap = formats.store(smap, opts.format)
        self.module = module


def _prepare(integrator, scene, sensor, plugin):
    key = (id(scene), id(sensor))
    if integrator._key == key:
        return integrator._prep
    sensor = sensor if sensor is not None else scene.sensors()[0]
    sd = scenes.from_mitsuba(scene)
    W, H = (int(x) for x in sensor.film().size())
    gb = gbuffer.cast(scene, sensor, W, H)
    lights = sd.own_lights
    if not lights:
        raise ValueError(f"{plugin}: the scene has no point, spot or directional emitter")
    opts = integrator.opts
    if opts.light >= len(lights):
        raise cfgmod.ConfigError(opts.source, "light", f"the scene has {len(lights)} usable emitters",
                                 [str(i) for i in range(len(lights))])
    chosen = range(len(lights)) if opts.light < 0 else [opts.light]
    prep = {"sd": sd, "gb": gb, "size": (W, H),
            "lights": [Prepared(sd, gb, lights[i], f"{i}:{lights[i].type}", opts) for i in chosen]}
    # the emitters the lights came from, in the same order (for dsm_shadow's radiance)
    emitters = [e for e in scene.emitters() if scenes.emitter_to_light(e) is not None]
    prep["emitters"] = [emitters[i] for i in chosen]
    integrator._key, integrator._prep = key, prep
    return prep


def _srgb_to_linear(c):
    c = np.asarray(c, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


CLASS_LINEAR = _srgb_to_linear(metrics.CLASS_COLORS).astype(np.float32)


def classes_image(prep: dict, opts: Options) -> np.ndarray:
    """(H, W) classes of the first prepared light, exactly as the runner classifies the case."""
    W, H = prep["size"]
    lp = prep["lights"][0]
    classes = np.zeros(W * H, np.uint8)
    st = lp.setup
    if st.p is not None and len(st.pixels):
        rx = Receiver.make(lp.view, st.p, st.n, prep["sd"].diagonal)
        v, _ = visibility(lp.module, opts.spec.params, rx, lp.smap, opts.filter, opts.seed)
        classes[st.pixels] = metrics.classify(v.numpy(), st.v_star)
    return classes.reshape(H, W)


class DsmError(mi.SamplingIntegrator):
    """Per-pixel classification: correct lit, correct shadow, acne, peter-panning (report colours)."""

    def __init__(self, props):
        super().__init__(props)
        self.opts = Options(props, "dsm_error", all_lights=False)
        self._key, self._prep = None, None

    def render(self, scene, sensor=None, seed=0, spp=0, develop=True, evaluate=True):
        if isinstance(sensor, int):
            sensor = scene.sensors()[sensor]
        prep = _prepare(self, scene, sensor, "dsm_error")
        img = CLASS_LINEAR[classes_image(prep, self.opts)]
        return mi.TensorXf(img)

    def sample(self, scene, sampler, ray, medium=None, active=True):
        raise RuntimeError("dsm_error renders whole images (mi.render); it has no per-sample form")

    def to_string(self):
        return f"DsmError[{self.opts.spec.name} {self.opts.spec.label}, R={self.opts.resolution}]"


class DsmShadow(mi.SamplingIntegrator):
    """Direct light from point, spot and directional emitters, visibility from a shadow map."""

    def __init__(self, props):
        super().__init__(props)
        self.opts = Options(props, "dsm_shadow", all_lights=True)
        self._key, self._prep = None, None

    def aov_names(self):
        return ["dsm.V", "dsm.Vstar"] if self.opts.aovs else []

    def render(self, scene, sensor=None, seed=0, spp=0, develop=True, evaluate=True):
        sensor_obj = scene.sensors()[sensor] if isinstance(sensor, int) else sensor
        prep = _prepare(self, scene, sensor_obj, "dsm_shadow")
        if len(prep["emitters"]) != len(prep["lights"]):
            raise ValueError("dsm_shadow shades with the scene's point, spot and directional emitters; this scene has "
                             "none (dsm_error can still classify it under dsm's default light)")
        return mi.SamplingIntegrator.render(self, scene, sensor, seed, spp, develop, evaluate)

    def sample(self, scene, sampler, ray, medium=None, active=True):
        prep = self._prep
        if prep is None:
            raise RuntimeError("dsm_shadow: call mi.render (the maps are built before sampling)")
        si = scene.ray_intersect(ray, active)
        valid = active & si.is_valid()
        bsdf = si.bsdf(ray)
        ctx = mi.BSDFContext()
        n = mi.Vector3f(si.n) * dr.sign(dr.dot(si.n, -ray.d))
        result = mi.Spectrum(0.0)
        v_sum, vs_sum = mi.Float(0.0), mi.Float(0.0)
        diag = prep["sd"].diagonal
        magnitude = reference.scene_magnitude(prep["sd"].bbox)
        for lp, emitter in zip(prep["lights"], prep["emitters"]):
            ds, spec = emitter.sample_direction(si, sampler.next_2d(), valid)
            f = bsdf.eval(ctx, si, si.to_local(ds.d), valid)
            rx = Receiver.make(lp.view, si.p, n, diag)
            v, _ = visibility(lp.module, self.opts.spec.params, rx, lp.smap, self.opts.filter, self.opts.seed)
            v = dr.select(valid & lp.view.inside(si.p), v, 0.0)
            result += f * spec * v
            if self.opts.aovs:
                vstar, _ = reference.visibility(scene, si, lp.light, magnitude)
                v_sum += v
                vs_sum += dr.select(valid & vstar, 1.0, 0.0)
        aovs = [v_sum, vs_sum] if self.opts.aovs else []
        return dr.select(valid, result, 0.0), valid, aovs

    def to_string(self):
        return f"DsmShadow[{self.opts.spec.name} {self.opts.spec.label}, R={self.opts.resolution}]"
