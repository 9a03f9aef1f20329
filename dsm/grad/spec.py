"""What ``dsm grad`` differentiates, read once into a frozen :class:`GradSpec`.

``[gradient]`` holds what is gradient's own: the parameters, the loss (and its target), the central
difference's step, the image of receivers, the references' and comparisons' settings. The scene,
the light, the map and the bias come from the kit's own tables (:mod:`.kit_tables`): ``[[scene]]``
(an occluder built-in: a square plate, a box or a mesh of side ``size`` at ``height`` over a ground
at z = 0), ``[[light]]`` (a spot straight down from [0, 0, H], a directional light tilted in the
x-z plane, or a square area light facing down: its truth :func:`dsm.truth.area.irradiance_fraction`),
``[map]`` (resolution, kind, filter, blur, antialias) and ``[[scheme]]`` (a constant bias). Every
mistake is a ConfigError naming the file, the key and the valid choices, before any work; a key of the
old flat ``[gradient]`` table is refused with one line naming its new table and key. The image is the
ground seen from above: ``image_resolution``^2 receivers over [-window, window]^2, one per pixel: at a
seeded random point of the pixel (``image_jitter``, the default) or at its centre.
"""
from __future__ import annotations

import math

from dataclasses import dataclass, field

from ..config.read import read_toml
from ..core.types import ConfigError, check_keys, choice, number, as_list
from . import kit_tables, support
from .technique import MOMENT_TECHNIQUES, Technique

# a differentiable parameter: (its unit, the lights it applies to or None for every light)
PARAMS = {
    "occluder_z": ("world", None),        # the occluder's translation along z (the plate's height)
    "occluder_x": ("world", None),        # the occluder's translation along x (the box's offset)
    "corner_z": ("world", None),          # a displacement along z of the occluder's first vertex
    "light_height": ("world", ("point", "area")),   # the point light's z (the area light's centre's)
    "light_x": ("world", ("point", "area")),        # the point light's x (the area light's centre's)
    "light_angle": ("degree", ("directional",)),    # the directional light's tilt from the vertical toward +x
}
SCENES = tuple(kit_tables.SCENES.values())  # GradSpec.scene (each a [[scene]] builtin's: kit_tables.SCENES)
LIGHTS = tuple(support.LIGHTS.values())     # GradSpec.light: the kit light types dsm grad differentiates
LOSSES = ("shadow_area", "shadow_moment_x", "l2")
# the unit of each loss, given the world unit of length
LOSS_UNITS = {"shadow_area": "world^2", "shadow_moment_x": "world^3", "l2": "1 (mean over pixels)"}
# the depth map's filters grad differentiates, then every pre-filtered kind of the kit's registry
TECHNIQUES = support.FILTERS + MOMENT_TECHNIQUES
MIN_SHADOW_PIXELS = 4     # the shadow's least width in image pixels: fewer leave no edge to differentiate
FLOAT32_STEP = 2.0 ** -24  # a float32 depth's relative step
MIN_DEPTH_STEPS = 4       # the occluder-ground gap's least size in float32 depth steps at the light's distance
KEYS = ("image_resolution", "window", "params", "loss", "target", "pcss_light_size", "fd_step", "fd_halvings",
        "image_jitter", "reference_samples", "reference_step", "projective_spp", "projective_seeds",
        "projective_integrators", "inverse_starts", "inverse_iterations", "inverse_tolerance", "light_samples",
        "equal_error_spp", "equal_error_seeds")
TABLES = ("gradient", "scene", "light", "map", "scheme")    # the config's tables dsm grad reads
MAX_LIGHT_SAMPLES = 32          # the area light's truth: light samples per axis and receiver (32^2 rays each)
# the central difference's default step per unit (world: a fraction of the occluder's size)
FD_STEP = {"world": 2e-3, "degree": 0.02}
# Mitsuba's projective-sampling integrators (dsm.grad.projective)
PROJECTIVE_INTEGRATORS = ("direct_projective", "prb_projective")
# the supersampled reference's default step per unit (world: a fraction of the occluder's size; measured
# at 32^2 receivers per pixel: its error estimate under 1 % of the closed forms, dsm.grad.reference)
REFERENCE_STEP = {"world": 0.04, "degree": 1.0}


