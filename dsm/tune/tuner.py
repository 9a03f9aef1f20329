"""Bias tuned by gradient: every continuous scheme parameter, and a learned bias map, fitted by
Dr.Jit's AD through the kit's own lookup and judged by the exact (hard) objective.

**Objective** (the oracles'): ``E = (n_acne + lambda n_peterpan) / n_receivers``, pooled over
every training case (scene x light x training camera): the counts summed, then divided by the
summed receivers.

**Relaxation.** A receiver's lit probability is ``s_r = sigmoid(margin_r(theta) / T_r)``, the
margin being the scheme's signed margin (lit when >= 0) and ``T_r = t texel_world(r)`` a
temperature in depth units tied to the texel at the receiver; ``t`` (texels) is annealed from
``temperature[0]`` to ``temperature[1]`` over the steps (``schedule``: geometric or linear).
The relaxed loss is ``(sum over truly lit (1 - s_r) + lambda sum over truly shadowed s_r) /
n_receivers``; an empty class adds 0.

**Gradients.** The parameters are Dr.Jit Floats with gradients; the scheme's own ``shift`` and
``margin`` run on them (``dr.backward``), steps are ``mi.ad.Adam``'s (first-moment decay
``BETA1`` = 0.5: the default 0.9 carries the iterate across the flat optimum of a piecewise
constant objective after the gradient turns) on each parameter divided by one texel's worth in
its unit (the mean texel width over the training receivers for world units, that over the depth
range for range units, over the scene diagonal for adaptive's K; 1 for texel units and slope
factors). ``lr`` is the step in those texels at the first temperature; it shrinks in proportion
to the temperature. After each step a parameter is clipped into its search range
(``[tune.range]``, default ``[valid minimum or 0, start + 16 texels' worth]``). Parameters
that act through the choice of texel (normal offset's ``offset``, combined's
``normal_offset``) have no derivative through z1 under a nearest lookup (a gather at
``floor(u)``): while tuning, schemes with a shift read z1 **bilinearly** between the four
surrounding texel centres (continuous in the lookup point), the slope and z2 layers and the
tangent-plane texel from the nearest texel. The hard objective always uses the kit's nearest
lookup (``pipeline.visibility``).

**Search.** ``steps`` is the budget of exact objective evaluations, the grid search's too: the
start, then a coarse grid over the search box at cell centres (a quarter of the budget), then
Adam from the better of the two, one evaluation per step, then an exact refinement (a quarter):
a compass search on the exact objective and exact line searches along each parameter (the
margins linearised by forward-mode AD, the objective along the line counted at every
receiver's flip). The best evaluation is the result: never worse than the start, nor than any
point the search saw (the relaxed loss only steers; it can rise where the exact objective
falls, so it never picks the result).

**Learned bias map** (``[tune.bias_map]``, ``fit = "adam"``; ``fit = "residual"``: a residual over
the best tuned scheme, dsm.tune.residual_map): one bias per block of ``block x block`` texels
of the light's map, the map fitted once to the union of every camera's receivers (training and
held-out) so the grid is the same for all views. Trained on the training cameras (started from
the tuned constant bias when one was tuned in the same unit), judged on the held-out cameras
against the per-texel oracle of the held-out views and against the best tuned global scheme.

**Comparisons.** Constant bias against the exact oracle (world or texel, by the bias's unit)
of the training views; every scheme against a grid search over the same box with at most the
same number of (hard) loss evaluations, both timed (``dr.sync_thread`` before each clock).
"""
from __future__ import annotations

import csv
import dataclasses
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import drjit as dr
import mitsuba as mi
import numpy as np

from ..maps import lookup
from . import resume as tune_resume
from ..report.io import atomic
from ..report.tables import objective
from .. import pipeline as pl
from ..schemes import get as get_scheme
from ..schemes.base import no_shift
from ..types import DEFAULT_CAMERA, ConfigError, Length, SchemeSpec, as_list, check_keys, choice, describe_params, number, vec3

TUNE_KEYS = ("lambda", "steps", "lr", "temperature", "schedule", "seed", "batch", "params", "range", "camera",
             "bias_map", "scan", "gradcheck")
CAMERA_KEYS = ("name", "position", "target", "up", "fov", "role")
ROLES = ("train", "heldout")
SCHEDULES = ("geometric", "linear")
MAP_KEYS = ("block", "unit", "init", "steps", "lr", "fit", "radius", "min_gain", "margin")
MAP_FITS = ("adam", "residual")
MAP_UNITS = ("world", "texel")
CLIP = 30.0              # |margin / T| beyond which the sigmoid is flat (its derivative below 1e-13)
NAN = float("nan")       # one object: lists of rows compare equal where both hold it
BETA1 = 0.5              # Adam's first-moment decay (0.9 carries the iterate past the flat optimum of a
                         # piecewise-constant objective when the gradient flips as the temperature falls)
BETA2 = 0.9              # and second-moment decay: the gradient's scale falls by orders of magnitude as the
                         # iterate leaves the dense thresholds and the temperature drops; 0.999 remembers the
                         # early scale and stalls the steps


def tunable(module) -> tuple:
    """The continuous parameters of a scheme module (Length, float): the ones tuning can move."""
    return tuple(f.name for f in dataclasses.fields(module.Params)
                 if f.type in ("Length", Length, "float", float))


def _valid_min(module, name):
    f = {f.name: f for f in dataclasses.fields(module.Params)}[name]
    return f.metadata.get("min")


# ---------------------------------------------------------------- the [tune] table

@dataclass(frozen=True)
class TuneCamera:
    """One [[tune.camera]]: a pose and its role."""
    name: str
    position: tuple
    target: tuple
    up: tuple = (0.0, 0.0, 1.0)
    fov: float = 40.0
    role: str = "train"


@dataclass(frozen=True)
class BiasMapSpec:
    """``[tune.bias_map]``: block size in texels, the bias's unit and start, and Adam's steps and learning rate."""
    block: int = 1
    unit: str = "world"
    init: Length = Length(0.0, "world")
    steps: int = 100
    lr: float = 0.5
    fit: str = "adam"                 # adam: a bias per block by Adam; residual: see dsm.tune.residual_map
    blocks: tuple = (1, 2, 4)         # residual: the candidates of validation (block, radius, min_gain)
    radii: tuple = (0, 1, 2)
    gains: tuple = (1, 2, 3)
    margin: float = 0.5               # residual: texels kept inside a block's optimal interval


@dataclass(frozen=True)
class TuneSpec:
    """``[tune]``, checked: lambda, the step budget, learning rate, temperature schedule, parameters, cameras."""
    lam: float = 1.0
    steps: int = 100
    lr: float = 0.5                         # texels per step at the start temperature
    temperature: tuple = (0.25, 0.02)         # texels: start, end
    schedule: str = "geometric"
    seed: int = 7
    batch: float = 1.0                        # fraction of training receivers drawn per step
    params: dict = field(default_factory=dict)     # scheme name -> tuned parameter names
    ranges: dict = field(default_factory=dict)     # (scheme name, parameter) -> (lo, hi) in its unit
    cameras: tuple = ()
    bias_map: BiasMapSpec | None = None
    scan: int = 0                             # points of the exact 1-D scan of a one-parameter scheme (0: none)
    gradcheck: bool = False                   # AD against central differences of the relaxed loss, per parameter


@dataclass
class TuneConfig:
    """A tune run: the experiment Config, its checked ``[tune]`` spec and the scheme instances to tune."""
    config: object       # the experiment Config (scenes, lights, map)
    spec: TuneSpec
    schemes: tuple       # the SchemeSpecs to tune (the config's [[scheme]] instances)


