"""Every key of an experiment config, declared once: its table, type, unit, default, valid values,
source and meaning. The documentation's config reference is generated from this (docs/conf.py)
and tests/test_docs.py checks it against the keys the reader accepts, so the two cannot drift.

Tables whose keys are a dataclass's fields (a scheme's parameters, a built-in scene's, ``[contact]``,
``[map.<kind>]``) are described by those fields' metadata; :func:`dataclass_keys` reads them.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ..core.types import (AREA_SHAPES, Length, BACKENDS, BLUR_KERNELS, BUILD_MODES, CACHE_POLICIES, CAMERA_PATHS, CASCADE_FITS,
                          CASCADE_SPLITS, DEPTH_BOUNDS, FILTERS, FORMATS, LAMBDA_MAX, LIGHT_PATHS, LOOKUP_MODES,
                          MAP_KINDS, MAP_VIEWS, MAX_CASCADES, REPORT_IMAGES, SEED_MAX, VARIANTS, VIRTUAL_PRESETS,
                          VIRTUAL_RULES, HYBRID_ORIGINS)
from ..contact.presets import PRESETS as CONTACT_PRESETS
from ..scenes.params import BUILTINS
from .tune import MAP_FITS, MAP_UNITS, ROLES, SCHEDULES, SEARCHES

LENGTH = "length: a number (world units), \"k texel\" or \"k range\""
# dsm grad's choices, spelled here as config/ sits below grad/ (tests/test_grad_inputs.py checks they agree)
GRAD_PARAMS = ("occluder_z", "occluder_x", "corner_z", "light_height", "light_x", "light_angle")
GRAD_LOSSES = ("shadow_area", "shadow_moment_x", "l2")
GRAD_PROJECTIVE = ("direct_projective", "prb_projective")


@dataclass(frozen=True)
class Key:
    """One config key: where it lives, what it takes and what it means."""
    table: str                 # "map", "light", "tune.bias_map", ... (an array of tables without its brackets)
    name: str
    type: str                  # int, float, bool, str, length, [x, y, z], table, list of ...
    default: str               # as written in TOML, or a sentence ("the scene's")
    doc: str
    valid: tuple | str = ()    # the choices, or a range in words
    unit: str = ""
    source: str = ""           # the paper or engine the key comes from
    sweeps: bool = False       # a list of values multiplies the cases


def _r(lo, hi=None) -> str:
    """A range in words, its bounds written exactly: 'lo to hi' or '>= lo'."""
    return f">= {_exact(lo)}" if hi is None else f"{_exact(lo)} to {_exact(hi)}"


def _exact(x) -> str:
    """A bound as a user may paste it back: an integer in full, a float by its shortest repr."""
    return str(int(x)) if float(x).is_integer() else repr(float(x))


KEYS = (
    Key("experiment", "name", "str", "the file's stem", "names the results folder runs/<name>-<time>",
        "a plain file name"),
    Key("experiment", "seed", "int", "7", "seeds every random choice of the run", _r(0, SEED_MAX)),
    Key("experiment", "variant", "str", "llvm_ad_rgb (or --variant)", "the Mitsuba variant", VARIANTS),
    Key("camera", "resolution", "[width, height]", "256 x 256 (an XML scene: its film)",
        "the camera's pixels; one number is square", _r(1, 16384), "pixels"),
    Key("camera", "position", "[x, y, z]", "the scene's", "the camera's position (overrides a scene's pose)",
        unit="world"),
    Key("camera", "target", "[x, y, z]", "the scene's", "the point the camera looks at", unit="world"),
    Key("camera", "up", "[x, y, z]", "the scene's", "the camera's up direction"),
    Key("camera", "fov", "float", "the scene's", "horizontal field of view", "> 0 to 179", "degrees"),
    Key("camera", "near", "float", "the scene's", "near plane (at least 1e-12 of the distance to the target)",
        "> 0", "world"),
    Key("camera", "far", "float", "the scene's", "far plane", "> 0", "world"),
    Key("scene", "builtin", "str", "(builtin or file)", "a built-in scene; its parameters are listed below",
        tuple(BUILTINS)),
    Key("scene", "file", "str", "(builtin or file)", "a mesh (.ply, .obj) or a Mitsuba 3 XML scene, relative to "
        "the config file (an XML scene's sensor, film and emitters are used)"),
    Key("scene", "model", "str", "(none)", "a model the kit does not ship, from your copy: `file`, else the "
        "environment variable DSM_SPONZA (docs/sponza.md)", ("sponza",)),
    Key("scene", "version", "str", "told by the file's size", "which Sponza the copy is (Dabrovic's in metres, "
        "Crytek's remodel in centimetres)", ("dabrovic", "crytek")),
    Key("scene", "optional", "bool", "false", "an absent file is skipped (run.json says so) instead of an error"),
    Key("scene", "closed", "table", "each shape's own verdict", "override the closed-solid verdict per shape: { name = true } "
        "(second-depth and culling schemes rely on it)"),
    Key("light", "type", "str", "scene", "the light: the scene's own, or one given here",
        ("scene", "directional", "spot", "point", "area")),
    Key("light", "direction", "[x, y, z]", "a directional light: the scene's; a point light's main axis [0, 0, -1]",
        "a directional light's travel direction; a point or area light's main axis (the dual paraboloid's front)"),
    Key("light", "position", "[x, y, z]", "(required for spot, point, area)", "where the light is", unit="world"),
    Key("light", "target", "[x, y, z]", "(target or direction)", "the point a spot light aims at", unit="world"),
    Key("light", "cutoff", "float", "30", "a spot light's cone half angle", "> 0 to 85", "degrees"),
    Key("light", "shape", "str", "(required for area)", "an area light's shape (emitter: the scene's own)",
        AREA_SHAPES),
    Key("light", "size", "float or [w, h]", "(required for rectangle, disk, sphere)",
        "an area light's side (rectangle), radius (disk, sphere)", "> 0", "world"),
    Key("light", "scenes", "list of str", "every scene", "the scenes this light lights (a label or its first word)"),
    Key("light", "min_samples", "int", "16", "an area light's fewest shadow rays a receiver (a multiple of "
        "replicates)", "replicates to 2^20", source="adaptive Monte Carlo with a confidence bound"),
    Key("light", "max_samples", "int", "4096", "an area light's most shadow rays a receiver", "min_samples to 2^20"),
    Key("light", "tolerance", "float", "0.01", "the half width of V*'s confidence interval to stop at", _r(0, 1)),
    Key("light", "confidence", "float", "0.99", "the confidence of that interval", "0.5 to 0.999999"),
    Key("light", "replicates", "int", "16", "independent replicates the interval is estimated from", _r(2, 64)),
    Key("map", "resolution", "int", "512", "texels a side, per face", _r(1, 16384), "texels", sweeps=True),
    Key("map", "texels", "int", "(resolution)", "the same total texels per view (R = sqrt(texels / faces)); not "
        "with resolution", _r(1, 6 * 16384 ** 2), "texels", sweeps=True),
    Key("map", "filter", "str", "nearest", "the lookup's filter; pcf_wide:K is a K x K kernel (2 to 64); "
        "smrt:<preset> (ue5_local, ue5_directional, eevee, eevee_viewport, eevee_render) or smrt:RxS[:hold|eevee] is shadow-map ray tracing, R "
        "rays of S samples (docs/smrt.md)", FILTERS,
        source="Reeves et al. 1987 (PCF); Fernando 2005 (PCSS); UE5's and EEVEE's shadow-map ray tracing (SMRT)",
        sweeps=True),
    Key("map", "format", "str", "float32", "the stored depth's (or moments') precision", FORMATS, sweeps=True),
    Key("map", "view", "str", "dual_paraboloid", "a point light's views (vsv: spot lights too)", MAP_VIEWS,
        source="Brabec et al. 2002 (dual paraboloid); Wyman 2011 (vsv)", sweeps=True),
    Key("map", "shrink", "float", "off", "casters moved this far inward along welded vertex normals", ">= 0",
        "world"),
    Key("map", "cascades", "int or str", "off", "cascades of a directional light's map, or an engine's layout",
        f"1 to {MAX_CASCADES}, bevy, godot, filament, mjp, three, unity", source="Microsoft, Common techniques to improve shadow depth maps",
        sweeps=True),
    Key("map", "split", "str", "practical", "how the view depth is split over the cascades", CASCADE_SPLITS,
        sweeps=True),
    Key("map", "lambda", "float", "0.5", "practical split: lambda x log + (1 - lambda) x uniform", _r(0, 1),
        sweeps=True),
    Key("map", "fit", "str", "cascade", "what each cascade's map is fitted to", CASCADE_FITS,
        source="Microsoft, Common techniques to improve shadow depth maps", sweeps=True),
    Key("map", "depth_bounds", "str", "clipped", "near/far: the scene's box clipped to the light frustum, or the "
        "box", DEPTH_BOUNDS, sweeps=True),
    Key("map", "stabilize", "bool", "false", "quantized sphere, whole-texel origin (shimmer-free under motion)",
        source="Microsoft, Common techniques to improve shadow depth maps", sweeps=True),
    Key("map", "blend", "float", "0", "mix with the next cascade over this last fraction of each split", _r(0, 0.5),
        sweeps=True),
    Key("map", "max_distance", "float", "the farthest receiver's view depth", "the cascades' far end", "> 0",
        "world", sweeps=True),
    Key("map", "kind", "str", "depth", "depth runs the [[scheme]]s; the others are pre-filtered maps", MAP_KINDS,
        source="Donnelly & Lauritzen 2006; Annen et al. 2008; Lauritzen & McCool 2008; Peters & Klein 2015",
        sweeps=True),
    Key("map", "blur", "int", "1", "blur width of a pre-filtered map's moments (odd; 1: none)", _r(1, 63),
        "texels", sweeps=True),
    Key("map", "blur_kernel", "str", "box", "the moments' blur (gaussian: sigma (W + 1) / 6)", BLUR_KERNELS,
        sweeps=True),
    Key("map", "moment_samples", "int", "1", "N x N rays a texel, their moments averaged (an MSAA resolve)",
        ">= 1", sweeps=True),
    Key("map", "mipmaps", "bool", "false", "moments read from a mip chain at each pixel's footprint", sweeps=True),
    Key("map", "antialias", "bool or list of bool", "false", "dsm grad only: the map's silhouette texels moved "
        "toward their neighbours by the edge's exact position (dsm run refuses it)", source="Worchel & Alexa 2023",
        sweeps=True),
    Key("map", "leak_texels", "float", "2", "false light this far inside the exact shadow counts as a leak",
        ">= 0", "texels"),
    Key("map", "vsm", "table", "the kind's defaults", "VSM's parameters or preset (see Pre-filtered maps)"),
    Key("map", "esm", "table", "the kind's defaults", "ESM's parameters or preset"),
    Key("map", "evsm", "table", "the kind's defaults", "EVSM's parameters or preset"),
    Key("map", "msm", "table", "the kind's defaults", "MSM's parameters or preset"),
    Key("map", "virtual", "table", "off", "a directional or spot light's virtual shadow map (see [map.virtual])"),
    Key("map.virtual", "preset", "str or list", "(every key given)", "the engine whose values the other keys "
        "override", tuple(sorted(VIRTUAL_PRESETS)), source="docs/virtual_shadow_maps.md", sweeps=True),
    Key("map.virtual", "page_size", "int", "the preset's (ue5 128, eevee and eevee_punctual 256)", "texels a page side",
        _r(1, 4096),
        "texels"),
    Key("map.virtual", "resolution", "int", "the preset's (ue5 16384, eevee and eevee_punctual 8192)", "virtual texels "
        "a level side (a whole number of pages; punctual: level 0's, level l has 2^-l of it)", _r(1, 2 ** 20),
        "texels"),
    Key("map.virtual", "first_level", "int", "the preset's", "the finest clipmap level (a level is 2^level "
        "centimetres in UE5, 2^level units in EEVEE; punctual: >= 0, resolution / 2^level texels)", _r(-60, 60)),
    Key("map.virtual", "last_level", "int", "the preset's", "the coarsest clipmap level", _r(-60, 60)),
    Key("map.virtual", "levels", "int", "(last_level)", "levels from first_level (instead of last_level)",
        _r(1, 64)),
    Key("map.virtual", "lod_bias", "float", "the preset's (ue5 -0.5, eevee 0)", "level-of-detail bias (-1 doubles "
        "the resolution a receiver reads)", _r(-16, 16), "levels"),
    Key("map.virtual", "rule", "str", "the preset's", "how a receiver's level is chosen: its pixel footprint "
        "(UE5) or its distance (EEVEE) on a directional light, its footprint seen from a spot light (punctual, "
        "EEVEE)", VIRTUAL_RULES),
    Key("map.virtual", "unit_cm", "float", "100", "centimetres in one scene unit (UE5's levels are in centimetres)",
        "> 0", "cm"),
    Key("map.virtual", "border", "float", "the preset's (ue5 0.05, eevee 0)", "a receiver this fraction of a page "
        "from its page's edge also tags the neighbour", _r(0, 0.5), "pages"),
    Key("map.virtual", "max_pages", "int", "2048", "the physical page pool; more tagged pages stop the map",
        ">= 1", "pages"),
    Key("map.virtual", "lod_min", "float", "0", "punctual: the footprint's floor, > 0 in metres in the world, "
        "< 0 its magnitude on the light's unit plane (EEVEE's resolution limit; 0: none)", "any", "m"),
    Key("contact", "preset", "str", "none", "an engine's contact-shadow settings (no other key with it)",
        tuple(sorted(CONTACT_PRESETS))),
    Key("memory", "budget_mb", "float", "RAM / 4", "wavefront budget: larger maps are cast in tiles", "> 0", "MB"),
    Key("timing", "repeats", "int", "3", "timed calls of every lookup, build and reference (their median)",
        _r(1, 100)),
    Key("timing", "lookups", "str", "wavefront", "a map's cases looked up in one wavefront, or one by one",
        LOOKUP_MODES),
    Key("timing", "builds", "str", "alone", "each map built alone, or a light's small maps of one view kind as one "
        "wavefront", BUILD_MODES),
    Key("oracle", "lambda", "float", "1", "weight of peter-panning in the oracles' objective", _r(0, LAMBDA_MAX),
        sweeps=True),
    Key("report", "images", "str", "all", "case images written: error and shadow, errors only, none",
        REPORT_IMAGES),
    Key("execution", "backend", "str", "local", "where the cases run: here, or each map group a Ray task",
        BACKENDS),
    Key("execution", "address", "str", "local", "a Ray cluster (auto, ray://host:port) or local; backend ray only"),
    Key("execution", "cpus_per_task", "float", "1", "each Ray task's CPUs (Dr.Jit's threads in it)", "> 0"),
    Key("execution", "gpus_per_task", "float", "0", "each Ray task's GPUs (cuda_ad_rgb)", ">= 0"),
    Key("motion", "frames", "int", "8", "frames of the path", _r(2, 1000)),
    Key("motion", "camera", "str", "none", "the camera's path", CAMERA_PATHS),
    Key("motion", "offset", "[x, y, z]", "(dolly)", "the camera's whole translation over the frames", unit="world"),
    Key("motion", "angle", "float", "(pan, orbit)", "the camera's whole turn over the frames", unit="degrees"),
    Key("motion", "keys", "list of tables", "(keyframes)", "camera keyframes {position, target}, at least two"),
    Key("motion", "light", "str", "none", "the light's path", LIGHT_PATHS),
    Key("motion", "light_axis", "[x, y, z]", "[0, 0, 1]", "the axis a directional light turns about"),
    Key("motion", "light_angle", "float", "(turn)", "a directional light's whole turn over the frames",
        unit="degrees"),
    Key("motion", "light_offset", "[x, y, z]", "(move)", "a spot or point light's whole translation", unit="world"),
    Key("motion", "light_keys", "list of tables", "(keyframes)", "light keyframes {position, target}, at least two"),
    Key("motion", "points", "int", "4000", "fixed surface points whose flicker is counted", _r(1, 10_000_000)),
    Key("motion", "label", "str", "the path's", "the path's name in the results"),
    Key("motion", "casters", "list of tables", "[]", "moving shapes {shape, offset | keys, angle, axis}"),
    Key("motion", "cache", "str", "none", "the maps' cache policy: none casts a map again whenever its view or "
        "a caster moved; static only when its view changed; stagger:N also every N frames; invalidate re-casts the texels a "
        "moved caster's bounds touch", CACHE_POLICIES),
    Key("motion.casters", "shape", "str", "(required)", "the moving shape's name (the scene's shape names)"),
    Key("motion.casters", "offset", "[x, y, z]", "(offset or keys)", "the shape's whole translation over the "
        "frames (linear)", unit="world"),
    Key("motion.casters", "keys", "list of [x, y, z]", "(offset or keys)", "translations at keyframes spread "
        "evenly over the frames", unit="world"),
    Key("motion.casters", "angle", "float", "0", "the shape's whole turn over the frames, about axis through "
        "its bounding box's centre", unit="degrees"),
    Key("motion.casters", "axis", "[x, y, z]", "[0, 0, 1]", "the turn's axis"),
    Key("motion.casters", "static", "bool", "false", "flagged static although it moves: cache invalidate never "
        "re-casts for it (UE5's Static invalidation on a moving primitive)"),
    Key("motion.keys", "position", "[x, y, z]", "(required)", "a keyframe's position", unit="world"),
    Key("motion.keys", "target", "[x, y, z]", "(required for the camera)", "a keyframe's target", unit="world"),
    Key("motion.light_keys", "position", "[x, y, z]", "(required)", "a light keyframe's position", unit="world"),
    Key("motion.light_keys", "target", "[x, y, z]", "none", "a spot light's aim at the keyframe (on all or none)",
        unit="world"),
    Key("scheme", "name", "str", "(name or preset)", "a bias scheme; its parameters are on the schemes page",
        "dsm schemes"),
    Key("scheme", "preset", "str", "(name or preset)", "an engine's default bias, per light type",
        "dsm schemes (presets)"),
    # dsm grad's own table (dsm/grad/spec.py reads it; the scene, light, map and bias are the tables above)
    Key("gradient", "params", "list of str", "[\"occluder_z\"]", "the parameters differentiated, each with its unit",
        GRAD_PARAMS),
    Key("gradient", "loss", "str", "shadow_area", "the loss over the image: the shadow's area (world^2), its first "
        "moment in x (world^3), or the mean squared difference from a target image", GRAD_LOSSES),
    Key("gradient", "target", "table", "(l2 only)", "parameter values whose exact image is the l2 loss's target, "
        "e.g. {occluder_z = 0.05}"),
    Key("gradient", "image_resolution", "int", "128", "the image of receivers: pixels a side", _r(8, 4096), "pixels"),
    Key("gradient", "window", "float", "1", "the image covers [-window, window]^2 on the ground", "> 0", "world"),
    Key("gradient", "image_jitter", "bool", "true", "one receiver per pixel at a seeded random point (false: its "
        "centre)"),
    Key("gradient", "pcss_light_size", "float", "0.1", "PCSS's light width under a spot or directional light (an "
        "area light's is its size)", "> 0", "world"),
    Key("gradient", "fd_step", "table", "0.002 x size (world), 0.02 (degree)", "the central difference's first "
        "step, by parameter", "> 0"),
    Key("gradient", "fd_halvings", "int", "4", "how often the step is halved while a class changes within it",
        _r(0, 20)),
    Key("gradient", "reference_samples", "int", "32", "--compare: the truth's receivers per pixel and axis",
        _r(1, 64)),
    Key("gradient", "reference_step", "table", "0.04 x size (world), 1 (degree)", "--compare: the truth's "
        "central-difference step, by parameter", "> 0"),
    Key("gradient", "projective_spp", "int", "64", "--compare: Mitsuba's projective integrators' samples per pixel",
        _r(1, 4096)),
    Key("gradient", "projective_seeds", "int", "4", "--compare: their seeds", _r(1, 64)),
    Key("gradient", "projective_integrators", "list of str", "both", "--compare: Mitsuba's projective integrators",
        GRAD_PROJECTIVE),
    Key("gradient", "inverse_starts", "list of float", "[-0.1, -0.05, 0.05, 0.1]", "--inverse: starting offsets "
        "from the truth, in the parameter's unit"),
    Key("gradient", "inverse_iterations", "int", "40", "--inverse: Adam's steps", _r(1, 1000)),
    Key("gradient", "inverse_tolerance", "float", "0.01", "--inverse: a start succeeds within it", "> 0"),
    Key("gradient", "light_samples", "int", "8", "area light: the truth's light samples per receiver and axis",
        _r(1, 32)),
    Key("gradient", "equal_error_spp", "list of int", "[1, 4, 16, 64, 256]", "area light, --compare: path "
        "tracing's samples per pixel, strictly increasing", _r(1, 4096)),
    Key("gradient", "equal_error_seeds", "int", "4", "area light, --compare: seeds per spp", _r(2, 64)),
    Key("tune", "lambda", "float", "1", "the objective: (acne + lambda peter-panning) / receivers",
        _r(0, LAMBDA_MAX)),
    Key("tune", "steps", "int", "100", "gradient steps a scheme", _r(1, 100000)),
    Key("tune", "lr", "float", "0.5", "step size at the first temperature", "> 0", "texels"),
    Key("tune", "temperature", "[start, end]", "[0.25, 0.02]", "the sigmoid's temperature, annealed down",
        "start >= end > 0", "texels"),
    Key("tune", "schedule", "str", "geometric", "how the temperature falls", SCHEDULES),
    Key("tune", "seed", "int", "[experiment] seed", "draws each step's receivers when batch < 1", _r(0, SEED_MAX)),
    Key("tune", "batch", "float", "1", "fraction of training receivers drawn per step", "> 0 to 1"),
    Key("tune", "params", "table", "every continuous parameter", "scheme name = [parameters to tune]"),
    Key("tune", "range", "table", "0 to start + 16 texels' worth", "search box per scheme and parameter, in its "
        "unit"),
    Key("tune", "camera", "array of tables", "the scene's camera (train)", "training and held-out cameras"),
    Key("tune", "bias_map", "table", "none", "a learned bias map (see tune.bias_map)"),
    Key("tune", "scan", "int", "0", "points of an exact 1-D scan of one-parameter schemes", _r(0, 100000)),
    Key("tune", "gradcheck", "bool", "false", "AD against central differences of the relaxed loss"),
    Key("tune", "search", "str", "ad", "optuna: also Optuna's TPE on the exact objective at the AD tuner's number "
        "of exact evaluations (the extra dsm[tune])", SEARCHES),
    Key("tune", "objectives", "int", "1", "2: also NSGA-II on acne and peter-panning, its Pareto front "
        "(search = optuna)", "1 or 2"),
    Key("tune.camera", "name", "str", "cam<i>", "the camera's name in the results"),
    Key("tune.camera", "position", "[x, y, z]", "(required)", "scales and moves with a built-in's scale, translate",
        unit="world"),
    Key("tune.camera", "target", "[x, y, z]", "(required)", "the point it looks at", unit="world"),
    Key("tune.camera", "up", "[x, y, z]", "[0, 0, 1]", "its up direction"),
    Key("tune.camera", "fov", "float", "40", "horizontal field of view", "> 0 to 179", "degrees"),
    Key("tune.camera", "role", "str", "train", "fitted on, or judged on", ROLES),
    Key("tune.bias_map", "fit", "str", "edge", "adam: a bias per block; residual: over the best tuned scheme; "
        "edge: predicted per receiver from its 3 x 3 texels", MAP_FITS),
    Key("tune.bias_map", "block", "int or list", "1 (residual: [1, 2, 4])", "texels a side per bias value", ">= 1",
        "texels"),
    Key("tune.bias_map", "unit", "str", "world", "the unit of the map's values", MAP_UNITS),
    Key("tune.bias_map", "init", "length", "0", "the map's start value", unit=LENGTH),
    Key("tune.bias_map", "steps", "int", "[tune] steps", "adam: steps", ">= 1"),
    Key("tune.bias_map", "lr", "float", "[tune] lr", "adam: step size", "> 0"),
    Key("tune.bias_map", "radius", "list of int", "[0, 1, 2]", "residual: smoothing across blocks (candidates)",
        ">= 0", "blocks"),
    Key("tune.bias_map", "min_gain", "list of int", "[1, 2, 3]", "residual: errors a block must save (candidates)",
        ">= 0"),
    Key("tune.bias_map", "margin", "float", "0.5", "residual: kept inside a block's optimal interval", ">= 0",
        "texels"),
    Key("tune.bias_map", "width", "list of float", "[1, 1.125, 1.25, 1.375, 1.5]", "edge: tent half-widths",
        "0.5 to 1.5", "texels"),
    Key("tune.bias_map", "clip", "list of float", "[0.5, 1, 2, 4, 8]", "edge: margins a vote saturates at", "> 0",
        "texels"),
    Key("tune.bias_map", "grazing", "list of float", "[0, 0.125, ..., 1]", "edge: the threshold's rise per "
        "(1 - cos)", ">= 0"),
    Key("tune.bias_map", "samples", "int", "4", "edge: light rays a texel side for per-texel offsets (0: none)",
        _r(0, 16)),
    Key("tune.bias_map", "layers", "int", "8", "edge: surfaces followed along each light ray", ">= 1"),
)

TABLES = ("experiment", "camera", "scene", "light", "map", "map.virtual", "contact", "hybrid", "memory", "timing", "oracle",
          "report", "execution", "motion", "motion.keys", "motion.light_keys", "motion.casters", "scheme", "gradient", "tune",
          "tune.camera", "tune.bias_map")


def keys_of(table: str) -> tuple:
    """The declared keys of ``table`` (e.g. "map", "tune.bias_map"), in declaration order."""
    return tuple(k for k in KEYS if k.table == table)


def exact_text(value) -> str:
    """A default as a user may paste it back into TOML: floats by their shortest repr, a Length as
    \"value unit\" (world units as a bare number), tuples as lists."""
    if isinstance(value, Length):
        return _exact(value.value) if value.unit == "world" else f'"{_exact(value.value)} {value.unit}"'
    if isinstance(value, bool) or value is None:
        return str(value).lower()
    if isinstance(value, float):
        return "inf" if value == float("inf") else _exact(value)
    if isinstance(value, tuple):
        return "[" + ", ".join(exact_text(v) for v in value) + "]"
    return f'"{value}"' if isinstance(value, str) else str(value)


