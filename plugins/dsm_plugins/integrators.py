"""``dsm_shadow`` (direct light with shadow-map visibility) and ``dsm_error`` (classification).

Properties (both): ``scheme`` (a scheme name, default ``adaptive``) and that scheme's own
parameters under their names (``bias = "1 texel"``, ``K = 0.0001``, ``culling = "back_closed"``;
or ``preset``), ``resolution`` (per face, default 1024), ``view`` (point lights:
``paraboloid``, ``dual_paraboloid`` or ``cube``; default ``cube``), ``filter`` (``nearest``,
``pcf_bilinear``, ``pcf_jitter4x4``), ``format`` (``float32``, ``unorm16``, ``unorm24``,
``ndc24``; and ``pcf_wide[:K]``, ``pcss``), ``seed`` (jitter of pcf_jitter4x4, the reference's
samples). ``area = true``: the scene's area emitters (on meshes) are the lights, with soft
shadows (:mod:`dsm.truth.area`; the map cast from the luminaire's centre without it; ``pcss`` and
``pcf_wide`` give penumbrae); ``dsm_error`` then renders |V - V*| (magma) against a reference
of ``samples`` stratified samples per pixel (default 64), and ``dsm_shadow``'s ``dsm.Vstar``
AOV is one area sample's visibility per sample (V* on average). ``light``: which of the scene's point, spot
and directional emitters (an index; ``dsm_shadow`` uses all of them by default, ``dsm_error``
the first). ``dsm_shadow`` with ``aovs = true`` (a boolean: ``<boolean>`` in XML, or
``true``/``false``/``1``/``0``) adds two channels per sample: ``dsm.V`` (the map's
visibility) and ``dsm.Vstar`` (exact visibility), so a user can see where they differ.

A bad property raises :class:`~dsm.ConfigError` as one line naming it (Mitsuba shows
``... failed to instantiate ...: ConfigError: <integrator type="dsm_error">: scheme: unknown
value 'foo' (valid: ...)``); a ``light`` index the scene does not have fails at the start of
rendering, listing the scene's point, spot and directional emitters.

Before rendering, each plugin casts the same pixel-centre G-buffer as the runner, builds the
map with exactly the layers the scheme needs, and (``dsm_error``) classifies each receiver
pixel as the runner does (:func:`dsm.case.evaluate`; a directional light's map fitted to those receivers): the image's
class counts are the runner's counts for that case. ``dsm_shadow`` samples anywhere inside
a pixel, so its directional maps are fitted to the hit points of the pixel corners as well
(a point outside such a map, where no caster was recorded, reads as lit). The prepared maps
are kept while a fingerprint of the scene (shape vertices and transforms, emitters, sensor
and film) is unchanged, and rebuilt after ``mi.traverse(scene)`` + ``params.update()``.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

import dsm.pipeline as pl
from dsm.case import Case, MapContext, Where, evaluate
from dsm.core import types as cfgmod
from dsm.pipeline import Receiver

OWN_KEYS = ("scheme", "resolution", "view", "filter", "format", "light", "seed", "area", "samples")
SHADOW_KEYS = OWN_KEYS + ("aovs",)
TRUE_WORDS, FALSE_WORDS = ("true", "1"), ("false", "0")


def _boolean(raw, source, key):
    """A boolean property: a bool (XML ``<boolean>``, a dict's True/False), 0/1, or a string
    ``true``/``false``/``1``/``0`` (any case): never Python's ``bool("false") == True``."""
    if isinstance(raw, bool):
        return raw
    if isinstance(raw, int) and raw in (0, 1):
        return bool(raw)
    if isinstance(raw, str) and raw.strip().lower() in TRUE_WORDS + FALSE_WORDS:
        return raw.strip().lower() in TRUE_WORDS
    raise cfgmod.ConfigError(source, key, f"expected a boolean, got {raw!r}", ("true", "false"))


class Options:
    """The plugin's properties, checked like a config: a mistake raises one
    :class:`~dsm.ConfigError` line naming the property as the user wrote it
    (``scheme``, ``bias``, ``resolution``), the bad value and the valid choices."""

    def __init__(self, props, plugin: str, all_lights: bool):
        source = f"<integrator type=\"{plugin}\">"
        if mi.variant() not in cfgmod.VARIANTS:      # scalar and spectral variants fail deep in a render
            raise cfgmod.ConfigError(source, "variant", f"Mitsuba variant {mi.variant()} is not supported: dsm runs "
                                     "vectorized Dr.Jit code in RGB", cfgmod.VARIANTS)
        own = SHADOW_KEYS if plugin == "dsm_shadow" else OWN_KEYS
        # properties the base class read (hide_emitters, timeout, ...) are the base's own
        names = list(props.unqueried()) if hasattr(props, "unqueried") else list(props.keys())
        d = {k: props[k] for k in names}
        table = {k: v for k, v in d.items() if k not in own}
        if "name" in table:            # the scheme is `scheme` here, never the config's `name`
            raise cfgmod.ConfigError(source, "name", "unknown property; the scheme is given as `scheme`", own)
        if "preset" not in table:
            table["name"] = d.get("scheme", "adaptive")
        elif "scheme" in d:
            raise cfgmod.ConfigError(source, "scheme", "give either scheme (and its parameters) or preset, not both")
        try:
            specs = pl.scheme_specs(table, source, "integrator")
        except cfgmod.ConfigError as e:
            key = "scheme" if e.key == "integrator.name" else e.key.removeprefix("integrator.")
            choices = e.choices
            if e.problem == "unknown key":      # the plugin's own properties are valid keys too
                choices = tuple(own) + tuple(c for c in choices if c not in own)
                raise cfgmod.ConfigError(source, key, "unknown property", choices, got=e.got) from None
            raise cfgmod.ConfigError(source, key, e.problem, choices, got=e.got) from None
        if len(specs) != 1:
            raise cfgmod.ConfigError(source, "scheme", "give one value per parameter (no sweeps)")
        self.spec = specs[0]
        self.resolution = cfgmod.number(d.get("resolution", 1024), source, "resolution", integer=True, minimum=1,
                                         maximum=16384)
        self.view = cfgmod.choice(d.get("view", "cube"), source, "view", cfgmod.POINT_VIEWS)
        filt = d.get("filter", "nearest")
        if not (isinstance(filt, str) and filt.startswith("pcf_wide:")):
            cfgmod.choice(filt, source, "filter", cfgmod.FILTERS)
        elif not (filt[9:].isdigit() and 2 <= int(filt[9:]) <= 64):
            raise cfgmod.ConfigError(source, "filter", f"{filt!r}: pcf_wide:K takes a kernel width K in texels, "
                                     "an integer from 2 to 64")
        self.filter = filt
        # area = true: the scene's area emitters are the lights (soft shadows; dsm.truth.area), each
        # receiver's reference V* from `samples` stratified samples (min = max, no early stop)
        self.area = _boolean(d.get("area", False), source, "area")
        self.samples = cfgmod.number(d.get("samples", 64), source, "samples", integer=True, minimum=1,
                                     maximum=1 << 16)
        self.format = cfgmod.choice(d.get("format", "float32"), source, "format", cfgmod.FORMATS)
        self.seed = cfgmod.number(d.get("seed", 7), source, "seed", integer=True, minimum=0)
        # dsm_shadow: -1 (the default) shades with every light; dsm_error classifies one light
        self.light = cfgmod.number(d.get("light", -1 if all_lights else 0), source, "light", integer=True,
                                    minimum=-1 if all_lights else 0)
        self.aovs = _boolean(d.get("aovs", False), source, "aovs")
        self.source = source


def clean_config_errors(fn):
    """Re-raise a :class:`~dsm.ConfigError` from ``fn`` without its traceback.

    Mitsuba reports an exception raised in a plugin's constructor as the text of its whole
    Python traceback followed by the message; without a traceback that text is the one line
    ``ConfigError: <integrator type="...">: key: problem (valid: ...)``. A bare ``raise``
    re-raises without adding this frame. Other exceptions (bugs) keep their traceback.
    """
    import functools

    @functools.wraps(fn, updated=())      # fn may be a class: copy its name, not its __dict__
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except cfgmod.ConfigError as e:
            e.__traceback__ = None
            raise
    return wrapper


def describe_lights(lights) -> str:
    """``0: point at (0, 1.9, 0), 1: directional towards (0, 0, -1)``: the emitters ``light`` indexes."""
    def v(x):
        return "(" + ", ".join(f"{float(c) + 0.0:.4g}" for c in x) + ")"      # + 0.0: no "-0"
    out = []
    for i, lt in enumerate(lights):
        if lt.type == "directional":
            out.append(f"{i}: directional towards {v(lt.direction)}")
        elif lt.type == "spot":
            axis = lt.direction if lt.direction is not None else np.subtract(lt.target, lt.position)
            out.append(f"{i}: spot at {v(lt.position)} towards {v(axis)}")
        else:
            out.append(f"{i}: {lt.type} at {v(lt.position)}")
    return ", ".join(out)


class Prepared:
    """One light's receivers, exact visibility, view and stored map for a scene and sensor.

    ``fit_extra``: more world points the orthographic (directional) view must cover beside the
    pixel-centre receivers (dsm_shadow passes the hit points of the pixel corners, so that
    every sample inside a pixel projects inside the map)."""

    def __init__(self, sd, gb, light, label, opts: Options, fit_extra=None):
        self.light, self.label = light, label
        setup = pl.light_setup(sd, gb, light, label, seed=opts.seed)
        self.geom = pl.area_geometry(light, sd.scene) if light.type == "area" else None
        pts = pl.points_np(setup.p) if setup.p is not None else np.zeros((0, 3))
        if light.type == "directional" and fit_extra is not None and len(fit_extra):
            pts = np.concatenate([pts, fit_extra])
        self.view = pl.make_view(light, opts.resolution, pts, sd.bbox, opts.view)
        if setup.p is not None:
            setup = setup.subset(self.view.inside(setup.p).numpy().astype(bool))
        self.setup = setup
        self.spec = pl.preset_for_light(opts.spec, light.type)      # an engine preset's values for this light
        module = pl.scheme_module(self.spec.name)
        culling = pl.culling_of(self.spec.params)
        closed = pl.closedness(sd)[0] if culling != "none" else None
        smap = pl.build_map(sd.scene, self.view, pl.needs_of([self.spec]), culling, closed)
        self.smap = pl.store(smap, opts.format)
        self.view = self.smap.view          # the depth function the stored format compares in
        self.module = module


def corner_points(scene, sensor, W: int, H: int, direction) -> np.ndarray:
    """World hit points of the (W+1) x (H+1) pixel corners on surfaces facing a directional
    light (travelling along ``direction``): with the pixel centres they bound every point a
    sample inside a pixel can hit (exactly on planes, to within the curvature elsewhere)."""
    idx = dr.arange(mi.UInt32, (W + 1) * (H + 1))
    x, y = mi.Float(idx % (W + 1)), mi.Float(idx // (W + 1))
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(x / W, y / H), mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(ray)
    n = mi.Vector3f(si.n) * dr.sign(dr.dot(si.n, -ray.d))
    to_light = -mi.Vector3f(*(float(c) for c in direction))
    keep = (si.is_valid() & (dr.dot(n, to_light) > 0)).numpy().astype(bool)
    p = np.stack([np.asarray(c.numpy(), np.float64) for c in (si.p.x, si.p.y, si.p.z)], axis=1)
    return p[keep]


def _array(value) -> np.ndarray:
    if hasattr(value, "matrix"):          # a Transform4f
        value = value.matrix
    try:
        return np.ascontiguousarray(np.asarray(value))
    except Exception:                    # an object without an array form: its text
        return np.frombuffer(str(value).encode(), np.uint8)


def fingerprint(scene, sensor) -> str:
    """A hash of what the G-buffer and the maps depend on: every shape's own parameters (vertex
    positions, faces, transforms) and bounds, the point/spot/directional emitters' parameters
    and transforms, the sensor's parameters, transform and film size. ``mi.traverse(scene)``
    + ``params.update()`` changes it (Mitsuba does not tell the integrator), so the plugins
    rebuild their maps for the scene as it is now, not as it was at the first render."""
    import hashlib
    h = hashlib.blake2b(digest_size=20)

    def put(tag, value=None):
        h.update(str(tag).encode() + b"\0")
        if value is not None:
            a = _array(value)
            h.update(f"{a.dtype}{a.shape}".encode())
            h.update(a.tobytes())

    for shape in scene.shapes():
        put(f"shape {type(shape).__name__} {shape.id()}")
        bb = shape.bbox()
        put("bbox", np.concatenate([np.asarray(bb.min, float).ravel(), np.asarray(bb.max, float).ravel()]))
        params = mi.traverse(shape)
        for k in sorted(params.keys()):
            # the shape's own (not nested: its bsdf, area emitter); texture coordinates move nothing
            if "." not in k and k != "vertex_texcoords":
                put(k, params[k])
    delta = mi.EmitterFlags.DeltaPosition | mi.EmitterFlags.DeltaDirection
    for e in scene.emitters():
        if not (int(e.flags()) & int(delta)):
            continue
        put(f"emitter {type(e).__name__}", e.world_transform())
        params = mi.traverse(e)
        for k in sorted(params.keys()):
            put(k, params[k])
    put("sensor", sensor.world_transform())
    film = sensor.film()
    put("film", np.array([*film.size(), *film.crop_size(), *film.crop_offset()], np.int64))
    params = mi.traverse(sensor)
    for k in sorted(params.keys()):
        if not k.startswith("sampler."):
            put(k, params[k])
    return h.hexdigest()


def _prepare(integrator, scene, sensor, plugin):
    pl.exact_math()           # per thread: a user's mi.render thread gets the runner's bits
    sensor = sensor if sensor is not None else scene.sensors()[0]
    key = (id(scene), id(sensor), fingerprint(scene, sensor))
    if integrator._key == key:
        return integrator._prep
    integrator._key, integrator._prep = None, None
    opts = integrator.opts
    sd = pl.scene_from_mitsuba(scene)
    lights = sd.own_lights
    if opts.area:
        lights = pl.area_emitter_lights(scene, cfgmod.LightSpec("area", shape="emitter", min_samples=opts.samples,
                                                                 max_samples=opts.samples, tolerance=0.0))
        if not lights:
            raise ValueError(f"{plugin}: area = true, but the scene has no area emitter on a mesh")
    if not lights:
        raise ValueError(f"{plugin}: the scene has no point, spot or directional emitter")
    if opts.light >= len(lights):
        raise cfgmod.ConfigError(opts.source, "light", f"{opts.light} is out of range; the scene's "
                                 f"point/spot/directional emitters are {describe_lights(lights)}")
    W, H = (int(x) for x in sensor.film().size())
    gb = pl.gbuffer(sd, W, H, sensor)
    chosen = range(len(lights)) if opts.light < 0 else [opts.light]
    prepared = []
    for i in chosen:
        extra = None
        if plugin == "dsm_shadow" and lights[i].type == "directional":
            extra = corner_points(scene, sensor, W, H, lights[i].direction)
        prepared.append(Prepared(sd, gb, lights[i], f"{i}:{lights[i].type}", opts, extra))
    prep = {"sd": sd, "gb": gb, "size": (W, H), "lights": prepared}
    # the emitters the lights came from, in the same order (for dsm_shadow's radiance)
    if opts.area:
        emitters = [scene.shapes()[lt.emitter_shapes[0]].emitter() for lt in lights]
    else:
        emitters = [e for e in scene.emitters() if pl.emitter_light(e) is not None]
    prep["emitters"] = [emitters[i] for i in chosen]
    integrator._key, integrator._prep = key, prep
    return prep


def _srgb_to_linear(c):
    c = np.asarray(c, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


CLASS_LINEAR = _srgb_to_linear(pl.CLASS_COLORS).astype(np.float32)


def evaluated(prep: dict, opts: Options):
    """The first prepared light's case as the runner evaluates it (dsm.case.evaluate): its V,
    counts and class image over the pixel-centre receivers (with the nearest filter, the errors
    the per-texel oracle makes too, at lambda 1 as the runner's default)."""
    lp, sd = prep["lights"][0], prep["sd"]
    st = lp.setup
    rx = None
    if st.p is not None and len(st.pixels):
        rx = Receiver.make(lp.view, st.p, st.n, sd.diagonal, st.camera)
    wrong = None
    if rx is not None and opts.filter == "nearest" and st.ref is None:
        wrong = pl.oracles(pl.thresholds(rx, lp.smap), st.v_star)["wrong"]
    where = Where("mitsuba", lp.label, lp.view.kind, opts.resolution, lp.view.n_texels, pl.culling_of(lp.spec.params))
    ctx = MapContext(where, sd, prep["gb"], st, lp.view, lp.smap, {opts.format: lp.smap}, {opts.format: rx},
                     opts.seed, 0, wrong={opts.format: wrong})
    return evaluate(ctx, Case("0001", lp.spec, opts.filter, opts.format))


def abs_error_image(prep: dict, opts: Options) -> np.ndarray:
    """(H, W, 3) linear RGB of |V - V*| of the first prepared (area) light, magma colours as the
    runner's ``<case>_abserr.png``; black outside the receivers."""
    from matplotlib import colormaps
    W, H = prep["size"]
    st = prep["lights"][0].setup
    img = np.zeros((W * H, 3), np.float32)
    if st.p is not None and len(st.pixels):
        err = np.abs(evaluated(prep, opts).v - st.v_frac)
        img[st.pixels] = _srgb_to_linear(np.round(colormaps["magma"](np.clip(err, 0, 1))[:, :3] * 255))
    return img.reshape(H, W, 3)


def classes_image(prep: dict, opts: Options) -> np.ndarray:
    """(H, W) classes of the first prepared light, exactly as the runner classifies the case."""
    return evaluated(prep, opts).classes


class DsmError(mi.SamplingIntegrator):
    """Per-pixel classification: correct lit, correct shadow, acne, peter-panning (report colours;
    with the nearest filter, errors no per-texel bias fixes in their darker shade)."""

    def __init__(self, props):
        super().__init__(props)
        self.opts = Options(props, "dsm_error", all_lights=False)
        self._key, self._prep = None, None

    @clean_config_errors
    def render(self, scene, sensor=None, seed=0, spp=0, develop=True, evaluate=True):
        if isinstance(sensor, int):
            sensor = scene.sensors()[sensor]
        prep = _prepare(self, scene, sensor, "dsm_error")
        if self.opts.area:          # soft shadows: the error map |V - V*|
            return mi.TensorXf(abs_error_image(prep, self.opts))
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

    @clean_config_errors
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
        magnitude = pl.scene_magnitude(prep["sd"].bbox)
        for lp, emitter in zip(prep["lights"], prep["emitters"]):
            ds, spec = emitter.sample_direction(si, sampler.next_2d(), valid)
            f = bsdf.eval(ctx, si, si.to_local(ds.d), valid)
            rx = Receiver.make(lp.view, si.p, n, diag, lp.setup.camera)   # distance-scaled schemes read it
            v, _ = pl.visibility(lp.spec, rx, lp.smap, self.opts.filter, self.opts.seed)
            inside = lp.view.inside(si.p)
            if lp.view.kind == "orthographic":
                # outside a directional light's map no caster was recorded: lit (the map is
                # fitted to cover every pixel's footprint, so this is only a safety net)
                v = dr.select(inside, v, 1.0)
            else:       # outside a spot's cone or a single paraboloid's hemisphere: unlit
                v = dr.select(inside, v, 0.0)
            v = dr.select(valid, v, 0.0)
            result += f * spec * v
            if self.opts.aovs and lp.geom is not None:     # one area sample: V* on average over samples
                vstar = pl.area_sample_visibility(scene, si, n, lp.geom, sampler.next_2d(), magnitude)
                v_sum += v
                vs_sum += dr.select(valid & vstar, 1.0, 0.0)
            elif self.opts.aovs:
                vstar, _ = pl.exact_visibility(scene, si, lp.light, magnitude)
                v_sum += v
                vs_sum += dr.select(valid & vstar, 1.0, 0.0)
        aovs = [v_sum, vs_sum] if self.opts.aovs else []
        return dr.select(valid, result, 0.0), valid, aovs

    def to_string(self):
        return f"DsmShadow[{self.opts.spec.name} {self.opts.spec.label}, R={self.opts.resolution}]"