def parse_tune(cfg) -> TuneConfig:
    """The ``[tune]`` table of an experiment config, checked (ConfigError naming file, key and
    choices) before any work: the schemes to tune are the config's ``[[scheme]]`` instances."""
    from ..schemes import get
    src = cfg.source
    raw = cfg.raw.get("tune", {})
    if not isinstance(raw, dict):
        raise ConfigError(src, "tune", "expected a table [tune]")
    check_keys(raw, TUNE_KEYS, src, "tune")
    lam = number(raw.get("lambda", 1.0), src, "tune.lambda", minimum=0)
    steps = number(raw.get("steps", 100), src, "tune.steps", integer=True, minimum=1, maximum=100000)
    lr = number(raw.get("lr", TuneSpec.lr), src, "tune.lr", positive=True)
    temp = raw.get("temperature", list(TuneSpec.temperature))
    if not isinstance(temp, list) or len(temp) != 2:
        raise ConfigError(src, "tune.temperature", f"expected [start, end] in texels, got {temp!r}")
    temp = tuple(number(t, src, "tune.temperature", positive=True) for t in temp)
    if temp[0] < temp[1]:
        raise ConfigError(src, "tune.temperature", f"[start, end] anneals down: start must be at or above end, "
                          f"got [{temp[0]:g}, {temp[1]:g}] (e.g. [0.25, 0.02])")
    schedule = choice(raw.get("schedule", "geometric"), src, "tune.schedule", SCHEDULES)
    seed = number(raw.get("seed", cfg.seed), src, "tune.seed", integer=True)
    batch = number(raw.get("batch", 1.0), src, "tune.batch", positive=True, maximum=1.0)
    scan = number(raw.get("scan", 0), src, "tune.scan", integer=True, minimum=0, maximum=100000)
    if scan == 1:                 # evenly spaced with both ends of the box: one point holds only the low end
        raise ConfigError(src, "tune.scan", "a scan takes both ends of the search box: give 0 (no scan) or at least 2")
    gradcheck = raw.get("gradcheck", False)
    if not isinstance(gradcheck, bool):
        raise ConfigError(src, "tune.gradcheck", f"expected true or false, got {gradcheck!r}", (True, False))

    from .. import lights as light_types
    for i, light in enumerate(cfg.lights):      # the objective and oracles count a hard V*, one ray per receiver
        if light.type in light_types.REGISTRY and light_types.is_soft(light):
            raise ConfigError(src, f"light[{i}].type", "dsm tune's objective and oracles are those of a hard V* "
                              "(one ray per receiver); an area light's reference is a fraction: remove it (dsm run "
                              "measures it)", tuple(t for t in light_types.REGISTRY if t != light.type))
    if cfg.map.moments:           # dsm tune's objective relaxes a margin per tap: depth schemes only
        raise ConfigError(src, "map.kind", "dsm tune tunes depth schemes; remove the pre-filtered kinds from "
                          "map.kind (dsm run measures them)", ("depth",))
    # the schemes: the config's [[scheme]] instances, each with something to tune
    specs = []
    for i, s in enumerate(cfg.schemes):
        if s.preset is not None:
            raise ConfigError(src, f"scheme[{i}].preset", "dsm tune tunes scheme parameters, not presets: give "
                              "the combined scheme with the preset's values (dsm schemes lists them)")
        if getattr(get(s.name), "VIEWS", None) is not None:      # a VSV lookup (dsm.maps.vsv): no depth map to tune on
            raise ConfigError(src, f"scheme[{i}].name", f"{s.name} reads a voxelized shadow volume; dsm tune tunes "
                              "shadow-map schemes", _tunable_names())
        if not tunable(get(s.name)):
            raise ConfigError(src, f"scheme[{i}].name", f"{s.name} has no continuous parameter to tune",
                              _tunable_names())
        specs.append(s)
    names = sorted({s.name for s in specs})
    params_raw = raw.get("params", {})
    if not isinstance(params_raw, dict):
        raise ConfigError(src, "tune.params", "expected a table: scheme name = [parameter names]")
    params = {}
    for n in names:
        mod = get(n)
        chosen = as_list(params_raw.get(n, list(tunable(mod))))
        for p in chosen:
            choice(p, src, f"tune.params.{n}", tunable(mod))
        if not chosen:
            raise ConfigError(src, f"tune.params.{n}", "empty list", tunable(mod))
        params[n] = tuple(dict.fromkeys(chosen))
    for n in params_raw:
        if n not in names:
            raise ConfigError(src, f"tune.params.{n}", "no [[scheme]] of that name is tuned", names)
    for i, s in enumerate(specs):              # specs are cfg.schemes, every one kept (or refused above)
        for p in params[s.name]:
            v = getattr(s.params, p)
            if not math.isfinite(v.value if isinstance(v, Length) else v):
                raise ConfigError(src, f"scheme[{i}].{p}", f"{s.name}.{p} starts at {v}: give a finite start to tune "
                                  f"it, or leave it out of tune.params.{s.name}", params[s.name])
    ranges = {}
    range_raw = raw.get("range", {})
    if not isinstance(range_raw, dict):
        raise ConfigError(src, "tune.range", "expected tables [tune.range.<scheme>] of parameter = [lo, hi]")
    for n, t in range_raw.items():
        if n not in names:
            raise ConfigError(src, f"tune.range.{n}", "no [[scheme]] of that name is tuned", names)
        if not isinstance(t, dict):
            raise ConfigError(src, f"tune.range.{n}", "expected a table of parameter = [lo, hi]")
        for p, lohi in t.items():
            key = f"tune.range.{n}.{p}"
            choice(p, src, key, params[n])
            if not isinstance(lohi, list) or len(lohi) != 2:
                raise ConfigError(src, key, f"expected [lo, hi] in the parameter's unit, got {lohi!r}")
            lo, hi = (number(x, src, key) for x in lohi)
            vmin = _valid_min(get(n), p)
            if not lo < hi:
                raise ConfigError(src, key, f"lo must be below hi, got {lohi!r}")
            if vmin is not None and lo < vmin:
                raise ConfigError(src, key, f"lo must be >= {vmin:g} (the parameter's valid range), got {lo!r}")
            ranges[(n, p)] = (lo, hi)

    cams = []
    cam_raw = raw.get("camera", [])
    if isinstance(cam_raw, dict):
        cam_raw = [cam_raw]
    if not isinstance(cam_raw, list) or not all(isinstance(c, dict) for c in cam_raw):
        raise ConfigError(src, "tune.camera", "expected an array of tables [[tune.camera]]")
    for i, c in enumerate(cam_raw):
        w = f"tune.camera[{i}]"
        check_keys(c, CAMERA_KEYS, src, w)
        for k in ("position", "target"):
            if k not in c:
                raise ConfigError(src, f"{w}.{k}", "missing (a camera is a position, a target, an up and a fov)")
        pos, tgt = vec3(c["position"], src, f"{w}.position"), vec3(c["target"], src, f"{w}.target")
        if pos == tgt:
            raise ConfigError(src, f"{w}.target", "the target equals the position")
        up = vec3(c.get("up", [0.0, 0.0, 1.0]), src, f"{w}.up", nonzero=True)
        fwd = np.subtract(tgt, pos)
        if np.linalg.norm(np.cross(fwd, up)) <= 1e-6 * np.linalg.norm(fwd) * np.linalg.norm(up):
            raise ConfigError(src, f"{w}.up", f"{tuple(up)} is along the view direction (target - position); "
                              "give an up across it (default [0, 0, 1])")
        fov = number(c.get("fov", 40.0), src, f"{w}.fov", positive=True, maximum=179.0)
        role = choice(c.get("role", "train"), src, f"{w}.role", ROLES)
        name = c.get("name", f"cam{i}")
        if not isinstance(name, str) or not name:
            raise ConfigError(src, f"{w}.name", "expected a non-empty string")
        cams.append(TuneCamera(name, pos, tgt, up, fov, role))
    if len({c.name for c in cams}) != len(cams):
        raise ConfigError(src, "tune.camera", "camera names must differ")
    if cams and not any(c.role == "train" for c in cams):
        raise ConfigError(src, "tune.camera", "no camera has role = \"train\"", ROLES)

    bmap = None
    if "bias_map" in raw:
        b = raw["bias_map"]
        if not isinstance(b, dict):
            raise ConfigError(src, "tune.bias_map", "expected a table [tune.bias_map]")
        check_keys(b, MAP_KEYS, src, "tune.bias_map")
        unit = choice(b.get("unit", "world"), src, "tune.bias_map.unit", MAP_UNITS)
        init = Length.parse(b.get("init", f"0 {unit}" if unit != "world" else 0.0), src, "tune.bias_map.init")
        if init.unit != unit:
            raise ConfigError(src, "tune.bias_map.init", f"give the start in the map's unit ({unit})", MAP_UNITS)
        fit = choice(b.get("fit", "adam"), src, "tune.bias_map.fit", MAP_FITS)
        def ints(key, default, lo):
            """A bias-map key's candidates: one integer or a non-empty list."""
            vals = as_list(b.get(key, list(default)))
            if not vals:
                raise ConfigError(src, f"tune.bias_map.{key}", f"empty list: give at least one value (default {list(default)})")
            return tuple(number(x, src, f"tune.bias_map.{key}", integer=True, minimum=lo) for x in vals)
        blocks = ints("block", BiasMapSpec.blocks if fit == "residual" else [1], 1)
        if fit == "adam" and len(blocks) != 1:
            raise ConfigError(src, "tune.bias_map.block", "Adam fits one block size: give one number (a list is "
                              "validated with fit = \"residual\")", MAP_FITS)
        for key in ("radius", "min_gain", "margin"):
            if key in b and fit != "residual":
                raise ConfigError(src, f"tune.bias_map.{key}", "only with fit = \"residual\"", MAP_FITS)
        for key in ("unit", "init", "steps", "lr"):     # the residual is in texels, fitted exactly: no Adam
            if key in b and fit == "residual":
                raise ConfigError(src, f"tune.bias_map.{key}", "only with fit = \"adam\" (a residual map is in "
                                  "texels, fitted exactly per block)", MAP_FITS)
        bmap = BiasMapSpec(blocks[0], unit, init,
                           number(b.get("steps", steps), src, "tune.bias_map.steps", integer=True, minimum=1,
                                  maximum=100000),
                           number(b.get("lr", lr), src, "tune.bias_map.lr", positive=True), fit, blocks,
                           ints("radius", BiasMapSpec.radii, 0), ints("min_gain", BiasMapSpec.gains, 1),
                           number(b.get("margin", BiasMapSpec.margin), src, "tune.bias_map.margin", minimum=0))
        if fit == "residual" and sum(c.role == "train" for c in cams) < 2:
            raise ConfigError(src, "tune.camera", "a residual map chooses its block size by leaving one training "
                              "camera out: give at least two [[tune.camera]] with role = \"train\"", ROLES)
        if not any(c.role == "heldout" for c in cams):
            raise ConfigError(src, "tune.camera", "a learned bias map is judged on held-out views: add a "
                              "[[tune.camera]] with role = \"heldout\"", ROLES)

    m = cfg.map
    for key, vals in (("map.resolution", m.resolutions_for(1)), ("map.format", m.format)):
        if len(vals) != 1:
            raise ConfigError(src, key, f"dsm tune fits one map per scene and light: give one value, got {list(vals)}")
    if getattr(m, "cascade", ()):
        raise ConfigError(src, "map.cascades", "dsm tune fits one map per scene and light fixed across views; "
                          "a cascaded view follows its camera: remove the cascades")
    if m.filter != ("nearest",):
        raise ConfigError(src, "map.filter", "dsm tune measures the nearest lookup (the oracles' lookup)",
                          ("nearest",))
    spec = TuneSpec(lam, steps, lr, temp, schedule, seed, batch, params, ranges, tuple(cams), bmap, scan, gradcheck)
    return TuneConfig(cfg, spec, tuple(specs))