def contact_bounds() -> dict:
    """[contact]'s bounds the reader checks beyond its fields' metadata (dsm.config.read)."""
    from .read import CONTACT_MAX_STEPS
    return {"length": "> 0", "steps": _r(1, CONTACT_MAX_STEPS), "jitter": _r(0, 1)}


def dataclass_keys(table: str, cls, bounds: dict | None = None) -> tuple:
    """Keys of a table read into dataclass ``cls`` (its fields' defaults and metadata: doc, min, max,
    choices, path: a file's suffixes); ``bounds`` gives the valid range of fields the reader bounds further."""
    out = []
    for f in dataclasses.fields(cls):
        md = f.metadata
        lo, hi = md.get("min"), md.get("max")
        valid = md.get("choices") or md.get("path") or (_r(lo, hi) if lo is not None and hi is not None else
                                      (_r(lo) if lo is not None else ""))
        valid = (bounds or {}).get(f.name, valid)
        default = exact_text(f.default) if f.default is not dataclasses.MISSING else "(required)"
        ftype = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
        ftype = {"Length": "length", "tuple": "[x, y, z]"}.get(ftype, ftype)
        out.append(Key(table, f.name, ftype, str(default),
                       md.get("doc", ""), valid, LENGTH if ftype == "length" else ""))
    return tuple(out)


def hybrid_keys() -> tuple:
    """``[hybrid]``'s keys (one table or an array of them): the rule, the origin rule and every rule's
    parameters (dsm.hybrid), each read by the reader's one parse_hybrid."""
    from .. import hybrid
    out = [Key("hybrid", "rule", "str", "(required)", "the rule that sends receivers to rays (a case per "
               "instance of every depth case)", hybrid.names(), source="docs/hybrid.md"),
           Key("hybrid", "origin", "str", "spawn", "where a hybrid's ray starts (dsm.hybrid.origins)", HYBRID_ORIGINS,
               source="kit; Mitsuba 3.9; Wachter & Binder 2019 (Ray Tracing Gems ch. 6); absolute 1e-4", sweeps=True)]
    for rule in hybrid.REGISTRY:
        out += [dataclasses.replace(k, sweeps=True, source=rule.SOURCE) for k in dataclass_keys("hybrid", rule.Params)]
    return tuple(out)


KEYS = KEYS + hybrid_keys()
