"""Plain types every module of the kit may import; this module imports nothing of dsm but dsm.core.suggest.

The lists of choices (each defined once), lengths and their units, :class:`ConfigError`,
the value checks that produce it, and the frozen specs a config is read into.
"""
from __future__ import annotations

import dataclasses
import itertools
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .suggest import valid_words

LENGTH_UNITS = ("world", "texel", "range")
FILTERS = ("nearest", "pcf_bilinear", "pcf_jitter4x4", "pcf_wide", "pcss", "smrt")
FORMATS = ("float32", "unorm16", "unorm24", "ndc24", "float16")
# [map] kind: the depth-compare map, or a pre-filtered moment map (dsm.prefilter)
MAP_KINDS = ("depth", "vsm", "esm", "evsm", "msm")
BLUR_KERNELS = ("box", "gaussian")         # [map] blur_kernel: a pre-filtered map's separable blur
BLUR_LABELS = {"box": "box", "gaussian": "gauss"}      # the filter column's word for each
POINT_VIEWS = ("paraboloid", "dual_paraboloid", "cube")
MAP_VIEWS = POINT_VIEWS + ("vsv",)      # [map] view: and a voxelized shadow volume (dsm.maps.vsv; spot lights too)
AREA_SHAPES = ("rectangle", "disk", "sphere", "emitter")
# vectorized Dr.Jit variants only: the kit's code runs on wide arrays (scalar_rgb cannot run it)
VARIANTS = ("llvm_ad_rgb", "cuda_ad_rgb")
# [report] images: error and shadow images per case, error images only, or none
REPORT_IMAGES = ("all", "errors", "none")
LOOKUP_MODES = ("wavefront", "per_case")   # [timing] lookups (dsm.experiment.wavefront)
BUILD_MODES = ("alone", "together")        # [timing] builds: each map timed alone, or a sweep's small maps stacked


class ConfigError(ValueError):
    """A config mistake, reported before any work starts."""

    def __init__(self, source: str, key: str, problem: str, choices=None, *, got=None):
        """``got``: the misspelt name, where there is one: the message adds the nearest of ``choices``."""
        self.source, self.key, self.problem = source, key, problem
        self.choices, self.got = (tuple(choices) if choices else ()), got
        msg = f"{source}: {key}: {problem}"
        if self.choices:
            msg += f" ({valid_words(got, self.choices)})"
        super().__init__(msg)
        self.more = []          # further problems of the same kind (scenes.check gathers every scene's)


class NothingToRun(ConfigError):
    """A valid config whose every scene is an absent optional file: the run would compute nothing."""


# ---------------------------------------------------------------- lengths

@dataclass(frozen=True)
class Length:
    """A length parameter: a world-space number, ``"k texel"`` or ``"k range"``.

    ``texel`` is the world width of one texel of the map at the receiver (constant for an
    orthographic view, growing with distance for a perspective one); ``range`` is a fraction
    of the view's depth range (far - near), the unit of hardware depth-bias constants.
    """
    value: float
    unit: str = "world"

    @staticmethod
    def parse(raw: Any, source: str = "<config>", key: str = "length") -> "Length":
        """``raw`` (a number, a ``"k unit"`` string or a Length) as a Length; else a ConfigError at ``key``."""
        if isinstance(raw, Length):
            return raw
        if isinstance(raw, bool):
            raise ConfigError(source, key, f"expected a number or a string like \"2 texel\", got {raw!r}")
        if isinstance(raw, (int, float)):
            value, unit = float(raw), "world"
        elif isinstance(raw, str):
            parts = raw.split()
            if len(parts) != 2:
                raise ConfigError(source, key, f"cannot read length {raw!r}; write a number or \"<k> <unit>\"",
                                  LENGTH_UNITS)
            value = length_number(parts[0])
            if value is None:
                raise ConfigError(source, key, f"{parts[0]!r} in {raw!r} is not a number (nor 2^k)") from None
            unit = parts[1].rstrip("s") if parts[1] not in LENGTH_UNITS else parts[1]
            if unit not in LENGTH_UNITS:
                raise ConfigError(source, key, f"unknown unit {parts[1]!r} in {raw!r}", LENGTH_UNITS,
                                  got=parts[1])
        else:
            raise ConfigError(source, key, f"expected a number or a string like \"2 texel\", got {type(raw).__name__}")
        if not math.isfinite(value):
            raise ConfigError(source, key, f"length {raw!r} is not finite")
        return Length(value, unit)

    def __str__(self) -> str:
        v = f"{self.value:g}"
        return v if self.unit == "world" else f"{v} {self.unit}"