def _tunable_names():
    from ..schemes import REGISTRY
    return [s.NAME for s in REGISTRY if tunable(s)]


# ---------------------------------------------------------------- cases: receivers of every view

@dataclass
class Case:
    """One scene, light and camera: receivers seen in the light's shared map."""
    scene: str
    light: str
    camera: str
    role: str
    group: int                 # index of the (scene, light) map
    setup: object              # LightSetup (receivers inside the view)
    rx: object                 # Receiver in the stored map's view
    v_star: np.ndarray
    v_star_dr: object          # mi.Bool
    th: object                 # pipeline.Thresholds (nearest texel, no shift)

    @property
    def n(self) -> int:
        """The number of receivers in this case."""
        return int(self.v_star.size)


@dataclass
class Group:
    """One scene and light: its map per culling (one layer set each), shared by all cameras."""
    scene: str
    light: str
    view: object
    maps: dict                 # culling -> stored map
    n_texels: int
    diagonal: float


def _cameras(tc, sd):
    """(name, role, sensor) of every camera: the [[tune.camera]] poses, placed like the config's
    lights (scaled by the scene's scale, then moved by its translation); none: the scene's own."""
    from ..scenes.load import look_at_sensor
    W, H = tc.config.camera_resolution or DEFAULT_CAMERA
    if not tc.spec.cameras:
        return [("scene", "train", sd.sensor)]
    out = []
    s, t = sd.scale, np.asarray(sd.offset, float)
    for c in tc.spec.cameras:
        d = look_at_sensor(np.multiply(c.position, s) + t, np.multiply(c.target, s) + t, c.up, c.fov, W, H)
        out.append((c.name, c.role, mi.load_dict(d)))
    return out


def prepare_cases(tc, progress=None):
    """Load every scene, light and camera; fit each light's map to the union of its cameras'
    receivers; build it for every culling the tuned schemes ask for. (groups, cases, notes)"""
    cfg = tc.config
    fmt = cfg.map.format[0]
    R = cfg.map.resolutions_for(1)[0]
    kind = cfg.map.view[0]
    needs = {}
    for s in tc.schemes:     # every layer a scheme may read: a tuned term may start at 0 (combined's slope_scale)
        needs.setdefault(pl.culling_of(s.params), set()).update(pl.scheme_module(s.name).NEEDS)
    needs.setdefault("none", set())
    groups, cases, notes = [], [], []
    for spec in cfg.scenes:
        sd = pl.load_scene(spec, cfg.camera_resolution, getattr(cfg, "camera", None))   # [camera] pose, if any
        lights = sd.lights_for(cfg.lights)
        closed = pl.closedness(sd)[0] if any(c != "none" for c in needs) else None
        extents = pl.spawn_extents(sd.scene)
        cams = [(name, role, pl.gbuffer(sd, sensor=sensor)) for name, role, sensor in _cameras(tc, sd)]
        for li, light in enumerate(lights):
            label = light.label or light.type
            setups = [(name, role, pl.light_setup(sd, gb, light, label)) for name, role, gb in cams]
            pts = [pl.points_np(s.p) for _, _, s in setups if s.p is not None]
            pts = np.concatenate(pts) if pts else np.zeros((0, 3))
            view = pl.make_view(light, R, pts, sd.bbox, kind)
            maps = {c: pl.store(pl.build_map(sd.scene, view, sorted(nd), c, closed, extents=extents), fmt)
                    for c, nd in needs.items()}
            g = len(groups)
            groups.append(Group(sd.label, label, view, maps, view.n_texels, sd.diagonal))
            for name, role, s in setups:
                if s.p is not None:
                    s = s.subset(view.inside(s.p).numpy().astype(bool))
                if s.p is None or len(s.pixels) == 0:
                    notes.append(f"{sd.label} / {label} / {name}: no receiver (left out)")
                    continue
                smap = maps["none"]
                rx = pl.receivers(smap.view, s, sd.diagonal)
                dr.eval(rx.depth, rx.u_map, rx.v_map, rx.face, rx.texel_world, rx.to_light)
                th = pl.thresholds(rx, smap)
                cases.append(Case(sd.label, label, name, role, g, s, rx, s.v_star.copy(), mi.Bool(s.v_star), th))
            if progress:
                progress(f"{sd.label} / {label}")
    return groups, cases, notes


# ---------------------------------------------------------------- the relaxed loss

def _bilinear_z1(rx, smap):
    """z1 interpolated between the four texel centres around the receiver's map position
    (each read as the nearest lookup would read that texel: clamped to the face, the far
    bound beyond a directional map), continuous in the lookup point."""
    x, y = rx.u_map - 0.5, rx.v_map - 0.5
    i0, j0 = dr.floor(dr.detach(x)), dr.floor(dr.detach(y))
    fx, fy = x - i0, y - j0
    z = 0
    for a in (0, 1):
        for b in (0, 1):
            t = lookup.tap_at(rx, smap, i0 + 0.5 + a, j0 + 0.5 + b)
            w = (fx if a else 1.0 - fx) * (fy if b else 1.0 - fy)
            z = z + w * t.z1
    return z


def _resolved(module, params, values: dict, rx):
    """The lookup's resolved parameters (``lookup.resolve``) with the tuned ones replaced by the
    differentiable ``values`` (name -> scalar Float in the parameter's own unit)."""
    ns = vars(lookup.resolve(params, rx)).copy()
    for name, val in values.items():
        cur = getattr(params, name)
        if isinstance(cur, Length):
            if cur.unit == "texel":
                val = val * rx.texel_world
            elif cur.unit == "range":
                val = val * dr.opaque(mi.Float, rx.view.depth_range)
        ns[name] = val
    return SimpleNamespace(**ns)


def margins(module, params, values, rx, smap, relax: bool):
    """The scheme's signed margin per receiver with ``values`` substituted (differentiable);
    ``relax``: z1 read bilinearly (for parameters that move the lookup point)."""
    prm = _resolved(module, params, values, rx)
    rx2 = module.shift(rx, prm)
    tap = lookup.nearest_tap(rx2, smap)
    if relax:
        tap = dataclasses.replace(tap, z1=_bilinear_z1(rx2, smap))
    return module.margin(rx2, tap, prm)


def relaxed_sum(m, rx, v_star_dr, t_texels, lam, weight=None):
    """sum over truly lit (1 - s) + lambda sum over truly shadowed s, s = sigmoid(m / T),
    T = t texel_world (a Dr.Jit scalar)."""
    x = dr.clip(m / (t_texels * rx.texel_world), -CLIP, CLIP)
    s = 1.0 / (1.0 + dr.exp(-x))
    per = dr.select(v_star_dr, 1.0 - s, lam * s)
    if weight is not None:
        per = per * weight
    return dr.sum(per)


def relaxed_loss(module, params, values, cases, groups, t_texels, lam, weights=None):
    """The relaxed objective over ``cases`` (a Dr.Jit scalar with the graph to ``values``)."""
    relax = module.shift is not no_shift and any(
        k in values for k in ("offset", "normal_offset"))
    culling = pl.culling_of(params)
    total, n = 0.0, 0
    t = dr.opaque(mi.Float, float(t_texels))
    for i, c in enumerate(cases):
        smap = groups[c.group].maps[culling]
        m = margins(module, params, values, c.rx, smap, relax)
        w = None if weights is None else weights[i]
        total = total + relaxed_sum(m, c.rx, c.v_star_dr, t, lam, w)
        n += c.n            # a batch's weights are 1 / batch on the drawn receivers: the same expectation
    return total / max(n, 1), relax


def relaxed_loss_np(module, params, values: dict, cases, groups, t_texels, lam) -> float:
    """The same relaxed loss computed from the kit's forward margins in numpy float64 (the
    finite-difference tests' second computation)."""
    vals = {k: mi.Float(float(v)) for k, v in values.items()}
    relax = module.shift is not no_shift and any(k in vals for k in ("offset", "normal_offset"))
    culling = pl.culling_of(params)
    total, n = 0.0, 0
    for c in cases:
        m = margins(module, params, vals, c.rx, groups[c.group].maps[culling], relax)
        x = np.asarray(m.numpy(), np.float64) / (t_texels * np.asarray(c.rx.texel_world.numpy(), np.float64))
        x = np.clip(x, -CLIP, CLIP)
        s = 1.0 / (1.0 + np.exp(-x))
        total += float(np.where(c.v_star, 1.0 - s, lam * s).sum())
        n += c.n
    return total / max(n, 1)


# ---------------------------------------------------------------- hard (exact) evaluation

def with_values(spec: SchemeSpec, values: dict) -> SchemeSpec:
    """The scheme instance with tuned values (numbers, in each parameter's own unit)."""
    upd = {}
    for k, v in values.items():
        cur = getattr(spec.params, k)
        upd[k] = Length(float(v), cur.unit) if isinstance(cur, Length) else float(v)
    return SchemeSpec(spec.name, dataclasses.replace(spec.params, **upd))


