"""The ``[tune]`` table of an experiment config, read into a typed, frozen TuneSpec at load time."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..core.types import LAMBDA_MAX, SEED_MAX, ConfigError, Length, as_list, check_keys, choice, number, vec3


TUNE_KEYS = ("lambda", "steps", "lr", "temperature", "schedule", "seed", "batch", "params", "range", "camera",
             "bias_map", "scan", "gradcheck", "search", "objectives")
SEARCHES = ("ad", "optuna")     # the gradient tuner alone, or beside Optuna at its number of exact evaluations
CAMERA_KEYS = ("name", "position", "target", "up", "fov", "role")
ROLES = ("train", "heldout")
SCHEDULES = ("geometric", "linear")
MAP_KEYS = ("block", "unit", "init", "steps", "lr", "fit", "radius", "min_gain", "margin", "width", "clip", "grazing",
            "samples", "layers")
MAP_FITS = ("adam", "residual", "edge")
EDGE_KEYS = ("width", "clip", "grazing", "samples", "layers")
MAX_SAMPLES = 16                  # light rays a texel side: 16^2 rays a texel already costs 256 maps' casts
EDGE_WIDTH_TEXELS = (0.5, 1.5)    # the edge map's tent half-widths: wider than 1.5 reaches beyond its 3 x 3 taps
MAP_UNITS = ("world", "texel")


def tunable(module) -> tuple:
    """The continuous parameters of a scheme module (Length, float): the ones tuning can move."""
    return tuple(f.name for f in dataclasses.fields(module.Params)
                 if f.type in ("Length", Length, "float", float))


def valid_min(module, name):
    """A scheme parameter's valid minimum (its field metadata), None when unbounded."""
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
    fit: str = "edge"                 # edge (dsm.tune.edge_map, the fit that beats the best global scheme on
                                      # held-out views); adam: a bias per block by Adam; residual: dsm.tune.residual_map
    blocks: tuple = (1, 2, 4)         # residual: the candidates of validation (block, radius, min_gain)
    radii: tuple = (0, 1, 2)
    gains: tuple = (1, 2, 3)
    margin: float = 0.5               # residual: texels kept inside a block's optimal interval
    widths: tuple = (1.0, 1.125, 1.25, 1.375, 1.5)     # edge: tent half-widths (texels), see dsm.tune.edge_map
    clips: tuple = (0.5, 1.0, 2.0, 4.0, 8.0)           # edge: margins (texels) a vote saturates at
    grazings: tuple = (0.0, 0.125, 0.25, 0.375, 0.5, 0.75, 1.0)   # edge: the threshold's rise per (1 - cos)
    samples: int = 4                  # edge: light rays a texel side for its per-texel offsets (0: shared threshold only)
    layers: int = 8                   # edge: surfaces followed along each light ray


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
    search: str = "ad"                        # "optuna": also a black-box study per scheme (dsm.tune.blackbox)
    objectives: int = 1                       # 2: also NSGA-II on (acne, peter-panning), its Pareto front


def parse_tune(raw: dict, source: str, seed: int, schemes: tuple) -> TuneSpec | None:
    """The ``[tune]`` table of raw tables ``raw`` as a TuneSpec (None without one), checked when the config
    is read: a ConfigError names the file, the key and its choices."""
    if "tune" not in raw:
        return None
    return tune_spec(raw["tune"], source, seed, schemes)


def tune_spec(t, src: str, seed: int, schemes: tuple) -> TuneSpec:
    """A ``[tune]`` table ``t`` of ``src`` checked into a TuneSpec; ``seed``: the experiment's (the default),
    ``schemes``: the config's [[scheme]] instances, which tune.params and tune.range name."""
    if not isinstance(t, dict):
        raise ConfigError(src, "tune", "expected a table [tune]")
    check_keys(t, TUNE_KEYS, src, "tune")
    lam = number(t.get("lambda", 1.0), src, "tune.lambda", minimum=0, maximum=LAMBDA_MAX)
    steps = number(t.get("steps", 100), src, "tune.steps", integer=True, minimum=1, maximum=100000)
    lr = number(t.get("lr", TuneSpec.lr), src, "tune.lr", positive=True)
    temp = _temperature(t, src)
    schedule = choice(t.get("schedule", "geometric"), src, "tune.schedule", SCHEDULES)
    seed = number(t.get("seed", seed), src, "tune.seed", integer=True, minimum=0, maximum=SEED_MAX)
    batch = number(t.get("batch", 1.0), src, "tune.batch", positive=True, maximum=1.0)
    scan = number(t.get("scan", 0), src, "tune.scan", integer=True, minimum=0, maximum=100000)
    if scan == 1:                 # evenly spaced with both ends of the box: one point holds only the low end
        raise ConfigError(src, "tune.scan", "a scan takes both ends of the search box: give 0 (no scan) or at least 2")
    gradcheck = t.get("gradcheck", False)
    if not isinstance(gradcheck, bool):
        raise ConfigError(src, "tune.gradcheck", f"expected true or false, got {gradcheck!r}", ("true", "false"))
    search = choice(t.get("search", "ad"), src, "tune.search", SEARCHES)
    objectives = number(t.get("objectives", 1), src, "tune.objectives", integer=True, minimum=1, maximum=2)
    if objectives == 2 and search != "optuna":
        raise ConfigError(src, "tune.objectives", "two objectives are searched by Optuna's NSGA-II: give "
                          "search = \"optuna\" with it", ("1",))
    names = tuned_names(schemes)
    params = _params(t, src, names)
    ranges = _ranges(t, src, names, params)
    cams = _cameras(t, src)
    bmap = _bias_map(t["bias_map"], src, steps, lr, cams) if "bias_map" in t else None
    return TuneSpec(lam, steps, lr, temp, schedule, seed, batch, params, ranges, cams, bmap, scan, gradcheck, search,
                    objectives)


