"""The ``[gradient]`` table: which scene parameters are differentiated, the loss, the techniques.

Read once into a frozen :class:`GradSpec`; every mistake is a ConfigError naming the file, the
key and the valid choices, before any work. The scene is the kit's gradient test bed: a square
plate (or a box) of side ``occluder_size`` at height ``occluder_height`` over a ground at z = 0,
lit by a point light straight above at ``light_height`` or by a directional light tilted by
``light_angle`` degrees from the vertical toward +x, or by a square area light of side ``light_size``
facing down at ``light_height`` (its truth: :func:`dsm.truth.area.irradiance_fraction`). The image is the ground seen from above:
``image_resolution``^2 receivers over [-window, window]^2, one per pixel: at a seeded random point of
the pixel (``image_jitter``, the default) or at its centre.
"""
from __future__ import annotations

import math

from dataclasses import dataclass, field
from pathlib import Path

from .. import prefilter
from ..config.read import read_toml
from ..core.types import ConfigError, check_keys, choice, number, as_list
from . import support

# a differentiable parameter: (its unit, the lights it applies to or None for every light)
PARAMS = {
    "occluder_z": ("world", None),        # the occluder's translation along z (the plate's height)
    "occluder_x": ("world", None),        # the occluder's translation along x (the box's offset)
    "corner_z": ("world", None),          # a displacement along z of the occluder's first vertex
    "light_height": ("world", ("point", "area")),   # the point light's z (the area light's centre's)
    "light_x": ("world", ("point", "area")),        # the point light's x (the area light's centre's)
    "light_angle": ("degree", ("directional",)),    # the directional light's tilt from the vertical toward +x
}
SCENES = ("plate", "box", "mesh")
MESH_SUFFIXES = (".ply", ".obj")
LIGHTS = tuple(support.LIGHTS.values())     # gradient.light: the kit light types dsm grad differentiates
LOSSES = ("shadow_area", "shadow_moment_x", "l2")
# the unit of each loss, given the world unit of length
LOSS_UNITS = {"shadow_area": "world^2", "shadow_moment_x": "world^3", "l2": "1 (mean over pixels)"}
# the depth map's filters grad differentiates, then every pre-filtered kind of the kit's registry
MOMENT_TECHNIQUES = prefilter.NAMES
TECHNIQUES = support.FILTERS + MOMENT_TECHNIQUES
MAX_BLUR = 31
MAX_RESOLUTION = 4096
MIN_SHADOW_PIXELS = 4     # the shadow's least width in image pixels: fewer leave no edge to differentiate
FLOAT32_STEP = 2.0 ** -24  # a float32 depth's relative step
MIN_DEPTH_STEPS = 4       # the occluder-ground gap's least size in float32 depth steps at the light's distance
KEYS = ("scene", "mesh", "light", "light_height", "light_angle", "occluder_height", "occluder_size", "map_resolution",
        "image_resolution", "window", "params", "loss", "target", "techniques", "blur", "antialias", "bias",
        "light_size", "fd_step", "fd_halvings", "image_jitter", "reference_samples", "reference_step", "projective_spp",
        "projective_seeds", "projective_integrators", "inverse_starts", "inverse_iterations", "inverse_tolerance",
        "light_samples", "equal_error_spp", "equal_error_seeds", "box_height")
MAX_LIGHT_SAMPLES = 32          # the area light's truth: light samples per axis and receiver (32^2 rays each)
# the central difference's default step per unit (world: a fraction of the occluder's size)
FD_STEP = {"world": 2e-3, "degree": 0.02}
# Mitsuba's projective-sampling integrators (dsm.grad.projective)
PROJECTIVE_INTEGRATORS = ("direct_projective", "prb_projective")
# the supersampled reference's default step per unit (world: a fraction of the occluder's size; measured
# at 32^2 receivers per pixel: its error estimate under 1 % of the closed forms, dsm.grad.reference)
REFERENCE_STEP = {"world": 0.04, "degree": 1.0}


@dataclass(frozen=True)
class Technique:
    """One technique instance: its name, blur width in texels (moment maps; 1 elsewhere) and
    whether its map is antialiased (Worchel & Alexa 2023's edge treatment, dsm.grad.antialias)."""
    name: str
    blur: int = 1
    antialias: bool = False

    @property
    def label(self) -> str:
        """The instance as the table names it, e.g. ``vsm blur 3 aa``."""
        out = self.name + (f" blur {self.blur}" if self.name in MOMENT_TECHNIQUES else "")
        return out + (" aa" if self.antialias else "")


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
    """The GradSpec of TOML file ``path``'s ``[gradient]`` table; ConfigError for any mistake."""
    return parse(read_toml(path), str(path))