def hard_counts(spec: SchemeSpec, cases, groups) -> dict:
    """Exact counts of one scheme instance over ``cases`` with the kit's nearest lookup."""
    acne = pp = n = lit = 0
    culling = pl.culling_of(spec.params)
    for c in cases:
        v, _ = pl.visibility(spec, c.rx, groups[c.group].maps[culling])
        on = v.numpy() >= 0.5
        acne += int((c.v_star & ~on).sum())
        pp += int((~c.v_star & on).sum())
        n += c.n
        lit += int(c.v_star.sum())
    return _counts(acne, pp, n, lit)


def _counts(acne, pp, n, lit) -> dict:
    sh = n - lit
    nan = float("nan")
    return {"n_receivers": n, "n_gt_lit": lit, "n_gt_shadowed": sh, "n_acne": acne, "n_peterpan": pp,
            "acne_rate": acne / lit if lit else nan, "peterpan_rate": pp / sh if sh else nan,
            "error_rate": (acne + pp) / n if n else nan}


def _sync_clock():
    dr.sync_thread()
    return time.perf_counter()


# ---------------------------------------------------------------- tuning one scheme

@dataclass
class Param:
    """One tuned parameter: its unit, start, step scale (one texel's worth in its unit) and search range."""
    name: str
    unit: str                  # world | texel | range | "" (a plain number)
    start: float
    scale: float
    lo: float
    hi: float


# parameters that are lengths without being Lengths: K multiplies the scene's diagonal (adaptive)
DIAGONAL_FRACTIONS = {("adaptive", "K")}
BOX_TEXELS = 16.0         # the default search range: [valid minimum or 0, start + 16 texels' worth]


def texel_sizes(train, groups) -> dict:
    """One texel's worth in each unit, over the training receivers: world (the mean texel
    width), range (that over the mean depth range), diagonal (that over the mean scene diagonal)."""
    tw = float(np.mean(np.concatenate([c.th.texel_world for c in train]).astype(np.float64)))
    used = sorted({c.group for c in train})
    rng = float(np.mean([groups[g].view.depth_range for g in used]))
    diag = float(np.mean([groups[g].diagonal for g in used]))
    return {"texel": 1.0, "world": tw, "range": tw / rng, "diagonal": tw / diag, "": 1.0}


def _param_box(tc, spec, sizes, oracle_best=None) -> list:
    """Each tuned parameter: its start, its step scale (one texel's worth in its unit; 1 for
    factors on the slope) and its search range. ``oracle_best``: the exact oracle's best constant
    bias of the training views per unit (world, texel), from the thresholds: constant's default
    range reaches twice it, so it always holds the best value."""
    from ..schemes import get
    mod = get(spec.name)
    out = []
    for name in tc.spec.params[spec.name]:
        cur = getattr(spec.params, name)
        v = cur.value if isinstance(cur, Length) else float(cur)
        unit = cur.unit if isinstance(cur, Length) else ""
        scale = sizes["diagonal" if (spec.name, name) in DIAGONAL_FRACTIONS else unit]
        vmin = _valid_min(mod, name)
        best = (oracle_best or {}).get(unit) if (spec.name, name) == ("constant", "bias") else None
        reach = 2.0 * best if best is not None and math.isfinite(best) else 0.0
        lo, hi = tc.spec.ranges.get((spec.name, name), (0.0 if vmin is None else vmin,
                                                        max(max(v, 0.0) + BOX_TEXELS * scale, reach)))
        if vmin is not None:
            lo = max(lo, vmin)
        out.append(Param(name, unit, min(max(v, lo), hi), scale, lo, hi))
    return out


def temperature_at(spec: TuneSpec, step: int, steps: int) -> float:
    """The temperature in texels at ``step`` of ``steps``: geometric or linear from its start to its end."""
    t0, t1 = spec.temperature
    f = step / max(steps - 1, 1)
    return t0 * (t1 / t0) ** f if spec.schedule == "geometric" else t0 + (t1 - t0) * f


def _batch_weights(spec: TuneSpec, cases, rng):
    if spec.batch >= 1.0:
        return None
    return [mi.Float((rng.random(c.n) < spec.batch).astype(np.float32) / spec.batch) for c in cases]


COARSE_SHARE = 4          # a quarter of the evaluations (after the start) for the coarse grid


def _evaluation_row(spec, phase, step, values, hard, **extra) -> dict:
    """One row of steps.csv: an evaluation of the exact objective (its phase: start, coarse, gradient)."""
    return {"scheme": spec.name, "phase": phase, "step": step, "temperature_texel": NAN, "loss": NAN,
            "hard_objective": hard, "time_ms": NAN, **{f"param_{k}": v for k, v in values.items()}, **extra}


def coarse_grid(box, budget: int) -> list:
    """At most ``budget`` points of a regular grid over ``box``, at cell centres (k per parameter,
    k = floor(budget^(1/p)))."""
    k = max(1, int(math.floor(budget ** (1.0 / len(box)) + 1e-9))) if budget >= 1 else 0
    if k == 0:
        return []
    axes = [b.lo + (np.arange(k) + 0.5) * (b.hi - b.lo) / k for b in box]
    return [{b.name: float(x) for b, x in zip(box, combo)}
            for combo in np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(box))]


def phase_budgets(steps: int) -> dict:
    """How ``steps`` exact evaluations are spent: the start, a coarse grid (a quarter of the rest),
    the exact local refinement (another quarter), Adam steps (what remains)."""
    coarse = refine = (steps - 1) // COARSE_SHARE
    return {"start": 1, "coarse": coarse, "gradient": steps - 1 - coarse - refine, "refine": refine}


def tune_scheme(tc, spec: SchemeSpec, train, groups, progress=None, oracle_best=None) -> dict:
    """Within ``steps`` evaluations of the exact training objective: the start, a coarse grid of
    the search box (a quarter of them), Adam on the relaxed loss from the better of the two
    (one evaluation per step), then a compass search on the exact objective around the best
    point so far (the last quarter). The best evaluation is returned, so the result is never
    worse than the start or any point the search saw. Per evaluation its phase, the loss,
    the exact objective and the step's time."""
    ts = tc.spec
    box = _param_box(tc, spec, texel_sizes(train, groups), oracle_best)
    exact = lambda vals: objective(hard_counts(with_values(spec, vals), train, groups), ts.lam)
    budget = phase_budgets(ts.steps)
    start = {p.name: p.start for p in box}
    best = (exact(start), start)
    rows = [_evaluation_row(spec, "start", 0, start, best[0])]
    grid = coarse_grid(box, budget["coarse"])
    for vals in grid:
        rows.append(_evaluation_row(spec, "coarse", len(rows), vals, exact(vals)))
        if rows[-1]["hard_objective"] < best[0]:
            best = (rows[-1]["hard_objective"], vals)
    for _ in rows:
        if progress:
            progress()
    # a coarse grid may hold fewer points than its share (k^p <= share): Adam takes the rest
    adam = _adam(tc, spec, box, train, groups, best[1], ts.steps - len(rows) - budget["refine"], len(rows), progress)
    for r in adam["rows"]:
        if r["hard_objective"] < best[0]:
            best = (r["hard_objective"], {p.name: r[f"param_{p.name}"] for p in box})
    rows += adam["rows"]
    k = max(1, round(len(grid) ** (1.0 / len(box)))) if grid else 1
    ref = exact_refinement(spec, box, best, train, groups, ts.lam, exact, ts.steps - len(rows), k)
    for phase, vals, obj in ref["evaluations"]:
        rows.append(_evaluation_row(spec, phase, len(rows), vals, obj))
        if progress:
            progress()
    best = ref["best"]
    times = [r["time_ms"] for r in adam["rows"]] or [0.0]
    return {"values": best[1], "box": box, "steps": rows, "relaxed_lookup": adam["relax"],
            "first_step_ms": times[0], "step_ms": float(np.median(times[1:])) if len(times) > 1 else times[0],
            "total_ms": float(sum(times)) + ref["ms"], "refine_ms": ref["ms"], "evaluations": len(rows)}


def margin_line(module, params, values: dict, direction: dict, cases, groups) -> tuple:
    """Every receiver's exact (nearest-lookup) margin at ``values`` and its derivative along
    ``direction`` (parameter name -> change per unit step, in the parameter's unit), by Dr.Jit's
    forward-mode AD: (margin, slope), float64 arrays over the cases in order."""
    culling = pl.culling_of(params)
    m_all, g_all = [], []
    for c in cases:
        a = mi.Float(0.0)
        dr.enable_grad(a)
        vals = {k: dr.opaque(mi.Float, float(v)) + a * dr.opaque(mi.Float, float(direction.get(k, 0.0)))
                for k, v in values.items()}
        m = margins(module, params, vals, c.rx, groups[c.group].maps[culling], relax=False)
        dr.forward(a)
        m_all.append(np.asarray(dr.detach(m).numpy(), np.float64))
        g_all.append(np.asarray(dr.grad(m).numpy(), np.float64))
    return np.concatenate(m_all), np.concatenate(g_all)