@dataclass(frozen=True)
class GradSpec:
    """What ``dsm grad`` differentiates: the scene, the parameters (with units), loss and techniques."""
    scene: str = "plate"
    mesh: str = ""                           # scene = "mesh": the occluder's PLY or OBJ file (absolute path)
    light: str = "point"
    light_height: float = 2.0
    light_angle: float = 20.0
    occluder_height: float = 0.5
    occluder_size: float = 0.5
    box_height: float | None = None          # scene = "box": its height (world); None: occluder_size (a cube)
    map_resolution: int = 128
    image_resolution: int = 128
    window: float = 1.0
    params: tuple = ("occluder_z",)
    loss: str = "shadow_area"
    target: tuple = ()                       # ((param, value), ...): the l2 loss's target parameters
    techniques: tuple = field(default_factory=lambda: tuple(Technique(t) for t in TECHNIQUES))
    bias: float = 0.02
    light_size: float = 0.1                  # world: PCSS's light width; the area light's side
    fd_step: tuple = ()                      # ((param, step), ...) in the parameter's unit
    fd_halvings: int = 4
    image_jitter: bool = True                # one receiver per pixel at a seeded random point (else its centre)
    reference_samples: int = 32              # the reference's receivers per pixel and axis (stratified)
    reference_step: tuple = ()               # ((param, step), ...): the reference's central difference
    projective_spp: int = 64                 # Mitsuba's projective integrator: samples per pixel
    projective_seeds: int = 4                # ... and its seeds (bias and spread of a stochastic gradient)
    projective_integrators: tuple = PROJECTIVE_INTEGRATORS
    inverse_starts: tuple = (-0.1, -0.05, 0.05, 0.1)   # the inverse task's starts: offsets from the truth
    inverse_iterations: int = 40
    inverse_tolerance: float = 0.01          # a start succeeds when its final error is within this
    light_samples: int = 8                   # the area light's truth: stratified light samples per axis and receiver
    equal_error_spp: tuple = (1, 4, 16, 64, 256)      # --compare under an area light: path tracing's spp sweep
    equal_error_seeds: int = 4               # ... and its seeds per spp (its error's bias and spread)
    source: str = "<gradient>"

    def thickness(self) -> float:
        """The occluder's extent in z above ``occluder_height`` (world): 0 for the plate, the box's height,
        ``occluder_size`` for a mesh (scaled to fit the cube)."""
        if self.scene == "plate":
            return 0.0
        return self.box_height if self.scene == "box" and self.box_height is not None else self.occluder_size

    def unit(self, param: str) -> str:
        """The unit of parameter ``param`` (world or degree)."""
        return PARAMS[param][0]

    def step(self, param: str) -> float:
        """The central difference's step of ``param`` in its unit."""
        return self.step_in(param, self.fd_step, FD_STEP)

    def reference_step_of(self, param: str) -> float:
        """The supersampled reference's central-difference step of ``param`` in its unit."""
        return self.step_in(param, self.reference_step, REFERENCE_STEP)

    def step_in(self, param: str, given: tuple, defaults: dict) -> float:
        """``param``'s step as ``given`` ((param, step), ...), else its unit's default in ``defaults``: a
        world step in units of ``occluder_size``, so the difference scales with the scene."""
        if param in dict(given):
            return dict(given)[param]
        base = defaults[self.unit(param)]
        return base * self.occluder_size if self.unit(param) == "world" else base

    def nominal(self) -> dict:
        """Every parameter's value at the configured scene (the point where gradients are taken)."""
        return {"occluder_z": 0.0, "occluder_x": 0.0, "corner_z": 0.0, "light_height": self.light_height,
                "light_x": 0.0, "light_angle": self.light_angle}


def load(path) -> GradSpec:
    """The GradSpec of TOML file ``path`` (its ``[gradient]`` and the kit's tables); ConfigError for any mistake."""
    return parse(read_toml(path), str(path))