def parse(raw: dict, source: str = "<dict>") -> GradSpec:
    """The GradSpec of a config dict holding a ``[gradient]`` table (other tables are ignored)."""
    if "gradient" not in raw or not isinstance(raw["gradient"], dict):
        raise ConfigError(source, "gradient", "a [gradient] table is required (dsm grad reads it)")
    g = raw["gradient"]
    check_keys(g, KEYS, source, "gradient")
    kw = {"source": source}
    kw["scene"] = choice(g.get("scene", "plate"), source, "gradient.scene", SCENES)
    kw["light"] = choice(g.get("light", "point"), source, "gradient.light", LIGHTS)
    kw["mesh"] = _mesh(g, source, kw["scene"])
    if "box_height" in g and kw["scene"] != "box":
        raise ConfigError(source, "gradient.box_height", f"is read only with scene = \"box\", not {kw['scene']!r}")
    for key in ("light_height", "occluder_height", "occluder_size", "window", "light_size", "box_height"):
        if key in g:
            kw[key] = number(g[key], source, f"gradient.{key}", positive=True)
    if "light_angle" in g and kw["light"] != "directional":     # it would be ignored, silently
        raise ConfigError(source, "gradient.light_angle", f"is read only with light = \"directional\", not "
                          f"{kw['light']!r} (a point or area light is placed by light_height and light_x)")
    if "light_angle" in g:
        kw["light_angle"] = number(g["light_angle"], source, "gradient.light_angle", minimum=-60.0, maximum=60.0)
    if "bias" in g:
        kw["bias"] = number(g["bias"], source, "gradient.bias", minimum=0.0)
    for key in ("map_resolution", "image_resolution"):
        if key in g:
            kw[key] = number(g[key], source, f"gradient.{key}", integer=True, minimum=8, maximum=MAX_RESOLUTION)
    if "fd_halvings" in g:
        kw["fd_halvings"] = number(g["fd_halvings"], source, "gradient.fd_halvings", integer=True, minimum=0,
                                   maximum=20)
    if "image_jitter" in g:
        if not isinstance(g["image_jitter"], bool):
            raise ConfigError(source, "gradient.image_jitter", f"expected true or false, got {g['image_jitter']!r}")
        kw["image_jitter"] = g["image_jitter"]
    kw.update(_compare_keys(g, source))
    light = kw["light"]
    for key in ("light_samples", "equal_error_spp", "equal_error_seeds"):
        if key in g and light != "area":
            raise ConfigError(source, f"gradient.{key}", f"is read only with light = \"area\", not {light!r}")
    kw["params"] = _params(g, source, light)
    kw["loss"] = choice(g.get("loss", "shadow_area"), source, "gradient.loss", LOSSES)
    kw["target"] = _target(g, source, light, kw["loss"])
    kw["fd_step"] = _steps(g, source, kw["params"])
    kw["reference_step"] = _steps(g, source, kw["params"], "reference_step")
    kw["techniques"] = _techniques(g, source)
    spec = GradSpec(**kw)
    if spec.light == "area" and not spec.light_size < 2.0 * spec.window:
        raise ConfigError(source, "gradient.light_size", f"the area light's side must be smaller than the image's "
                          f"(2 x window = {2.0 * spec.window:g}): a larger square hides the whole image from the "
                          f"projective integrators' camera above it; got {spec.light_size:g} (valid: 0 < light_size "
                          f"< {2.0 * spec.window:g})")
    if spec.light != "directional" and not spec.occluder_height + spec.thickness() < spec.light_height:
        raise ConfigError(source, "gradient.light_height", f"must be above the occluder's top "
                          f"({spec.occluder_height + spec.thickness():g}), got {spec.light_height:g}")
    check_extent(spec, source)
    for key in ("fd_step", "reference_step"):
        check_steps(spec, source, key)
    if "inverse_starts" in g:       # the defaults are offsets of a unit-sized scene: a scaled one gives its own
        check_starts(spec, source)
    return spec


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
    if not spec.bias < spec.occluder_height:
        raise ConfigError(source, "gradient.bias", f"must be below the occluder's height above the ground "
                          f"({spec.occluder_height:g}): a larger depth bias lights every receiver; got {spec.bias:g} "
                          f"(valid: 0 <= bias < {spec.occluder_height:g})")
    if spec.light != "directional":      # the map stores float32 depths from the light
        steps = spec.occluder_height / (spec.light_height * FLOAT32_STEP)
        if not steps >= MIN_DEPTH_STEPS:
            raise ConfigError(source, "gradient.light_height", f"the occluder's height above the ground "
                              f"({spec.occluder_height:g}) is {steps:.3g} float32 depth steps at the light's distance "
                              f"{spec.light_height:g}, under {MIN_DEPTH_STEPS}: the map cannot tell the occluder from "
                              f"the ground (valid: light_height <= "
                              f"{spec.occluder_height / (MIN_DEPTH_STEPS * FLOAT32_STEP):g})")
    reach = shadow_half_extent(spec)
    if not reach < spec.window:
        raise ConfigError(source, "gradient.window", f"the occluder's shadow reaches {reach:g} from the centre, "
                          f"beyond the image's half-width {spec.window:g}: its edge, where the gradient is, would be "
                          f"outside the image (valid: window > {reach:g}, or a smaller occluder_size)")
    pixels = reach / spec.window * spec.image_resolution
    if not pixels >= MIN_SHADOW_PIXELS:
        raise ConfigError(source, "gradient.window", f"the occluder's shadow spans {pixels:.3g} pixels of the "
                          f"{spec.image_resolution}^2 image, under {MIN_SHADOW_PIXELS} (valid: window <= "
                          f"{reach * spec.image_resolution / MIN_SHADOW_PIXELS:g}, or a larger occluder_size)")