def line_objective(m, g, v_star, lam, a_lo: float, a_hi: float) -> tuple:
    """The exact objective of margins that are affine in a step ``a`` (``m + a g``), at its best
    over ``[a_lo, a_hi]``: each receiver flips at ``a = -m / g``; counted at the ends and at the
    midpoints between consecutive flips by sorted counts (the threshold sweep of the exact
    oracles, along any line). (best step, its objective); ties: the widest interval's midpoint."""
    with np.errstate(divide="ignore", invalid="ignore"):
        flip = -m / g
    up, down, flat = g > 0, g < 0, g == 0
    inside = np.sort(flip[(up | down) & (flip > a_lo) & (flip < a_hi)])
    edges = np.unique(np.concatenate([[a_lo], inside, [a_hi]]))
    cands = np.concatenate([[a_lo], 0.5 * (edges[:-1] + edges[1:]), [a_hi]]) if len(edges) > 1 else edges
    width = np.concatenate([[0.0], np.diff(edges), [0.0]]) if len(edges) > 1 else np.zeros(1)
    err = np.zeros(len(cands))
    for sel, lit_when_above in ((up, True), (down, False)):
        for truth, weight in ((True, 1.0), (False, lam)):
            th = np.sort(flip[sel & (v_star == truth)])
            # lit iff a >= flip (g > 0) or a <= flip (g < 0); an error when lit differs from the truth
            n_lit = np.searchsorted(th, cands, "right") if lit_when_above else len(th) - np.searchsorted(th, cands, "left")
            err += weight * ((len(th) - n_lit) if truth else n_lit)
    err += float(((m[flat] < 0) & v_star[flat]).sum() + lam * ((m[flat] >= 0) & ~v_star[flat]).sum())
    obj = err / max(m.size, 1)
    best = np.flatnonzero(obj == obj.min())
    i = best[np.argmax(width[best])]
    return float(cands[i]), float(obj[i])


def line_search(module, spec, box, best, train, groups, lam, p) -> dict:
    """The exact objective's best along parameter ``p`` from ``best``'s values, under the
    receivers' margins linearised in that parameter (forward AD), within ``p``'s range: the
    point to evaluate (exact for a margin affine in the parameter: constant, receiver plane,
    adaptive; a candidate to check otherwise) and the objective the linearisation predicts there."""
    vals = best[1]
    m, g = margin_line(module, spec.params, vals, {p.name: 1.0}, train, groups)
    v_star = np.concatenate([c.v_star for c in train])
    a, predicted = line_objective(m, g, v_star, lam, p.lo - vals[p.name], p.hi - vals[p.name])
    return {**vals, p.name: min(max(vals[p.name] + a, p.lo), p.hi)}, predicted


def exact_refinement(spec, box, best, train, groups, lam, exact, budget: int, cells: int) -> dict:
    """At most ``budget`` exact evaluations around ``best``: a compass search (keeping two per
    parameter back), exact line searches along each parameter until a round gains nothing, and
    the compass search again with what is left. {best, evaluations: (phase, values, objective), ms}."""
    t0, out = _sync_clock(), []
    ref = compass_search(box, exact, best, max(budget - 2 * len(box), 0), cells)
    out += [("refine", v, o) for v, o in ref["evaluations"]]
    best, seen, improved = ref["best"], set(), True
    while improved and len(out) < budget:     # exact line searches along each parameter
        improved = False
        for p in box:
            if len(out) >= budget:
                break
            vals, predicted = line_search(get_scheme(spec.name), spec, box, best, train, groups, lam, p)
            key = tuple(vals[q.name] for q in box)
            if key in seen or predicted >= best[0]:     # the model is exact at the current point: no gain
                continue
            seen.add(key)
            out.append(("line", vals, exact(vals)))
            if out[-1][2] < best[0]:
                best, improved = (out[-1][2], vals), True
    ref = compass_search(box, exact, best, budget - len(out), cells)
    out += [("refine", v, o) for v, o in ref["evaluations"]]
    return {"best": ref["best"], "evaluations": out, "ms": (_sync_clock() - t0) * 1e3}


def compass_search(box, exact, best, budget: int, cells: int) -> dict:
    """Compass (pattern) search on the exact objective from ``best`` = (objective, values), at most
    ``budget`` new evaluations: each parameter is tried one step up and down (clipped to its
    range; a point already evaluated is not evaluated again), a strict improvement moves there,
    and a poll with none halves every step. First step: half a coarse-grid cell (``cells``
    points per parameter). Hooke & Jeeves, "Direct search solution of numerical and
    statistical problems", J. ACM 1961; Kolda, Lewis & Torczon, SIAM Review 2003 (compass search).
    The exact objective is piecewise constant, so its gradient is 0 almost everywhere: near the
    relaxed loss's optimum only a direct search on the exact objective can pick its best step."""
    steps = {p.name: (p.hi - p.lo) / cells / 2.0 for p in box}
    seen = {tuple(best[1][p.name] for p in box)}
    evaluations, t0 = [], _sync_clock()
    while len(evaluations) < budget and any(v > 0 for v in steps.values()):
        moved = False
        for p in box:
            for sign in (1.0, -1.0):
                if len(evaluations) >= budget:
                    break
                vals = dict(best[1])
                vals[p.name] = min(max(best[1][p.name] + sign * steps[p.name], p.lo), p.hi)
                key = tuple(vals[q.name] for q in box)
                if key in seen:
                    continue
                seen.add(key)
                obj = exact(vals)
                evaluations.append((vals, obj))
                if obj < best[0]:
                    best, moved = (obj, vals), True
                    break
        if not moved:
            steps = {k: v / 2.0 for k, v in steps.items()}
            if max(s / (p.hi - p.lo) for p, s in zip(box, steps.values())) < 1e-7:
                break                # below float32 resolution of the box: nothing left to find
    return {"best": best, "evaluations": evaluations, "ms": (_sync_clock() - t0) * 1e3}


def _adam(tc, spec, box, train, groups, origin: dict, steps: int, first: int, progress=None) -> dict:
    """``steps`` Adam steps on the relaxed loss from ``origin``; each step's exact objective."""
    from ..schemes import get
    mod, ts = get(spec.name), tc.spec
    rng = np.random.default_rng(ts.seed)
    opt = mi.ad.Adam(lr=ts.lr, beta_1=BETA1, beta_2=BETA2)
    for p in box:
        opt[p.name] = mi.Float(origin[p.name] / p.scale)
    rows, relax = [], False
    for step in range(steps):
        t_texels = temperature_at(ts, step, steps)
        w = _batch_weights(ts, train, rng)
        opt.set_learning_rate(ts.lr * t_texels / ts.temperature[0])      # steps shrink with the temperature
        t0 = _sync_clock()
        values = {p.name: opt[p.name] * p.scale for p in box}
        loss, relax = relaxed_loss(mod, spec.params, values, train, groups, t_texels, ts.lam, w)
        dr.backward(loss)
        grads = {p.name: float(dr.grad(opt[p.name]).numpy().ravel()[0]) / p.scale for p in box}
        opt.step()
        for p in box:
            opt[p.name] = dr.clip(opt[p.name], p.lo / p.scale, p.hi / p.scale)
        dr.eval(*[opt[p.name] for p in box])
        ms = (_sync_clock() - t0) * 1e3
        cur = {p.name: float(opt[p.name].numpy().ravel()[0]) * p.scale for p in box}
        hard = objective(hard_counts(with_values(spec, cur), train, groups), ts.lam)
        rows.append({**_evaluation_row(spec, "gradient", first + step, cur, hard), "temperature_texel": t_texels,
                     "loss": float(loss.numpy().ravel()[0]), "time_ms": ms,
                     **{f"grad_{k}": g for k, g in grads.items()}})
        if progress:
            progress()
    return {"rows": rows, "relax": relax}


def grid_search(tc, spec: SchemeSpec, box, train, groups, budget: int) -> dict:
    """The best hard training objective over a regular grid of the same box with at most
    ``budget`` evaluations (points per parameter: floor(budget^(1/p)))."""
    p = len(box)
    k = max(1, int(math.floor(budget ** (1.0 / p) + 1e-9)))
    axes = [np.linspace(b.lo, b.hi, k) for b in box]
    best, evals = None, 0
    t0 = _sync_clock()
    for combo in np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, p):
        vals = {b.name: float(x) for b, x in zip(box, combo)}
        obj = objective(hard_counts(with_values(spec, vals), train, groups), tc.spec.lam)
        evals += 1
        if best is None or obj < best[0]:
            best = (obj, vals)
    ms = (_sync_clock() - t0) * 1e3
    return {"values": best[1], "objective": best[0], "evaluations": evals, "points_per_parameter": k,
            "total_ms": ms}


def exact_scan(tc, spec: SchemeSpec, box, train, groups, points: int) -> dict | None:
    """A one-parameter scheme's exact training objective at ``points`` evenly spaced values of its
    search range, ends included (the reference the tuner is held to; for a constant bias, the
    oracle's curve sampled); None for a scheme tuning more than one parameter."""
    if len(box) != 1 or points < 1:
        return None
    b = box[0]
    best, t0 = None, _sync_clock()
    for x in np.linspace(b.lo, b.hi, points):
        obj = objective(hard_counts(with_values(spec, {b.name: float(x)}), train, groups), tc.spec.lam)
        if best is None or obj < best[0]:
            best = (obj, {b.name: float(x)})
    return {"values": best[1], "objective": best[0], "evaluations": points, "total_ms": (_sync_clock() - t0) * 1e3}


GRADCHECK_STEP = 0.01      # texels' worth: the central difference's half step