POWER_OF_TWO = re.compile(r"2\^(-?\d+)")


def length_number(text: str) -> float | None:
    """A length's number as written: a decimal, or ``2^k`` (how reports name a depth step, such as
    ``2^-24 range``, so a label pastes back exactly); None for anything else."""
    power = POWER_OF_TWO.fullmatch(text)
    if power:
        return 2.0 ** int(power[1])
    try:
        return float(text)
    except ValueError:
        return None


# ---------------------------------------------------------------- value checks

LAMBDA_MAX = 1e6      # the objective's weight on peter-panning: beyond this acne counts for nothing, and the
                      # tuner's relaxed loss (float32) overflows near 1e25
SEED_MAX = 2 ** 63 - 1    # seeds are non-negative (numpy's generators refuse negatives) and fit a 64-bit state


def number(raw, source, key, *, integer=False, positive=False, minimum=None, maximum=None):
    """``raw`` as a finite number (an ``int`` if ``integer``) within the bounds; else a ConfigError at ``key``."""
    if isinstance(raw, bool) or not isinstance(raw, (int, float)) or (integer and not isinstance(raw, int)):
        raise ConfigError(source, key, f"expected {'an integer' if integer else 'a number'}, got {raw!r}")
    if not math.isfinite(raw):
        raise ConfigError(source, key, f"{raw!r} is not finite")
    if positive and raw <= 0:
        raise ConfigError(source, key, f"must be > 0, got {raw!r}")
    if minimum is not None and raw < minimum:
        raise ConfigError(source, key, f"must be >= {minimum}, got {raw!r}")
    if maximum is not None and raw > maximum:
        raise ConfigError(source, key, f"must be <= {maximum}, got {raw!r}")
    return int(raw) if integer else float(raw)


def choice(raw, source, key, choices):
    """``raw`` checked to be one of ``choices``; else a ConfigError at ``key`` listing them."""
    if not isinstance(raw, str) or raw not in choices:
        raise ConfigError(source, key, f"unknown value {raw!r}", choices, got=raw)
    return raw


def vec3(raw, source, key, nonzero=False):
    """``raw`` as a tuple of three floats (not all zero if ``nonzero``); else a ConfigError at ``key``."""
    if not isinstance(raw, list) or len(raw) != 3:
        raise ConfigError(source, key, f"expected a list of three numbers, got {raw!r}")
    v = tuple(number(x, source, key) for x in raw)
    if nonzero and not any(v):
        raise ConfigError(source, key, "direction must not be zero")
    return v


def as_list(raw):
    """``raw`` as a list: itself if it is one, else a one-item list."""
    return raw if isinstance(raw, list) else [raw]


def check_keys(table: dict, allowed, source: str, where: str):
    """Raise a ConfigError for the first key of ``table`` not in ``allowed`` (reported as ``where.key``)."""
    for k in table:
        if k not in allowed:
            raise ConfigError(source, f"{where}.{k}" if where else k, "unknown key", sorted(allowed), got=k)