# an old flat [gradient] key -> (the kit's table that holds it now, what to give there; {v}: the old value)
MOVED = {
    "scene": ("[[scene]]", 'builtin = "occluder_plate" (or "occluder_box", "occluder_mesh")'),
    "mesh": ("[[scene]]", 'builtin = "occluder_mesh", mesh = {v}'),
    "light": ("[[light]]", 'type = "spot" (was "point"), "directional" or "area" (shape = "rectangle")'),
    "light_height": ("[[light]]", "position = [0, 0, {v}]"),
    "light_angle": ("[[light]]", 'type = "directional", direction = {v} (a tilt a: [sin a, 0, -cos a])'),
    "occluder_height": ("[[scene]]", "height = {v}"),
    "occluder_size": ("[[scene]]", "size = {v}"),
    "box_height": ("[[scene]]", "box_height = {v}"),
    "map_resolution": ("[map]", "resolution = {v}"),
    "techniques": ("[map]", 'kind = ["depth", ...] (and the moment kinds) with filter = [...] (the depth map\'s)'),
    "blur": ("[map]", "blur = {v}"),
    "antialias": ("[map]", "antialias = {v}"),
    "bias": ("[[scheme]]", 'name = "constant", bias = {v}'),
    "light_size": ("[[light]]", "size = {v} (an area light's side; PCSS's light width under a spot or "
                                "directional light is gradient.pcss_light_size)"),
}


def moved(key: str, value) -> str:
    """Where old flat ``[gradient]`` key ``key`` (given ``value``) lives now, as one line."""
    table, what = MOVED[key]
    if key == "light_angle" and isinstance(value, (int, float)) and not isinstance(value, bool):
        a = math.radians(value)
        value = [round(math.sin(a), 12), 0.0, round(-math.cos(a), 12)]
    v = toml_text(value)
    return f"moved: give {table} {what.format(v=v)} (dsm grad reads the kit's {table} table)"


def toml_text(value) -> str:
    """``value`` as TOML writes it (a user may paste it back): booleans lower case, lists in brackets."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, list):
        return "[" + ", ".join(toml_text(x) for x in value) + "]"
    return f'"{value}"' if isinstance(value, str) else repr(value)


def check_tables(raw: dict, source: str) -> dict:
    """The ``[gradient]`` table of ``raw``, its old keys and the tables dsm grad does not read refused."""
    if "gradient" not in raw or not isinstance(raw["gradient"], dict):
        raise ConfigError(source, "gradient", "a [gradient] table is required (dsm grad reads it)")
    for table in raw:
        if table not in TABLES:
            raise ConfigError(source, table, "dsm grad does not read this table: remove it", TABLES, got=table)
    g = raw["gradient"]
    for key in MOVED:
        if key in g:
            raise ConfigError(source, f"gradient.{key}", moved(key, g[key]))
    check_keys(g, KEYS, source, "gradient")
    return g


def parse(raw: dict, source: str = "<dict>") -> GradSpec:
    """The GradSpec of a config dict: its ``[gradient]`` table and the kit's ``[[scene]]``, ``[[light]]``,
    ``[map]`` and ``[[scheme]]``."""
    g = check_tables(raw, source)
    kw = {"source": source, **kit_tables.read_scene(raw, source), **kit_tables.read_light(raw, source),
          **kit_tables.read_map(raw, source)}
    kw.update(kit_tables.read_scheme(raw, source, kw["techniques"]))
    kw.update(_own_keys(g, source, kw["light"]))
    spec = GradSpec(**kw)
    check_light(spec, source)
    check_extent(spec, source)
    for key in ("fd_step", "reference_step"):
        check_steps(spec, source, key)
    if "inverse_starts" in g:       # the defaults are offsets of a unit-sized scene: a scaled one gives its own
        check_starts(spec, source)
    return spec


def _own_keys(g: dict, source: str, light: str) -> dict:
    """The ``[gradient]`` table's own keys (the image, parameters, loss, steps, comparisons) as GradSpec fields."""
    kw = {}
    if "window" in g:
        kw["window"] = number(g["window"], source, "gradient.window", positive=True)
    if "pcss_light_size" in g:
        if light == "area":
            raise ConfigError(source, "gradient.pcss_light_size", "under an area light PCSS's light width is the "
                              "light's own [[light]] size: remove it")
        kw["light_size"] = number(g["pcss_light_size"], source, "gradient.pcss_light_size", positive=True)
    if "image_resolution" in g:
        kw["image_resolution"] = number(g["image_resolution"], source, "gradient.image_resolution", integer=True,
                                        minimum=8, maximum=kit_tables.MAX_RESOLUTION)
    if "fd_halvings" in g:
        kw["fd_halvings"] = number(g["fd_halvings"], source, "gradient.fd_halvings", integer=True, minimum=0,
                                   maximum=20)
    if "image_jitter" in g:
        if not isinstance(g["image_jitter"], bool):
            raise ConfigError(source, "gradient.image_jitter", f"expected true or false, got {g['image_jitter']!r}")
        kw["image_jitter"] = g["image_jitter"]
    kw.update(_compare_keys(g, source))
    for key in ("light_samples", "equal_error_spp", "equal_error_seeds"):
        if key in g and light != "area":
            raise ConfigError(source, f"gradient.{key}", f"is read only under an area light ([[light]] type = "
                              f"\"area\"), not {kit_type(light)!r}")
    kw["params"] = _params(g, source, light)
    kw["loss"] = choice(g.get("loss", "shadow_area"), source, "gradient.loss", LOSSES)
    kw["target"] = _target(g, source, light, kw["loss"])
    kw["fd_step"] = _steps(g, source, kw["params"])
    kw["reference_step"] = _steps(g, source, kw["params"], "reference_step")
    return kw