def gradient_check(tc, spec: SchemeSpec, box, train, groups) -> dict:
    """Per tuned parameter at the start: the relaxed loss's derivative by Dr.Jit AD (all
    parameters differentiated together) against a central difference of the same loss computed
    in numpy float64 from the kit's forward margins, at the first temperature; half step
    ``GRADCHECK_STEP`` texels' worth in the parameter's unit. {name: {ad, fd, rel_error}}."""
    ts, mod = tc.spec, get_scheme(spec.name)
    start = {p.name: p.start for p in box}
    x = {p.name: mi.Float(float(p.start)) for p in box}
    for v in x.values():
        dr.enable_grad(v)
    loss, _ = relaxed_loss(mod, spec.params, x, train, groups, ts.temperature[0], ts.lam)
    dr.backward(loss)
    out = {}
    for p in box:
        h = GRADCHECK_STEP * p.scale
        f = lambda v: relaxed_loss_np(mod, spec.params, {**start, p.name: v}, train, groups, ts.temperature[0], ts.lam)
        fd = (f(p.start + h) - f(p.start - h)) / (2 * h)
        ad = float(dr.grad(x[p.name]).numpy().ravel()[0])
        out[p.name] = {"ad": ad, "fd": fd, "rel_error": abs(ad - fd) / abs(fd) if fd else NAN}
    return out


# ---------------------------------------------------------------- oracles of pooled cases

def pooled_thresholds(cases, groups):
    """The cases' thresholds as one set, texel ids made unique per map (group)."""
    off = np.cumsum([0] + [g.n_texels for g in groups])
    th = [c.th for c in cases]
    cat = lambda k: np.concatenate([getattr(t, k) for t in th])
    texel = np.concatenate([c.th.texel + off[c.group] for c in cases])
    return pl.Thresholds(cat("tau"), cat("kappa"), texel, cat("z1"), cat("depth"), cat("texel_world")), \
        np.concatenate([c.v_star for c in cases])


# ---------------------------------------------------------------- learned bias map