def coerce_field(f: dataclasses.Field, raw, source: str, key: str):
    """Convert one raw TOML value to a parameter dataclass field's type (Length, float, int, str, or
    a ``tuple`` of three numbers). ``metadata["min"]`` bounds numbers and Lengths (their value, in
    any unit: an upper limit or an offset below 0 has no meaning); ``metadata["max"]`` integers."""
    if f.type in ("Length", Length):
        value = Length.parse(raw, source, key)
        lo = f.metadata.get("min")
        if lo is not None and value.value < lo:
            raise ConfigError(source, key, f"must be >= {lo:g}, got {raw!r}")
        return value
    if f.type in ("tuple", tuple):
        return vec3(raw, source, key)
    if f.type in ("float", float):
        return number(raw, source, key, minimum=f.metadata.get("min"))
    if f.type in ("int", int):
        return number(raw, source, key, integer=True, minimum=f.metadata.get("min"), maximum=f.metadata.get("max"))
    if f.type in ("str", str):
        if "path" in f.metadata:      # a file's name: its reader resolves and checks it (dsm.scenes.spec)
            if not isinstance(raw, str):
                raise ConfigError(source, key, f"expected a path string, got {raw!r}")
            return raw
        return choice(raw, source, key, f.metadata["choices"])
    if f.type in ("bool", bool):
        if not isinstance(raw, bool):
            raise ConfigError(source, key, f"expected true or false, got {raw!r}")
        return raw
    raise TypeError(f"unsupported parameter type {f.type!r}")


def sweep_params(cls, table: dict, source: str, where: str, skip=()) -> list:
    """Expand a table of (possibly list-valued) parameters into instances of ``cls``."""
    fields = {f.name: f for f in dataclasses.fields(cls)}
    check_keys({k: v for k, v in table.items() if k not in skip}, fields, source, where)
    names, options = [], []
    for k, raw in table.items():
        if k in skip:
            continue
        if fields[k].type in ("tuple", tuple):
            # a vector: [x, y, z] is one value, a list of vectors sweeps
            values = raw if isinstance(raw, list) and raw and all(isinstance(x, list) for x in raw) else [raw]
        else:
            values = as_list(raw)
        if not values:
            raise ConfigError(source, f"{where}.{k}", "empty list")
        names.append(k)
        options.append([coerce_field(fields[k], v, source, f"{where}.{k}") for v in values])
        for i, v in enumerate(options[-1]):         # a value twice would run (and pool) the same cases twice
            if v in options[-1][:i]:
                first = values[options[-1][:i].index(v)]
                raise ConfigError(source, f"{where}.{k}", f"{values[i]!r} is given twice (the same value as "
                                  f"{first!r}): give each value once")
    return [cls(**dict(zip(names, combo))) for combo in itertools.product(*options)]


# ---------------------------------------------------------------- config tables

@dataclass(frozen=True)
class SceneSpec:
    """One scene: a built-in with its parameters, or a file (Mitsuba XML, OBJ, PLY)."""
    builtin: str | None = None
    file: Path | None = None
    params: Any = None          # builtin: its parameter dataclass; file: FileSceneParams
    label: str = ""
    closed: tuple = ()          # (shape name, closed) overrides of detected closedness
    missing: str = ""           # an optional file that is absent: the run records it as skipped
    model: str = ""             # a named model the kit does not ship (dsm.scenes.models: "sponza")
    units: float = 1.0          # the model's file units in its frame (Crytek's Sponza: cm, 0.01)
    source: str = field(default="", compare=False)     # the config file, for errors found on loading
    where: str = field(default="scene", compare=False)  # its [[scene]] key, e.g. "scene[2]"