def kit_type(light: str) -> str:
    """The kit's [[light]] type of GradSpec.light ``light`` (point: a spot straight down)."""
    return {g: kit for kit, g in support.LIGHTS.items()}[light]


def check_light(spec: GradSpec, source: str):
    """An area light as wide as the image, or a light under the occluder's top, refused."""
    if spec.light == "area" and not spec.light_size < 2.0 * spec.window:
        raise ConfigError(source, "light[0].size", f"the area light's side must be smaller than the image's "
                          f"(2 x gradient.window = {2.0 * spec.window:g}): a larger square hides the whole image from "
                          f"the projective integrators' camera above it; got {spec.light_size:g} (valid: 0 < size "
                          f"< {2.0 * spec.window:g})")
    if spec.light != "directional" and not spec.occluder_height + spec.thickness() < spec.light_height:
        raise ConfigError(source, "light[0].position", f"the light's height must be above the occluder's top "
                          f"({spec.occluder_height + spec.thickness():g}), got {spec.light_height:g}")




def _room(spec: GradSpec) -> dict:
    """How far each parameter may move from its nominal value (in its unit) and the scene stay one: the
    occluder between the ground and the light, the light above the occluder, inside the image's window, a
    directional light above the horizon."""
    top, ground = spec.occluder_height + spec.thickness(), spec.occluder_height
    above = spec.light_height - top if spec.light != "directional" else math.inf
    return {"occluder_z": min(ground, above), "corner_z": min(ground, above), "light_height": above,
            "occluder_x": spec.window, "light_x": spec.window, "light_angle": 90.0 - abs(spec.light_angle)}


def check_starts(spec: GradSpec, source: str):
    """The inverse task's start offsets that leave the scene (a plate under the ground, 1e30) refused."""
    for param in spec.params:
        room = _room(spec)[param]
        far = [s for s in spec.inverse_starts if not abs(s) < room]
        if far:
            raise ConfigError(source, "gradient.inverse_starts", f"{far[0]:g} moves {param} out of the scene "
                              f"(valid: offsets of {param} with |offset| < {room:g} {spec.unit(param)})")