def _blocks(cases, groups, block):
    """Per case the block index (unique across maps) of each receiver's nearest texel; the
    number of blocks."""
    offs, total = [], 0
    for g in groups:
        R = g.view.resolution
        nb = -(-R // block)
        offs.append((total, R, nb))
        total += g.view.faces * nb * nb
    out = []
    for c in cases:
        base, R, nb = offs[c.group]
        t = c.th.texel
        face, rest = t // (R * R), t % (R * R)
        i, j = rest % R, rest // R
        out.append(base + (face * nb + j // block) * nb + i // block)
    return out, total


def _map_margin(c, groups, bias_world):
    smap = groups[c.group].maps["none"]
    tap = lookup.nearest_tap(c.rx, smap)
    return tap.z1 + bias_world - c.rx.depth


def map_start(tc, train, groups, const=None) -> np.ndarray:
    """The bias map's start per map (group), in the map's unit: the best tuned constant bias
    (``const``, a result entry) converted with the group's mean texel width over its training
    receivers, so a block no training view sees keeps the tuned global bias; without one,
    ``[tune.bias_map] init``."""
    bm = tc.spec.bias_map
    out = np.full(len(groups), bm.init.value, np.float64)
    if const is None:
        return out
    b = const["spec"].params.bias
    for g in range(len(groups)):
        tws = [c.th.texel_world for c in train if c.group == g]
        tw = float(np.mean(np.concatenate(tws))) if tws else float(texel_sizes(train, groups)["world"])
        world = b.value * {"world": 1.0, "texel": tw, "range": groups[g].view.depth_range}[b.unit]
        out[g] = world if bm.unit == "world" else world / tw
    return out


def tune_bias_map(tc, train, held, groups, init_values, progress=None) -> dict:
    """Adam on one bias per block (started per map at ``init_values``, in the map's unit)."""
    bm, ts = tc.spec.bias_map, tc.spec
    blk_train, nblocks = _blocks(train, groups, bm.block)
    blk_held, _ = _blocks(held, groups, bm.block)
    scale = texel_sizes(train, groups)[bm.unit]      # steps in texels' worth, as the schemes'
    opt = mi.ad.Adam(lr=bm.lr, beta_1=BETA1, beta_2=BETA2)
    per_group = [g.view.faces * (-(-g.view.resolution // bm.block)) ** 2 for g in groups]
    start = np.repeat(np.asarray(init_values, np.float64), per_group)
    opt["b"] = mi.Float((start / scale).astype(np.float32))
    idx_train = [mi.UInt32(b.astype(np.uint32)) for b in blk_train]
    tex = bm.unit == "texel"
    rows = []

    def bias(c, idx, b):
        """Case ``c``'s bias in world units: block values ``b`` at ``idx`` (a texel map's times texel_world)."""
        val = dr.gather(mi.Float, b, idx) * scale
        return val * c.rx.texel_world if tex else val

    lo = min(0.0, float(start.min()))                # a bias map never goes below 0 unless started there
    for step in range(bm.steps):
        t_texels = temperature_at(ts, step, bm.steps)
        opt.set_learning_rate(bm.lr * t_texels / ts.temperature[0])
        t0 = _sync_clock()
        b = opt["b"]
        total = 0.0
        tt = dr.opaque(mi.Float, t_texels)
        for c, idx in zip(train, idx_train):
            total = total + relaxed_sum(_map_margin(c, groups, bias(c, idx, b)), c.rx, c.v_star_dr, tt, ts.lam)
        loss = total / max(sum(c.n for c in train), 1)
        dr.backward(loss)
        opt.step()
        opt["b"] = dr.maximum(opt["b"], lo / scale)
        dr.eval(opt["b"])
        ms = (_sync_clock() - t0) * 1e3
        hard = objective(_map_counts(train, idx_train, groups, opt["b"], scale, tex), ts.lam)
        rows.append({"scheme": "bias_map", "step": step, "temperature_texel": t_texels,
                     "loss": float(loss.numpy().ravel()[0]), "hard_objective": hard, "time_ms": ms})
        if progress:
            progress()
    b = opt["b"]
    seen = np.zeros(nblocks, bool)
    for x in blk_train:
        seen[x] = True
    idx_held = [mi.UInt32(x.astype(np.uint32)) for x in blk_held]
    cov_n = sum(int(seen[x].sum()) for x in blk_held)
    n_held = sum(c.n for c in held)
    times = [r["time_ms"] for r in rows]
    return {"values": np.asarray(b.numpy(), np.float64) * scale, "blocks": nblocks, "block": bm.block,
            "unit": bm.unit, "init": [float(x) for x in init_values], "steps": rows,
            "train": _map_counts(train, idx_train, groups, b, scale, tex),
            "heldout": _map_counts(held, idx_held, groups, b, scale, tex),
            "heldout_lit": _map_lit(held, idx_held, groups, b, scale, tex),
            "heldout_covered": [seen[x] for x in blk_held],
            "heldout_covered_fraction": cov_n / n_held if n_held else float("nan"),
            "blocks_trained": int(seen.sum()),
            "first_step_ms": times[0], "step_ms": float(np.median(times[1:])) if len(times) > 1 else times[0],
            "total_ms": float(sum(times))}


def _map_lit(cases, idxs, groups, b, scale, tex) -> list:
    """Per case whether each receiver is lit under the bias map ``b``."""
    out = []
    for c, idx in zip(cases, idxs):
        val = dr.gather(mi.Float, dr.detach(b), idx) * scale
        out.append((_map_margin(c, groups, val * c.rx.texel_world if tex else val) >= 0).numpy())
    return out


def _map_counts(cases, idxs, groups, b, scale, tex) -> dict:
    acne = pp = n = lit = 0
    for c, on in zip(cases, _map_lit(cases, idxs, groups, b, scale, tex)):
        acne += int((c.v_star & ~on).sum())
        pp += int((~c.v_star & on).sum())
        n += c.n
        lit += int(c.v_star.sum())
    return _counts(acne, pp, n, lit)


def margin_arrays(spec: SchemeSpec, cases, groups) -> dict:
    """A scheme instance's exact margins and what a residual map reads, per receiver over ``cases``
    (numpy: m, v_star, unit = texel_world, texel, group, resolution)."""
    mod, culling = get_scheme(spec.name), pl.culling_of(spec.params)
    ms = [np.asarray(margins(mod, spec.params, {}, c.rx, groups[c.group].maps[culling], False).numpy(), np.float64)
          for c in cases]
    cat = lambda xs: np.concatenate(xs) if xs else np.zeros(0)
    return {"m": cat(ms), "v_star": cat([c.v_star for c in cases]).astype(bool),
            "unit": cat([c.th.texel_world for c in cases]).astype(np.float64),
            "texel": cat([c.th.texel for c in cases]).astype(np.int64),
            "group": cat([np.full(c.n, c.group, np.int64) for c in cases]).astype(np.int64),
            "resolution": cat([np.full(c.n, groups[c.group].view.resolution, np.int64) for c in cases]).astype(np.int64)}


def residual_bias_map(tc, train, held, groups, base) -> dict:
    """The residual map over the best global scheme (``base``, a result entry): candidates
    validated leaving one training camera out, the chosen one fitted to every training view
    (dsm.tune.residual_map); its counts on the training and held-out views."""
    from . import residual_map as rm
    bm, lam = tc.spec.bias_map, tc.spec.lam
    t0 = _sync_clock()
    rx_tr, rx_he = margin_arrays(base["spec"], train, groups), margin_arrays(base["spec"], held, groups)
    cams = np.concatenate([np.full(c.n, c.camera) for c in train])
    ch = rm.choose(rx_tr, cams, bm.blocks, bm.radii, bm.gains, lam, bm.margin)
    block, radius, gain = ch["chosen"] or (bm.blocks[0], 0, math.inf)      # none: coverage by the first block
    fit = rm.smoothed_fit(rx_tr, block, radius, lam, bm.margin)
    m_tr, _ = rm.apply(fit, gain, rx_tr, block)
    m_he, covered = rm.apply(fit, gain, rx_he, block)
    moved = rm.residuals(fit, gain)
    counts = lambda m, v: _counts(int(((m < 0) & v).sum()), int(((m >= 0) & ~v).sum()), int(v.size), int(v.sum()))
    split = np.cumsum([c.n for c in held])[:-1]
    return {"fit": "residual", "base": f"{base['scheme']} {base['params']}", "block": block, "radius": radius,
            "min_gain": gain if ch["chosen"] else None, "chosen": ch["chosen"] is not None,
            "validation": {"none": ch["none"], "scores": ch["scores"]}, "unit": "texel",
            "values": np.stack([fit["keys"].astype(np.float64), moved]), "blocks": int(fit["keys"].size),
            "blocks_trained": int(fit["keys"].size), "blocks_moved": int((moved != 0).sum()), "steps": [],
            "train": counts(m_tr, rx_tr["v_star"]), "heldout": counts(m_he, rx_he["v_star"]),
            "heldout_lit": np.split(m_he >= 0, split), "heldout_covered": np.split(covered, split),
            "heldout_covered_fraction": float(covered.mean()) if covered.size else NAN,
            "init": [], "total_ms": (_sync_clock() - t0) * 1e3}


def heldout_split(held, groups, lit_map, covered, best_spec, lam) -> dict:
    """The learned map against the best global scheme and the per-texel oracle over the held-out
    receivers whose block saw training receivers (``covered``) and over the rest, with the share
    of the gap to the oracle the map closes: (global - map) / (global - oracle)."""
    v = np.concatenate([c.v_star for c in held])
    lit_map, covered = np.concatenate(lit_map), np.concatenate(covered).astype(bool)
    culling = pl.culling_of(best_spec.params)
    lit_best = np.concatenate([pl.visibility(best_spec, c.rx, groups[c.group].maps[culling])[0].numpy() >= 0.5
                               for c in held])
    th, vs = pooled_thresholds(held, groups)
    out = {}
    for name, sel in (("covered", covered), ("uncovered", ~covered)):
        n = int(sel.sum())
        obj = lambda lit: float(((~lit & v)[sel].sum() + lam * (lit & ~v)[sel].sum()) / n) if n else NAN
        sub = pl.Thresholds(**{f.name: getattr(th, f.name)[sel] for f in dataclasses.fields(th)})
        orc = pl.oracles(sub, vs[sel], lam)["row"]["per_texel_objective"] if n else NAN
        g, m = obj(lit_best), obj(lit_map)
        out[name] = {"n_receivers": n, "map": m, "best_global": g, "per_texel_oracle": orc,
                     "gap_closed": (g - m) / (g - orc) if n and g > orc else NAN}
    return out


# ---------------------------------------------------------------- the whole run

@dataclass
class TuneResult:
    """What ``dsm tune`` writes: per tuned scheme its values, hard metrics on the training and
    held-out views, the grid search and (constant) the oracle; the per-step rows; the learned
    bias map's result; the comparison rows."""
    schemes: list
    steps: list
    comparison: list
    bias_map: dict | None
    notes: list
    n_train: int
    n_heldout: int
    tuned_toml: str
    spec: TuneSpec
    resumed: int = 0      # schemes kept from the previous tune in the folder (--resume)

    def best(self):
        """The tuned scheme with the lowest training objective."""
        return min(self.schemes, key=lambda s: s["train"]["objective"]) if self.schemes else None


def tune(config, out=None, progress: bool = False, variant: str | None = None, resume: bool = False) -> TuneResult:
    """Tune every ``[[scheme]]`` of ``config`` (a Config, dict or TOML path with a ``[tune]``
    table) on its training views; write the results into ``out`` when given (``resume``: keep
    the schemes the tune already in ``out`` finished with the same input)."""
    from ..config.read import coerce
    config = coerce(config)
    tc = parse_tune(config)                   # the [tune] table checked before any scene loads
    tc.config = pl.prepare(config, variant)
    return run_tune(tc, out, progress, resume)


def run_tune(tc, out=None, progress: bool = False, resume: bool = False) -> TuneResult:
    """Tune and grid-search each scheme of a prepared ``tc``, then the bias map; write into ``out``
    if given, with the state ``--resume`` reads after each scheme (``resume``: keep its finished ones)."""
    ts = tc.spec
    bar = None
    if progress:
        from tqdm import tqdm
        total = len(tc.config.scenes) + ts.steps * len(tc.schemes) + (
            ts.bias_map.steps if ts.bias_map and ts.bias_map.fit == "adam" else 0)
        bar = tqdm(total=total, desc="dsm tune", unit="step", leave=False)
    tick = (lambda *a: bar.update(1)) if bar else None
    groups, cases, notes = prepare_cases(tc, tick)
    train = [c for c in cases if c.role == "train"]
    held = [c for c in cases if c.role == "heldout"]
    if not train:
        raise ConfigError(tc.config.source, "tune.camera", "no training view has a receiver")
    n_train, n_held = sum(c.n for c in train), sum(c.n for c in held)
    th_train, vs_train = pooled_thresholds(train, groups)
    orc_train = pl.oracles(th_train, vs_train, ts.lam)["row"]
    orc_held = pl.oracles(*pooled_thresholds(held, groups), ts.lam)["row"] if held else None
    results, steps, comparison = [], [], []
    keys = tune_resume.scheme_keys(tc)
    previous = tune_resume.read_state(out) if (resume and out is not None) else {}
    finished, kept = [], 0
    for spec, key in zip(tc.schemes, keys):
        if key in previous:                 # finished by the tune in ``out`` with this very input
            entry = {**previous[key]["entry"], "spec": with_values(spec, previous[key]["entry"]["values"])}
            results.append(entry)
            steps += previous[key]["steps"]
            comparison.append(_comparison_row(entry, ts.steps))
            finished.append(previous[key])
            kept += 1
            if tick:
                for _ in range(ts.steps):
                    tick()
            continue
        r = tune_scheme(tc, spec, train, groups, tick, {"world": orc_train["best_b"], "texel": orc_train["best_k"]})
        tuned = with_values(spec, r["values"])
        g = grid_search(tc, spec, r["box"], train, groups, ts.steps)
        grid_spec = with_values(spec, g["values"])
        scan = exact_scan(tc, spec, r["box"], train, groups, ts.scan)
        check = gradient_check(tc, spec, r["box"], train, groups) if ts.gradcheck else None
        entry = {"scheme": spec.name, "start": describe_params(spec.params), "params": describe_params(tuned.params),
                 "values": r["values"], "units": {p.name: p.unit for p in r["box"]},
                 "box": {p.name: [p.lo, p.hi] for p in r["box"]}, "relaxed_lookup": r["relaxed_lookup"],
                 "spec": tuned, "train": _with_obj(hard_counts(tuned, train, groups), ts.lam),
                 "heldout": _with_obj(hard_counts(tuned, held, groups), ts.lam) if held else None,
                 "start_train": _with_obj(hard_counts(spec, train, groups), ts.lam),
                 "start_heldout": _with_obj(hard_counts(spec, held, groups), ts.lam)["objective"] if held else NAN,
                 "gradcheck": check,
                 "scan": None if scan is None else {**scan, "params": describe_params(with_values(spec, scan["values"]).params)},
                 "first_step_ms": r["first_step_ms"], "step_ms": r["step_ms"], "tune_ms": r["total_ms"],
                 "grid": {**g, "params": describe_params(grid_spec.params),
                          "heldout": _with_obj(hard_counts(grid_spec, held, groups), ts.lam)["objective"]
                          if held else float("nan")}}
        if spec.name == "constant":
            unit = getattr(spec.params, "bias").unit
            tag = "texel" if unit == "texel" else "world" if unit == "world" else None
            if tag:
                entry["oracle"] = {"kind": tag, "objective": orc_train[f"{tag}_objective"],
                                   "bias": orc_train["best_k" if tag == "texel" else "best_b"]}
        results.append(entry)
        steps += r["steps"]
        comparison.append(_comparison_row(entry, ts.steps))
        if out is not None:                 # after each scheme, so a stopped tune resumes from here
            finished.append({"key": key, "entry": {k: v for k, v in entry.items() if k != "spec"},
                             "steps": r["steps"]})
            tune_resume.write_state(out, tc.config.name, finished)
    bmap = None
    if ts.bias_map and held:
        const = [e for e in results if e["scheme"] == "constant"]
        best_const = min(const, key=lambda e: e["train"]["objective"]) if const else None
        best = min(results, key=lambda e: e["train"]["objective"]) if results else None
        if ts.bias_map.fit == "residual" and best is not None:
            bmap = residual_bias_map(tc, train, held, groups, best)
            bmap["init_from"] = bmap["base"]
        else:
            init = map_start(tc, train, groups, best_const)
            bmap = tune_bias_map(tc, train, held, groups, init, tick)
            bmap["init_from"] = best_const["params"] if best_const else str(ts.bias_map.init)
        bmap["train"] = _with_obj(bmap["train"], ts.lam)
        bmap["heldout"] = _with_obj(bmap["heldout"], ts.lam)
        lit, covered = bmap.pop("heldout_lit"), bmap.pop("heldout_covered")
        if best is not None:
            bmap["heldout_split"] = heldout_split(held, groups, lit, covered, best["spec"], ts.lam)
        bmap["per_texel_oracle_heldout"] = orc_held["per_texel_objective"]
        bmap["per_texel_oracle_train"] = orc_train["per_texel_objective"]
        bmap["best_global"] = ({"scheme": best["scheme"], "params": best["params"],
                                "heldout": best["heldout"]["objective"], "train": best["train"]["objective"]}
                               if best else None)
        steps += bmap["steps"]
    elif ts.bias_map:
        notes.append("no held-out view has a receiver: the learned bias map was not trained")
    if bar:
        bar.close()
    res = TuneResult(results, steps, comparison, bmap, notes, n_train, n_held, tuned_toml(results), ts, kept)
    if out is not None:
        write(res, Path(out), orc_train, orc_held)
    return res


def _with_obj(counts, lam):
    return {**counts, "objective": objective(counts, lam)}


def _comparison_row(e, budget):
    g = e["grid"]
    row = {"scheme": e["scheme"], "tuned_params": e["params"], "tuned_train": e["train"]["objective"],
           "tuned_heldout": e["heldout"]["objective"] if e["heldout"] else float("nan"),
           "tuned_ms": e["tune_ms"], "tuned_evaluations": budget, "first_step_ms": e["first_step_ms"],
           "step_ms": e["step_ms"],
           "grid_params": g["params"], "grid_train": g["objective"], "grid_heldout": g["heldout"],
           "grid_ms": g["total_ms"], "grid_evaluations": g["evaluations"],
           "oracle": e.get("oracle", {}).get("objective", float("nan")),
           "start_train": e["start_train"]["objective"], "start_heldout": e["start_heldout"],
           "scan_params": e["scan"]["params"] if e["scan"] else "-",
           "scan_train": e["scan"]["objective"] if e["scan"] else NAN,
           "scan_evaluations": e["scan"]["evaluations"] if e["scan"] else 0}
    return row


def tuned_toml(results) -> str:
    """The tuned instances as ready ``[[scheme]]`` blocks."""
    lines = ["# tuned by dsm tune: paste into an experiment config"]
    for e in results:
        lines.append("[[scheme]]")
        lines.append(f'name = "{e["scheme"]}"')
        for f in dataclasses.fields(e["spec"].params):
            v = getattr(e["spec"].params, f.name)
            if isinstance(v, Length):
                if not math.isfinite(v.value):
                    continue               # a default without a finite value (no clamp): left at its default
                lines.append(f'{f.name} = {v.value!r}' if v.unit == "world" else f'{f.name} = "{v.value!r} {v.unit}"')
            elif isinstance(v, float):
                lines.append(f"{f.name} = {v!r}")
            elif isinstance(v, str):
                lines.append(f'{f.name} = "{v}"')
        lines.append(f"# train objective {e['train']['objective']:.6f}")
        lines.append("")
    return "\n".join(lines)


# ---------------------------------------------------------------- output folder

def _fmt(x):
    if isinstance(x, float):
        return "-" if math.isnan(x) else f"{x:.5f}"
    return str(x)


def table_text(res: TuneResult) -> str:
    """The Markdown summary (``table.md``): a row per tuned scheme against grid search and oracle, then the bias map."""
    lam = res.spec.lam
    out = [f"# dsm tune (lambda = {lam:g}; objective (n_acne + lambda n_peterpan) / n_receivers)", "",
           f"training receivers {res.n_train}, held-out receivers {res.n_heldout}", "",
           "| scheme | tuned | train | held-out | tune ms (evals; first, median step) | grid best | grid train "
           "| grid held-out | grid ms (evals) | oracle (train) | start train | start held-out | 1-D scan best "
           "| scan train (evals) | tuned / scan |",
           "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in res.comparison:
        out.append(f"| {r['scheme']} | {r['tuned_params']} | {_fmt(r['tuned_train'])} | {_fmt(r['tuned_heldout'])} "
                   f"| {r['tuned_ms']:.0f} ({r['tuned_evaluations']}; {r['first_step_ms']:.1f}, {r['step_ms']:.1f}) "
                   f"| {r['grid_params']} | {_fmt(r['grid_train'])} "
                   f"| {_fmt(r['grid_heldout'])} | {r['grid_ms']:.0f} ({r['grid_evaluations']}) "
                   f"| {_fmt(r['oracle'])} | {_fmt(r['start_train'])} | {_fmt(r['start_heldout'])} "
                   f"| {r['scan_params']} | {_fmt(r['scan_train'])} ({r['scan_evaluations']}) "
                   f"| {_fmt(r['tuned_train'] / r['scan_train']) if r['scan_train'] > 0 else '-'} |")
    checks = [(e["scheme"], k, g) for e in res.schemes for k, g in (e.get("gradcheck") or {}).items()]
    if checks:
        out += ["", f"## gradient check (relaxed loss at the start, temperature {res.spec.temperature[0]:g} texel; "
                f"central difference, half step {GRADCHECK_STEP:g} texel's worth, numpy float64)", "",
                "| scheme | parameter | AD | central difference | relative error |", "| --- | --- | --- | --- | --- |"]
        out += [f"| {n} | {k} | {g['ad']:.6g} | {g['fd']:.6g} | {_fmt(g['rel_error'])} |" for n, k, g in checks]
    if res.bias_map:
        b = res.bias_map
        bg = b["best_global"]
        if b.get("fit") == "residual":
            how = (f"a residual in texels over {b['base']}, blocks of {b['block']} x {b['block']} texels fitted "
                   f"exactly to the training receivers of the blocks within {b['radius']} of each, moved where they "
                   f"gain at least {b['min_gain']} errors ({b['blocks_moved']} of {b['blocks']} blocks moved)"
                   if b["chosen"] else f"no residual over {b['base']}: no candidate (block, radius, min_gain) "
                   f"beat it leaving one training camera out ({b['validation']['none']:g} errors; best candidate "
                   f"{min((s['errors'] for s in b['validation']['scores']), default=float('nan')):g})")
            head = f"{how}; {_fmt(b['heldout_covered_fraction'])} of held-out receivers fall in trained blocks"
        else:
            head = (f"{b['blocks']} blocks of {b['block']} x {b['block']} texels ({b['blocks_trained']} with training "
                    f"receivers; {_fmt(b['heldout_covered_fraction'])} of held-out receivers fall in them), unit "
                    f"{b['unit']}, started from {b['init_from']} (per map: "
                    f"{', '.join(f'{x:.4g}' for x in b['init'])})")
        out += ["", "## learned bias map", "", head, "",
                "| | train | held-out |", "| --- | --- | --- |",
                f"| learned map | {_fmt(b['train']['objective'])} | {_fmt(b['heldout']['objective'])} |",
                f"| per-texel oracle (of those views) | {_fmt(b['per_texel_oracle_train'])} "
                f"| {_fmt(b['per_texel_oracle_heldout'])} |"]
        if bg:
            out.append(f"| best tuned global ({bg['scheme']} {bg['params']}) | {_fmt(bg['train'])} "
                       f"| {_fmt(bg['heldout'])} |")
        if b.get("heldout_split"):
            out += ["", "| held-out receivers | n | learned map | best tuned global | per-texel oracle | gap closed |",
                    "| --- | --- | --- | --- | --- | --- |"]
            for name, r in b["heldout_split"].items():
                out.append(f"| in {'trained' if name == 'covered' else 'untrained'} blocks | {r['n_receivers']} "
                           f"| {_fmt(r['map'])} | {_fmt(r['best_global'])} | {_fmt(r['per_texel_oracle'])} "
                           f"| {_fmt(r['gap_closed'])} |")
    if res.notes:
        out += ["", "notes: " + "; ".join(res.notes)]
    return "\n".join(out) + "\n"


def write(res: TuneResult, out: Path, orc_train=None, orc_held=None):
    """Write ``res`` into folder ``out``: tuned.toml, steps.csv, table.md, tune.json, bias_map.npy and the plots."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "tuned.toml").write_text(res.tuned_toml)
    keys = []
    for r in res.steps:
        keys += [k for k in r if k not in keys]
    with open(out / "steps.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, keys, restval="")
        w.writeheader()
        for r in res.steps:
            w.writerow({k: ("" if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()})
    (out / "table.md").write_text(table_text(res))
    doc = {"lambda": res.spec.lam, "n_train": res.n_train, "n_heldout": res.n_heldout, "notes": res.notes,
           "schemes": [{k: v for k, v in e.items() if k not in ("spec",)} for e in res.schemes],
           "comparison": res.comparison, "oracle_train": orc_train, "oracle_heldout": orc_held,
           "bias_map": None if res.bias_map is None else
           {k: v for k, v in res.bias_map.items() if k not in ("steps", "values")}}
    if res.bias_map is not None:
        np.save(out / "bias_map.npy", res.bias_map["values"])
    (out / "tune.json").write_text(json.dumps(_no_nan(doc), indent=1, default=_json_default))
    plot(res, out / "plots")


def _no_nan(o):
    """Undefined values (NaN) as JSON null."""
    if isinstance(o, dict):
        return {str(k): _no_nan(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_no_nan(v) for v in o]
    if isinstance(o, Param):
        return _no_nan(dataclasses.asdict(o))
    if isinstance(o, (float, np.floating)):
        return None if math.isnan(o) else float(o)
    return o


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    return str(o)


def plot(res: TuneResult, folder: Path):
    """Plot each scheme's relaxed loss and hard objective per step into ``folder``/tune_loss.png."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    folder.mkdir(parents=True, exist_ok=True)
    names = list(dict.fromkeys(r["scheme"] for r in res.steps))
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for name in names:
        rows = [r for r in res.steps if r["scheme"] == name]
        s = [r["step"] for r in rows]
        axes[0].plot(s, [r["loss"] for r in rows], label=name)
        axes[1].plot(s, [r["hard_objective"] for r in rows], label=name)
    axes[0].set(title="relaxed loss", xlabel="step")
    axes[1].set(title=f"hard objective (lambda = {res.spec.lam:g})", xlabel="step")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    with atomic(folder / "tune_loss.png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