def _mesh(g: dict, source: str, scene: str) -> str:
    """The mesh file of scene = "mesh" (relative to the config's folder), checked before any work."""
    if scene != "mesh":
        if "mesh" in g:
            raise ConfigError(source, "gradient.mesh", f"is read only with scene = \"mesh\", not {scene!r}")
        return ""
    raw = g.get("mesh")
    if not isinstance(raw, str) or not raw:
        raise ConfigError(source, "gradient.mesh", f"scene = \"mesh\" needs a PLY or OBJ file, got {raw!r}")
    path = Path(raw) if Path(raw).is_absolute() else Path(source).parent / raw
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise ConfigError(source, "gradient.mesh", f"unknown file type {path.suffix!r}", MESH_SUFFIXES,
                          got=path.suffix)
    if not path.is_file():
        raise ConfigError(source, "gradient.mesh", f"no such file {str(path)!r}")
    return str(path.resolve())


def _param_names(raw, source: str, key: str, light: str) -> list:
    names = as_list(raw)
    if not names:
        raise ConfigError(source, key, "empty list", sorted(PARAMS))
    for n in names:
        choice(n, source, key, sorted(PARAMS))
        lights = PARAMS[n][1]
        if lights is not None and light not in lights:
            raise ConfigError(source, key, f"{n} is a parameter of a {' or '.join(lights)} light and gradient.light "
                              f"is {light}", [p for p, (_, lt) in PARAMS.items() if lt is None or light in lt])
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


def _techniques(g: dict, source: str) -> tuple:
    names = as_list(g.get("techniques", list(TECHNIQUES)))
    if not names:
        raise ConfigError(source, "gradient.techniques", "empty list", TECHNIQUES)
    for n in names:
        choice(n, source, "gradient.techniques", TECHNIQUES)
    if len(set(names)) != len(names):
        raise ConfigError(source, "gradient.techniques", "a technique is given twice: give each once")
    blurs = as_list(g.get("blur", [1, 3, 5]))
    if not blurs:
        raise ConfigError(source, "gradient.blur", "empty list")
    for b in blurs:
        w = number(b, source, "gradient.blur", integer=True, minimum=1, maximum=MAX_BLUR)
        if w % 2 == 0:
            raise ConfigError(source, "gradient.blur", f"a blur width is odd (centred on the texel), got {w}")
    if len(set(blurs)) != len(blurs):
        raise ConfigError(source, "gradient.blur", "a width is given twice: give each once")
    aas = as_list(g.get("antialias", [False, True]))
    if not aas or any(not isinstance(a, bool) for a in aas) or len(set(aas)) != len(aas):
        raise ConfigError(source, "gradient.antialias", f"expected false, true or [false, true], got {aas!r}")
    out = []
    for n in names:
        for w in (blurs if n in MOMENT_TECHNIQUES else [1]):
            out += [Technique(n, int(w), a) for a in aas]
    return tuple(out)