@dataclass(frozen=True)
class LightSpec:
    """A light. ``scene``: the scene's own lights (built-in default or XML emitters)."""
    type: str
    direction: tuple | None = None
    position: tuple | None = None
    target: tuple | None = None
    cutoff: float = 30.0        # spot half angle in degrees
    label: str = ""
    # area lights (dsm.truth.area): shape, size (side or [w, h]; diameter), the reference's sampling
    shape: str = ""
    size: tuple = ()
    min_samples: int = 16
    max_samples: int = 4096
    tolerance: float = 0.01
    confidence: float = 0.99    # the reference interval's confidence
    replicates: int = 16        # independent jittered sets per receiver (the interval's degrees of freedom + 1)
    emitter_shapes: tuple = ()  # an emitter light's shape indices (its map excludes them)
    scenes: tuple = ()          # area lights: only these scenes (labels or their first word); () all

    def applies_to(self, scene_label: str) -> bool:
        """Whether this light lights the scene labelled ``scene_label`` (``scenes`` empty: every scene)."""
        first = scene_label.replace("(", " ").split()[0] if scene_label.strip() else scene_label
        return not self.scenes or scene_label in self.scenes or first in self.scenes


CASCADE_SPLITS = ("uniform", "log", "practical")
CASCADE_FITS = ("receivers", "scene", "frustum", "cascade")
DEPTH_BOUNDS = ("clipped", "scene")         # near/far: the light frustum clipped to the scene's bounds, or the bounds
MAX_CASCADES = 8


@dataclass(frozen=True)
class CameraSpec:
    """``[camera]`` pose (None: the scene's own). Positions follow a built-in's scale and translate."""
    position: tuple | None = None
    target: tuple | None = None
    up: tuple | None = None
    fov: float | None = None        # horizontal, degrees
    near: float | None = None
    far: float | None = None

    @property
    def posed(self) -> bool:
        """Whether any pose field is set (else the scene's own camera stands)."""
        return any(getattr(self, f.name) is not None for f in dataclasses.fields(self))


@dataclass(frozen=True)
class CascadeSpec:
    """A directional light's cascade layout (``[map] cascades`` and its keys; dsm.maps.cascades)."""
    count: int = 1
    split: str = "practical"
    lam: float = 0.5                # practical split: lam * log + (1 - lam) * uniform
    fit: str = "cascade"
    depth_bounds: str = "clipped"
    stabilize: bool = False
    blend: float = 0.0              # fraction of each split blended with the next cascade
    max_distance: float | None = None   # None: the farthest receiver's view depth
    near: float | None = None       # None: the camera's near clip
    bounds: tuple = ()              # explicit far bounds per cascade (engine layouts), world units
    fractions: tuple = ()           # explicit far bounds as fractions of max_distance (engine layouts)
    blend_rule: str = "split"       # "split": f of the split's length; "distance": f of its far bound (Bevy)
    engine: str = ""

    @property
    def label(self) -> str:
        """The layout's name in reports: the engine's, or count, split and fit plus any non-default keys."""
        if self.engine:
            return self.engine
        split = f"practical({self.lam:g})" if self.split == "practical" else self.split
        out = f"{self.count}x {split} fit={self.fit}"
        if self.depth_bounds != "clipped":
            out += f" depth={self.depth_bounds}"
        if self.stabilize:
            out += " stable"
        if self.blend:
            out += f" blend={self.blend:g}"
        if self.max_distance is not None:
            out += f" max={self.max_distance:g}"
        return out


# how a receiver's level is chosen: footprint and distance a directional light's clipmap (dsm.maps.virtual),
# punctual a spot light's perspective page table (dsm.maps.virtual_punctual)
VIRTUAL_RULES = ("footprint", "distance", "punctual")