def tuned_names(schemes: tuple) -> list:
    """The sorted scheme names of ``schemes`` that dsm tune can tune: a shadow-map lookup with a
    continuous parameter (dsm tune refuses the others, naming them)."""
    from ..schemes import get
    return sorted({s.name for s in schemes
                   if get(s.name).VIEWS is None and tunable(get(s.name))})


def _temperature(t: dict, src: str) -> tuple:
    """tune.temperature: [start, end] in texels, annealed down."""
    temp = t.get("temperature", list(TuneSpec.temperature))
    if not isinstance(temp, list) or len(temp) != 2:
        raise ConfigError(src, "tune.temperature", f"expected [start, end] in texels, got {temp!r}")
    temp = tuple(number(x, src, "tune.temperature", positive=True) for x in temp)
    if temp[0] < temp[1]:
        raise ConfigError(src, "tune.temperature", f"[start, end] anneals down: start must be at or above end, "
                          f"got [{temp[0]:g}, {temp[1]:g}] (e.g. [0.25, 0.02])")
    return temp


def _params(t: dict, src: str, names: list) -> dict:
    """tune.params: scheme name -> the tuned parameter names (default: every continuous one)."""
    from ..schemes import get
    params_raw = t.get("params", {})
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
    return params


def _ranges(t: dict, src: str, names: list, params: dict) -> dict:
    """tune.range: (scheme name, parameter) -> (lo, hi) in the parameter's unit."""
    from ..schemes import get
    ranges = {}
    range_raw = t.get("range", {})
    if not isinstance(range_raw, dict):
        raise ConfigError(src, "tune.range", "expected tables [tune.range.<scheme>] of parameter = [lo, hi]")
    for n, table in range_raw.items():
        if n not in names:
            raise ConfigError(src, f"tune.range.{n}", "no [[scheme]] of that name is tuned", names)
        if not isinstance(table, dict):
            raise ConfigError(src, f"tune.range.{n}", "expected a table of parameter = [lo, hi]")
        for p, lohi in table.items():
            key = f"tune.range.{n}.{p}"
            choice(p, src, key, params[n])
            if not isinstance(lohi, list) or len(lohi) != 2:
                raise ConfigError(src, key, f"expected [lo, hi] in the parameter's unit, got {lohi!r}")
            lo, hi = (number(x, src, key) for x in lohi)
            vmin = valid_min(get(n), p)
            if not lo < hi:
                raise ConfigError(src, key, f"lo must be below hi, got {lohi!r}")
            if vmin is not None and lo < vmin:
                raise ConfigError(src, key, f"lo must be >= {vmin:g} (the parameter's valid range), got {lo!r}")
            ranges[(n, p)] = (lo, hi)
    return ranges


def _cameras(t: dict, src: str) -> tuple:
    """[[tune.camera]]: each a TuneCamera; names distinct, one training camera at least when any is given."""
    cam_raw = t.get("camera", [])
    if isinstance(cam_raw, dict):
        cam_raw = [cam_raw]
    if not isinstance(cam_raw, list) or not all(isinstance(c, dict) for c in cam_raw):
        raise ConfigError(src, "tune.camera", "expected an array of tables [[tune.camera]]")
    cams = [_camera(c, src, i) for i, c in enumerate(cam_raw)]
    if len({c.name for c in cams}) != len(cams):
        raise ConfigError(src, "tune.camera", "camera names must differ")
    if cams and not any(c.role == "train" for c in cams):
        raise ConfigError(src, "tune.camera", "no camera has role = \"train\"", ROLES)
    pose = lambda c: (c.position, c.target, c.up, c.fov)
    for i, c in enumerate(cams):
        twin = next((d for d in cams[:i] if pose(d) == pose(c)), None)
        if twin is not None:        # a held-out view equal to a training view measures nothing held out
            raise ConfigError(src, f"tune.camera[{i}]", f"the same pose as camera {twin.name!r}: give each "
                              "camera its own position, target, up or fov")
    return tuple(cams)


def _camera(c: dict, src: str, i: int) -> TuneCamera:
    """One [[tune.camera]] table: a position, a target, an up across the view, a fov, a role, a name."""
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
    return TuneCamera(name, pos, tgt, up, fov, role)