def check_steps(spec: GradSpec, source: str, key: str):
    """A central difference's +-step that moves the occluder under the ground or above the light, or the
    light under the occluder's top, refused: the difference would measure another scene."""
    room = _room(spec)
    for param in spec.params:
        step = spec.step_in(param, getattr(spec, key), REFERENCE_STEP if key == "reference_step" else FD_STEP)
        if not step < room[param]:
            what = {"light_height": "the light under the occluder's top", "occluder_x": "the occluder out of the image",
                    "light_x": "the light out of the image", "light_angle": "the light to the horizon (90 degrees)"}.get(
                param, "the occluder under the ground" if step >= spec.occluder_height else "the occluder above the light")
            raise ConfigError(source, f"gradient.{key}.{param}", f"{step:g} moves {what} at one side of the central "
                              f"difference (valid: 0 < step < {room[param]:g})")


def shadow_half_extent(spec: GradSpec) -> float:
    """How far from the origin the occluder's shadow reaches on the ground (world), at most: its
    half-side scaled by H / (H - h) under a point or area light, shifted by h tan(angle) under the
    directional light (the area light's penumbra reaches further; this bounds its umbra)."""
    half = 0.5 * spec.occluder_size
    if spec.light == "directional":
        return half + spec.occluder_height * abs(math.tan(math.radians(spec.light_angle)))
    return half * spec.light_height / (spec.light_height - spec.occluder_height - spec.thickness())


def check_extent(spec: GradSpec, source: str):
    """The sizes that leave nothing to differentiate, refused in one line: a bias at or above the
    occluder's height (every receiver lit), a shadow larger than the image (its edge, where every
    gradient lives, outside it) or under MIN_SHADOW_PIXELS pixels across, a light so far that float32 depths
    cannot part the occluder from the ground. All relative, so any scale passes."""
    depth = any(t.name not in MOMENT_TECHNIQUES for t in spec.techniques)   # a depth technique reads the bias
    if depth and not spec.bias < spec.occluder_height:
        raise ConfigError(source, "scheme[0].bias", f"must be below the occluder's height above the ground "
                          f"({spec.occluder_height:g}): a larger depth bias lights every receiver; got {spec.bias:g} "
                          f"(valid: 0 <= bias < {spec.occluder_height:g})")
    if spec.light != "directional":      # the map stores float32 depths from the light
        steps = spec.occluder_height / (spec.light_height * FLOAT32_STEP)
        if not steps >= MIN_DEPTH_STEPS:
            raise ConfigError(source, "light[0].position", f"the occluder's height above the ground "
                              f"({spec.occluder_height:g}) is {steps:.3g} float32 depth steps at the light's distance "
                              f"{spec.light_height:g}, under {MIN_DEPTH_STEPS}: the map cannot tell the occluder from "
                              f"the ground (valid: a height <= "
                              f"{spec.occluder_height / (MIN_DEPTH_STEPS * FLOAT32_STEP):g})")
    reach = shadow_half_extent(spec)
    if not reach < spec.window:
        raise ConfigError(source, "gradient.window", f"the occluder's shadow reaches {reach:g} from the centre, "
                          f"beyond the image's half-width {spec.window:g}: its edge, where the gradient is, would be "
                          f"outside the image (valid: window > {reach:g}, or a smaller [[scene]] size)")
    pixels = reach / spec.window * spec.image_resolution
    if not pixels >= MIN_SHADOW_PIXELS:
        raise ConfigError(source, "gradient.window", f"the occluder's shadow spans {pixels:.3g} pixels of the "
                          f"{spec.image_resolution}^2 image, under {MIN_SHADOW_PIXELS} (valid: window <= "
                          f"{reach * spec.image_resolution / MIN_SHADOW_PIXELS:g}, or a larger [[scene]] size)")


def _param_names(raw, source: str, key: str, light: str) -> list:
    names = as_list(raw)
    if not names:
        raise ConfigError(source, key, "empty list", sorted(PARAMS))
    for n in names:
        choice(n, source, key, sorted(PARAMS))
        lights = PARAMS[n][1]
        if lights is not None and light not in lights:
            raise ConfigError(source, key, f"{n} is a parameter of a {' or '.join(kit_type(x) for x in lights)} "
                              f"light and the [[light]] is a {kit_type(light)} light", [p for p, (_, lt) in PARAMS.items() if lt is None or light in lt])
    if len(set(names)) != len(names):
        raise ConfigError(source, key, "a parameter is given twice: give each once")
    return names