@dataclass(frozen=True)
class VirtualSpec:
    """A virtual shadow map (``[map.virtual]``): a directional light's clipmap levels around the camera
    (dsm.maps.virtual), or with ``rule = "punctual"`` a spot light's perspective page table whose levels
    halve its resolution (dsm.maps.virtual_punctual); pages tagged by the receivers, each read in its level."""
    preset: str = ""                # "ue5" | "eevee" | "" (every key given)
    page_size: int = 128            # texels per page side
    resolution: int = 16384         # virtual texels per level side
    first_level: int = 6            # finest clipmap level (absolute)
    last_level: int = 22            # coarsest clipmap level (absolute)
    lod_bias: float = -0.5          # level-of-detail bias (-1 doubles the resolution)
    rule: str = "footprint"         # footprint (UE5: floor, pixel footprint) | distance (EEVEE: ceil, distance)
    unit_cm: float = 100.0          # centimetres in one scene unit (a scene at scale 1)
    border: float = 0.05            # a receiver this fraction of a page from its page's edge also tags the neighbour
    max_pages: int = 2048           # the physical page pool
    lod_min: float = 0.0            # punctual: the footprint floor (> 0: metres, world; < 0: -it on the light plane)

    virtual = True                  # read by the plan and the views (a CascadeSpec has no such field)

    @property
    def punctual(self) -> bool:
        """Whether this is a spot light's map (EEVEE's punctual rule), not a directional light's clipmap."""
        return self.rule == "punctual"

    @property
    def count(self) -> int:
        """Clipmap levels (the view's faces)."""
        return self.last_level - self.first_level + 1

    def level_width(self, level, scale: float = 1.0):
        """World width (scene units at ``scale``) of absolute level ``level`` (a number or a numpy array):
        UE5 ``2^(l+3)`` cm (a radius of ``2^(l+1)`` cm, the level four radii wide), EEVEE ``2^l`` m."""
        cm = 2.0 ** (level + 3.0) if self.rule == "footprint" else 100.0 * 2.0 ** level
        return cm * scale / self.unit_cm

    @property
    def physical_texels(self) -> int:
        """Texels of the physical page pool: max_pages x page_size^2 (the plan's memory bound)."""
        return self.max_pages * self.page_size ** 2

    @property
    def label(self) -> str:
        """The layout's name in reports: ``vsm <preset>`` plus the keys that differ from the preset."""
        from dataclasses import fields
        base = VIRTUAL_PRESETS.get(self.preset, VirtualSpec())
        diff = [f"{f.name}={getattr(self, f.name):g}" if isinstance(getattr(self, f.name), float)
                else f"{f.name}={getattr(self, f.name)}" for f in fields(self)
                if f.name != "preset" and getattr(self, f.name) != getattr(base, f.name)]
        return " ".join(["vsm", self.preset or "custom"] + diff)


# the engines' defaults, each value read in the source named (docs/virtual_shadow_maps.md lists them)
VIRTUAL_PRESETS = {
    # Unreal Engine 5: VirtualShadowMapClipmap.cpp (r.Shadow.Virtual.Clipmap.FirstLevel 6, LastLevel 22,
    # r.Shadow.Virtual.ResolutionLodBiasDirectional -0.5; level radius 2^(level+1) cm, the level twice
    # that wide each side; the level rounds down), VirtualShadowMapArray.cpp (MaxPhysicalPages 2048,
    # PageDilationBorderSizeDirectional 0.05); the VSM documentation (16k x 16k virtual, 128 x 128 pages)
    "ue5": VirtualSpec("ue5", 128, 16384, 6, 22, -0.5, "footprint", 100.0, 0.05, 2048),
    # Blender EEVEE (4.2+): eevee_defines.hh (SHADOW_PAGE_RES 256, SHADOW_TILEMAP_RES 32 pages a side),
    # eevee_shadow.hh (coverage_get: a level is 2^level units wide), eevee_shadow_tilemap_lib.glsl (level =
    # ceil(log2(2 d narrowing) + lod_bias); pages tagged at the pixel, radius 0), eevee_shadow.cc
    # (lod_bias = -log2(shadow_resolution_scale): 0 at scale 1; pages = pool bytes / (256^2 x 4));
    # one Blender unit is a metre. Assumed: the 512 MB pool (2048 pages) and the level range (EEVEE
    # derives it from the camera's near plane and bounds each frame)
    "eevee": VirtualSpec("eevee", 256, 8192, -8, 24, 0.0, "distance", 100.0, 0.0, 2048),
    # Blender EEVEE's spot and point lights (dsm.maps.virtual_punctual): eevee_defines.hh (SHADOW_PAGE_RES 256,
    # SHADOW_TILEMAP_RES 32, so SHADOW_MAP_MAX_RES 8192 texels at level 0; SHADOW_TILEMAP_LOD 5, levels 0 to 5);
    # the level rule shadow_punctual_pixel_ratio (eevee_shadow_tilemap_lib.glsl); lod_min the light's
    # resolution limit (Light::shadow_lod_min_get, eevee_light.cc): its default was not read, 0 leaves it out
    "eevee_punctual": VirtualSpec("eevee_punctual", 256, 8192, 0, 5, 0.0, "punctual", 100.0, 0.0, 2048, 0.0),
}