def _bias_map(b, src: str, steps: int, lr: float, cams: tuple) -> BiasMapSpec:
    """[tune.bias_map]: the fit (edge, the default; adam or residual, baselines) and its keys, Adam's
    defaulting to [tune]'s steps and lr."""
    if not isinstance(b, dict):
        raise ConfigError(src, "tune.bias_map", "expected a table [tune.bias_map]")
    check_keys(b, MAP_KEYS, src, "tune.bias_map")
    unit = choice(b.get("unit", "world"), src, "tune.bias_map.unit", MAP_UNITS)
    init = Length.parse(b.get("init", f"0 {unit}" if unit != "world" else 0.0), src, "tune.bias_map.init")
    if init.unit != unit:
        raise ConfigError(src, "tune.bias_map.init", f"give the start in the map's unit ({unit})", MAP_UNITS)
    fit = choice(b.get("fit", BiasMapSpec.fit), src, "tune.bias_map.fit", MAP_FITS)
    ints = lambda key, default, lo: _map_ints(b, src, key, default, lo)
    blocks = ints("block", BiasMapSpec.blocks if fit == "residual" else [2] if fit == "edge" else [1], 1)
    if fit in ("adam", "edge") and len(blocks) != 1:
        raise ConfigError(src, "tune.bias_map.block", f"{fit} takes one block size: give one number (a list is "
                          "validated with fit = \"residual\")", MAP_FITS)
    for key in ("radius", "min_gain", "margin"):
        if key in b and fit != "residual":
            raise ConfigError(src, f"tune.bias_map.{key}", "only with fit = \"residual\"", MAP_FITS)
    for key in EDGE_KEYS:
        if key in b and fit != "edge":
            raise ConfigError(src, f"tune.bias_map.{key}", "only with fit = \"edge\"", MAP_FITS)
    for key in ("unit", "init", "steps", "lr"):     # the residual and edge maps are fitted exactly: no Adam
        if key in b and fit in ("residual", "edge"):
            raise ConfigError(src, f"tune.bias_map.{key}", "only with fit = \"adam\" (the residual and edge "
                              "maps are fitted exactly, no Adam)", MAP_FITS)
    bmap = BiasMapSpec(blocks[0], unit, init,
                       number(b.get("steps", steps), src, "tune.bias_map.steps", integer=True, minimum=1,
                              maximum=100000),
                       number(b.get("lr", lr), src, "tune.bias_map.lr", positive=True), fit, blocks,
                       ints("radius", BiasMapSpec.radii, 0), ints("min_gain", BiasMapSpec.gains, 1),
                       number(b.get("margin", BiasMapSpec.margin), src, "tune.bias_map.margin", minimum=0),
                       *_edge_candidates(b, src),
                       number(b.get("samples", BiasMapSpec.samples), src, "tune.bias_map.samples", integer=True,
                              minimum=0, maximum=MAX_SAMPLES),
                       number(b.get("layers", BiasMapSpec.layers), src, "tune.bias_map.layers", integer=True,
                              minimum=1, maximum=64))
    if fit == "residual" and sum(c.role == "train" for c in cams) < 2:
        raise ConfigError(src, "tune.camera", "a residual map chooses its block size by leaving one training "
                          "camera out: give at least two [[tune.camera]] with role = \"train\"", ROLES)
    if not any(c.role == "heldout" for c in cams):
        raise ConfigError(src, "tune.camera", "a learned bias map is judged on held-out views: add a "
                          "[[tune.camera]] with role = \"heldout\"", ROLES)
    return bmap


def _edge_candidates(b: dict, src: str) -> tuple:
    """The edge map's candidate lists (width within 0.5 to 1.5 texels: the 3 x 3 taps; clip above 0; grazing >= 0)."""
    out = []
    for key, lo, hi, pos in (("width", *EDGE_WIDTH_TEXELS, True), ("clip", None, None, True),
                             ("grazing", 0.0, None, False)):
        vals = as_list(b.get(key, list(getattr(BiasMapSpec, key + "s"))))
        if not vals:
            raise ConfigError(src, f"tune.bias_map.{key}", "empty list: give at least one value")
        nums = tuple(number(x, src, f"tune.bias_map.{key}", positive=pos, minimum=lo, maximum=hi) for x in vals)
        if key == "width" and min(nums) <= EDGE_WIDTH_TEXELS[0]:
            raise ConfigError(src, "tune.bias_map.width", "a tent of half-width 0.5 texel or less can miss every tap: "
                              "give widths above 0.5 (1: bilinear)")
        out.append(nums)
    return tuple(out)


def _map_ints(b: dict, src: str, key: str, default, lo: int) -> tuple:
    """A bias-map key's candidates: one integer or a non-empty list."""
    vals = as_list(b.get(key, list(default)))
    if not vals:
        raise ConfigError(src, f"tune.bias_map.{key}", f"empty list: give at least one value (default {list(default)})")
    return tuple(number(x, src, f"tune.bias_map.{key}", integer=True, minimum=lo) for x in vals)