def _params(g: dict, source: str, light: str) -> tuple:
    return tuple(_param_names(g.get("params", ["occluder_z"]), source, "gradient.params", light))


def _target(g: dict, source: str, light: str, loss: str) -> tuple:
    if "target" not in g:
        if loss == "l2":
            raise ConfigError(source, "gradient.target", "the l2 loss needs a target: a table of parameter "
                              "values whose exact (ray-traced) image is the target", sorted(PARAMS))
        return ()
    if loss != "l2":
        raise ConfigError(source, "gradient.target", f"is read only with loss = \"l2\", not {loss!r}")
    t = g["target"]
    if not isinstance(t, dict) or not t:
        raise ConfigError(source, "gradient.target", f"expected a table of parameter values, got {t!r}")
    _param_names(list(t), source, "gradient.target", light)
    return tuple((k, number(v, source, f"gradient.target.{k}")) for k, v in t.items())


def _steps(g: dict, source: str, params: tuple, key: str = "fd_step") -> tuple:
    t = g.get(key, {})
    if not isinstance(t, dict):
        raise ConfigError(source, f"gradient.{key}", f"expected a table of steps by parameter, got {t!r}")
    for k in t:
        if k not in params:
            raise ConfigError(source, f"gradient.{key}.{k}", "names no parameter of gradient.params", params)
    return tuple((k, number(v, source, f"gradient.{key}.{k}", positive=True)) for k, v in t.items())


def count(raw, source: str, key: str, lo: int, hi: int) -> int:
    """``raw`` as an integer from ``lo`` to ``hi``; else a ConfigError at ``key`` that names the range."""
    try:
        return number(raw, source, key, integer=True, minimum=lo, maximum=hi)
    except ConfigError as e:
        raise ConfigError(source, key, f"{e.problem} (valid: an integer from {lo} to {hi})") from None


def _compare_keys(g: dict, source: str) -> dict:
    """The reference's, the projective integrator's and the inverse task's keys (dsm grad --compare, --inverse)."""
    kw = {}
    for key, lo, hi in (("reference_samples", 1, 64), ("projective_spp", 1, 4096), ("projective_seeds", 1, 64),
                        ("inverse_iterations", 1, 1000), ("light_samples", 1, MAX_LIGHT_SAMPLES),
                        ("equal_error_seeds", 2, 64)):
        if key in g:
            kw[key] = count(g[key], source, f"gradient.{key}", lo, hi)
    if "inverse_tolerance" in g:
        kw["inverse_tolerance"] = number(g["inverse_tolerance"], source, "gradient.inverse_tolerance", positive=True)
    if "projective_integrators" in g:
        names = as_list(g["projective_integrators"])
        for n in names:
            choice(n, source, "gradient.projective_integrators", PROJECTIVE_INTEGRATORS)
        if len(set(names)) != len(names):
            raise ConfigError(source, "gradient.projective_integrators", "an integrator is given twice: give each once")
        kw["projective_integrators"] = tuple(names)
    if "inverse_starts" in g:
        starts = as_list(g["inverse_starts"])
        if not starts:
            raise ConfigError(source, "gradient.inverse_starts", "empty list")
        kw["inverse_starts"] = tuple(number(x, source, "gradient.inverse_starts") for x in starts)
    if "equal_error_spp" in g:
        kw["equal_error_spp"] = _spp_sweep(g["equal_error_spp"], source)
    return kw


def _spp_sweep(raw, source: str) -> tuple:
    """equal_error_spp: at least two samples-per-pixel counts, increasing (path tracing's error curve)."""
    key = "gradient.equal_error_spp"
    spps = [count(x, source, key, 1, 4096) for x in as_list(raw)]
    if len(spps) < 2 or any(b <= a for a, b in zip(spps, spps[1:])):
        raise ConfigError(source, key, "expected at least two strictly increasing counts, each from 1 to 4096 "
                          f"(e.g. [4, 16, 64, 256, 1024]), "
                          f"got {raw!r}")
    return tuple(int(x) for x in spps)