CAMERA_PATHS = ("none", "dolly", "pan", "orbit", "keyframes")
LIGHT_PATHS = ("none", "turn", "move", "keyframes")
CACHE_POLICIES = ("none", "static", "stagger:N", "invalidate")   # [[motion]] cache: dsm.experiment.cache's registry holds one module each


@dataclass(frozen=True)
class MotionSpec:
    """One ``[[motion]]`` path over ``frames`` frames (dsm.experiment.motion)."""
    frames: int = 8
    camera: str = "none"            # none | dolly (translate by offset) | pan | orbit (by angle) | keyframes
    offset: tuple = (0.0, 0.0, 0.0)  # dolly: the camera's whole translation over the path (scene units)
    angle: float = 0.0              # pan / orbit: degrees over the path, about the camera's up
    keys: tuple = ()                # keyframes: ((position, target), ...), spread evenly over the frames
    light: str = "none"             # none | turn (a directional light's direction about light_axis) | move | keyframes
    light_axis: tuple = (0.0, 0.0, 1.0)
    light_angle: float = 0.0        # degrees over the path
    light_offset: tuple = (0.0, 0.0, 0.0)  # move: a spot or point light's whole translation (scene units)
    light_keys: tuple = ()          # keyframes: ((position, target or None), ...) of a spot or point light
    points: int = 4000              # fixed points sampled on the surfaces (the experiment's seed)
    label: str = ""
    casters: tuple = ()             # CasterPath per moving shape ([[motion.casters]])
    cache: str = "none"             # the maps' cache policy (CACHE_POLICIES; dsm.experiment.cache)


@dataclass(frozen=True)
class CasterPath:
    """One moving shape of a ``[[motion]]`` path: its translation per frame (world units before the scene's scale)."""
    shape: str                      # the shape's name (SceneData.shape_names)
    offset: tuple = (0.0, 0.0, 0.0)  # linear: the whole translation over the frames
    keys: tuple = ()                # keyframes: translations spread evenly over the frames (at least two)
    angle: float = 0.0              # the whole turn over the frames (degrees), about ``axis`` through the shape's centre
    axis: tuple = (0.0, 0.0, 1.0)   # the turn's axis (world)
    flagged_static: bool = False    # ``static = true``: flagged static, so ``invalidate`` never re-casts for it


@dataclass(frozen=True)
class MapSpec:
    """``[map]``: the resolutions, filters, stored formats, point-light views, texel budgets and cascades swept."""
    resolution: tuple = (512,)
    filter: tuple = ("nearest",)
    format: tuple = ("float32",)
    view: tuple = ("dual_paraboloid",)
    texels: tuple = ()          # equal-memory sweeps: total texels per view, R = round(sqrt(texels / faces))
    cascade: tuple = ()         # CascadeSpec layouts of directional lights (empty: one map fitted to the receivers)
    kind: tuple = ("depth",)    # map kinds (MAP_KINDS): depth runs the [[scheme]]s, the others their moments
    moments: tuple = ()         # MomentSpec instances of the pre-filtered kinds (dsm.prefilter)
    leak_split: bool = False    # kind given: every case splits its peter-panning into contact and leak
    leak_texels: float = 2.0    # the split: peter-panning this many texels inside the exact shadow is a leak
    virtual: tuple = ()         # VirtualSpec layouts of directional lights ([map.virtual]; dsm.maps.virtual)

    def resolutions_for(self, faces: int) -> tuple:
        """Per-face resolutions of a view with ``faces`` faces (from ``texels`` when given)."""
        if not self.texels:
            return self.resolution
        return tuple(max(1, round((t / faces) ** 0.5)) for t in self.texels)


class ParamsLabel:
    """A spec of frozen ``params`` whose report label is those parameters."""

    @property
    def label(self) -> str:
        """The parameters as ``name=value`` words (describe_params)."""
        return describe_params(self.params)


@dataclass(frozen=True)
class SchemeSpec(ParamsLabel):
    """One scheme instance (a ``[[scheme]]`` value set): its name, frozen parameters and preset, if any."""
    name: str
    params: Any                 # the scheme's frozen parameter dataclass
    preset: str | None = None


@dataclass(frozen=True)
class MomentSpec(ParamsLabel):
    """One pre-filtered map instance: its kind (``name``), frozen parameters, blur width (texels)
    and blur kernel (``box`` or ``gaussian``)."""
    name: str
    params: Any
    blur: int = 1
    preset: str | None = None
    kernel: str = "box"
    samples: int = 1      # rays per texel side the moments are averaged over (samples^2 a texel)
    mipmaps: bool = False  # a chain of 2 x 2 means read at the receiver's footprint (dsm.prefilter.mipmaps)

    @property
    def filter(self) -> str:
        """The case's filter column: the blur, ``box:W`` or ``gauss:W``, then ``/ssN`` where the
        moments are supersampled N x N a texel (nothing at 1: the labels of one ray a texel)."""
        return (f"{BLUR_LABELS[self.kernel]}:{self.blur}" + (f"/ss{self.samples}" if self.samples > 1 else "")
                + ("/mip" if self.mipmaps else ""))


HYBRID_ORIGINS = ("spawn", "mitsuba", "wachter_binder", "epsilon")   # where a hybrid's ray starts (dsm.hybrid.origins)


@dataclass(frozen=True)
class HybridSpec(ParamsLabel):
    """One hybrid instance (a ``[hybrid]`` value set, dsm.hybrid): the rule that picks the receivers a
    ray decides (``rule``), its frozen parameters, and the origin rule of those rays."""
    rule: str
    params: Any
    origin: str = "spawn"


@dataclass(frozen=True)
class OracleSpec:
    """``[oracle]``: the weights of peter-panning in the oracles' objective
    E(lambda) = (n_acne + lambda n_peterpan) / n_receivers; one oracle row per lambda."""
    lambdas: tuple = (1.0,)


@dataclass(frozen=True)
class ContactSpec:
    """``[contact]``: screen-space contact shadows after every case's lookup (dsm.contact). A march
    of ``steps`` samples from each receiver toward the light over ``length`` through the camera's
    depth buffer; a sample is occluded where it lies behind the buffer by less than ``thickness``;
    ``jitter`` (0 to 1) moves every sample back by up to that fraction of a step, per receiver;
    ``length_depth_scale`` / ``length_depth_min`` / ``thickness_per_length``: a length scaled by the
    receiver's view depth and a thickness relative to it (Unity HDRP's; off by default)."""
    length: Length = field(default=Length(8.0, "texel"), metadata={"doc": "march length toward the light",
                                                                   "min": 0.0})
    steps: int = field(default=16, metadata={"doc": "samples along the march", "min": 1})
    thickness: Length = field(default=Length(2.0, "texel"), metadata={"doc": "depth a buffer surface is taken "
                                                                      "to occupy behind itself", "min": 0.0})
    jitter: float = field(default=0.0, metadata={"doc": "per-receiver offset of the samples, in steps",
                                                 "min": 0.0})
    # opt-in, off by default (the march is then unchanged): HDRP's depth-scaled ray (dsm.contact.march)
    length_depth_scale: float = field(default=0.0, metadata={
        "doc": "0: off; else the length is scaled by max(length_depth_min, this x the receiver's view depth), "
               "per world unit of depth", "min": 0.0})
    length_depth_min: float = field(default=1.0, metadata={"doc": "the least factor of the depth-scaled length",
                                                           "min": 0.0})
    thickness_per_length: float = field(default=0.0, metadata={
        "doc": "0: off; else the thickness is this fraction of the receiver's (scaled) length, replacing "
               "thickness", "min": 0.0})


BACKENDS = ("local", "ray")


@dataclass(frozen=True)
class ExecutionSpec:
    """``[execution]``: where the cases run (dsm.experiment.cluster). ``backend`` local or ray; ``address``
    a Ray cluster's address (``auto``, ``ray://host:port``) or ``local`` (start one here);
    ``cpus_per_task`` / ``gpus_per_task``: what each map group's Ray task asks for (fractions allowed)."""
    backend: str = "local"
    address: str | None = None
    cpus_per_task: float = 1.0
    gpus_per_task: float = 0.0


@dataclass(frozen=True)
class Config:
    """An experiment config, checked and frozen: scenes, lights, the map sweep, schemes and how to run them."""
    name: str
    source: str
    seed: int = 7
    variant: str | None = None
    camera_resolution: tuple | None = None   # None: an XML scene's own film, else DEFAULT_CAMERA
    camera: "CameraSpec | None" = None       # [camera] pose; None: the scene's own
    scenes: tuple = ()
    lights: tuple = ()
    map: MapSpec = field(default_factory=MapSpec)
    schemes: tuple = ()
    timing_repeats: int = 3
    timing_lookups: str = "wavefront"       # [timing] lookups: a map's cases in one wavefront, or "per_case"
    timing_builds: str = "alone"            # [timing] builds: "together" stacks a sweep's small maps (dsm.maps.stacked)
    memory_budget_mb: float | None = None   # None: a quarter of this machine's memory
    oracle: "OracleSpec" = field(default_factory=lambda: OracleSpec())
    report_images: str = "all"              # [report] images (REPORT_IMAGES)
    motion: tuple = ()                       # MotionSpec paths ([[motion]]); empty: still frames
    contact: "ContactSpec | None" = None     # [contact]: contact shadows after each case (None: not planned)
    hybrid: tuple = ()                       # [hybrid]: HybridSpec instances, each a case of every depth case (dsm.hybrid)
    shrink: float | None = None              # [map] shrink: casters moved inward along welded normals, world units (None: off)
    tune: "TuneSpec | None" = field(default=None, compare=False, repr=False)   # [tune] (dsm.config.tune), read by dsm tune
    raw: dict = field(default_factory=dict, compare=False)
    execution: ExecutionSpec = field(default_factory=ExecutionSpec, compare=False)   # where, not what


# the culling choices of a map build (midpoint, dual); second_depth's front_closed is its own
CULLINGS = ("none", "back", "front", "back_closed")
# faces (maps) per view kind ("fitted": an area light's perspective or paraboloid view, chosen from its receivers)
VIEW_FACES = {"fitted": 1, "orthographic": 1, "perspective": 1, "paraboloid": 1, "dual_paraboloid": 2, "cube": 6,
              "vsv": 1}
DEFAULT_CAMERA = (256, 256)     # built-ins and meshes without [camera] resolution


def describe_params(params) -> str:
    """A scheme instance's parameters as ``name=value`` words (the report's ``params`` column); a
    field marked ``metadata["label"] = "if_set"`` (one added after runs were labelled without
    it) only where it differs from its default, so earlier labels stay as they were."""
    return " ".join(f"{f.name}={getattr(params, f.name)}" for f in dataclasses.fields(params)
                    if f.metadata.get("label") != "if_set" or getattr(params, f.name) != f.default)
