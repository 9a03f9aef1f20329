"""Experiment configs: TOML read once into frozen, validated dataclasses.

Everything is checked before any work starts. A mistake raises :class:`ConfigError`, whose
message names the file, the key and the valid choices. Lists sweep: every list-valued scheme
parameter, scene parameter or map option multiplies the cases (see :func:`expand`).
"""
from __future__ import annotations

import dataclasses
import itertools
import os
import tomllib
from dataclasses import replace
from pathlib import Path

from .virtual import check_reach, parse_virtual
from ..core.types import (LENGTH_UNITS, FILTERS, FORMATS, POINT_VIEWS, MAP_VIEWS, VARIANTS, CULLINGS, VIEW_FACES, DEFAULT_CAMERA, REPORT_IMAGES, LOOKUP_MODES, BUILD_MODES, LAMBDA_MAX, SEED_MAX, ConfigError, NothingToRun, Length, number, choice, vec3, as_list, check_keys, coerce_field, sweep_params, SceneSpec, LightSpec, MapSpec, SchemeSpec, OracleSpec, Config, describe_params, BACKENDS, ExecutionSpec, CameraSpec, CascadeSpec, CASCADE_SPLITS, CASCADE_FITS, DEPTH_BOUNDS, MAX_CASCADES, MotionSpec, CAMERA_PATHS, LIGHT_PATHS, CACHE_POLICIES, CasterPath, MAP_KINDS, MomentSpec, ContactSpec, BLUR_KERNELS, HybridSpec, HYBRID_ORIGINS)

# a run's folder is runs/<name>-tune-YYYYmmdd-HHMMSS[-n] (at most 25 bytes more) and a file name takes 255 bytes
NAME_MAX_BYTES = 255 - len("-tune-20240101-120000-999")
KIND_KEYS = ("kind", "blur", "blur_kernel", "moment_samples", "mipmaps", "leak_texels", "vsm", "esm", "evsm", "msm")    # [map] kind and its tables
CASCADE_KEYS = ("cascades", "split", "lambda", "fit", "depth_bounds", "stabilize", "blend", "max_distance")


TOP_KEYS = ("experiment", "camera", "scene", "light", "map", "scheme", "timing", "memory", "oracle", "report", "motion",
            "execution", "tune", "contact", "gradient", "hybrid")    # [tune]: read by dsm tune, [gradient] by dsm grad; ignored by dsm run


# the shipped experiments named after a source's file number before 0.2.0 (CHANGELOG.md)
RENAMED_EXPERIMENTS = {"seed002_fit.toml": "common_techniques_fit.toml",
                       "seed002_shimmer.toml": "common_techniques_shimmer.toml"}


def load(path) -> Config:
    """The Config read from TOML file ``path``; ConfigError for a missing, unreadable or invalid file."""
    path = Path(path)
    return parse(read_toml(path), str(path), base=path.parent)


def read_toml(path) -> dict:
    """The tables of TOML file ``path``; a ConfigError in one line for a folder, a missing, unreadable,
    non-UTF-8 or invalid file (every command's config is read here)."""
    path = Path(path)
    source = str(path)
    if path.is_dir():
        raise ConfigError(source, "file", "is a folder, not a config file")
    if not path.is_file():
        moved = RENAMED_EXPERIMENTS.get(path.name)
        raise ConfigError(source, "file", "no such config file" + (
            f"; renamed in 0.2.0 to {path.with_name(moved)} (experiments are named by their paper)" if moved else ""))
    try:
        with open(path, "rb") as fh:
            raw = tomllib.load(fh)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(source, "toml", f"not valid TOML: {e}") from None
    except UnicodeDecodeError as e:
        raise ConfigError(source, "file", f"not UTF-8 text (byte 0x{e.object[e.start]:02x} at offset {e.start}): "
                          "TOML files are UTF-8; save it as UTF-8") from None
    except OSError as e:
        raise ConfigError(source, "file", f"cannot read it: {e.strerror or e}") from None
    return raw


def coerce(obj, source: str = "<dict>") -> Config:
    """A Config from what ``dsm.run`` accepts: a Config, a dict of config tables, or a path (str or
    os.PathLike) to a TOML file. Anything else is a TypeError with one line saying what is accepted;
    a mistake inside is a ConfigError."""
    if isinstance(obj, Config):
        return obj
    if isinstance(obj, dict):
        return parse(obj, source)
    if isinstance(obj, (str, os.PathLike)):
        return load(obj)
    raise TypeError(f"dsm.run: config must be a dsm Config, a dict of config tables or a path to a TOML file, "
                    f"not {type(obj).__name__} ({obj!r:.60})")


def absent_files(cfg: Config) -> list:
    """Files of the config's optional scenes that are absent (each once, in config order)."""
    out = []
    for s in cfg.scenes:
        name = s.file if s.file is not None else f"{s.model} (no copy given)"      # a model without a path
        if s.missing and name not in out:
            out.append(name)
    return out


def check_runnable(cfg: Config):
    """Raise NothingToRun when every scene of the config is an absent optional file."""
    if cfg.scenes and all(s.missing for s in cfg.scenes):
        model = next((s for s in cfg.scenes if s.model), None)
        if model is not None:           # a model's own line: its keys and where to obtain a copy
            raise NothingToRun(cfg.source, f"{model.where}.model", "nothing to run: "
                               + model.missing.removeprefix("skipped: "))
        files = absent_files(cfg)
        where = sorted({str(f.parent) for f in files})
        raise NothingToRun(cfg.source, "scene", "nothing to run: every scene is an absent optional file ("
                           + ", ".join(f.name for f in files) + f" in {', '.join(where)}); "
                           "put the files at those paths to run them (models without redistribution terms are not shipped: "
                           "data/meshes/README.md)")


def _plain_name(name, source):
    if not isinstance(name, str) or not name:
        raise ConfigError(source, "experiment.name", "expected a non-empty string")
    if ("/" in name or "\\" in name or name in (".", "..") or any(ord(c) < 32 for c in name)
            or os.sep in name or (os.altsep and os.altsep in name)):
        raise ConfigError(source, "experiment.name", f"{name!r} must be a plain file name (it names the results "
                          "folder under runs/): no '/', '\\', '..' or control characters")
    if len(os.fsencode(name)) > NAME_MAX_BYTES:
        raise ConfigError(source, "experiment.name", f"{name[:24]!r}... is {len(os.fsencode(name))} bytes long; "
                          f"it names the results folder runs/<name>-<time>, so at most {NAME_MAX_BYTES} bytes")
    return name


def _check_light_scenes(lights, scenes, source):
    """ConfigError where a light's ``scenes = [...]`` names no scene of the config (the light would
    light nothing, silently)."""
    for i, light in enumerate(lights):
        for name in light.scenes:
            if not any(replace(light, scenes=(name,)).applies_to(sc.label) for sc in scenes):
                firsts = {sc.label.replace("(", " ").split()[0] for sc in scenes}
                raise ConfigError(source, f"light[{i}].scenes", f"{name!r} names no scene of the config (a scene's "
                                  "label, or its first word)", sorted(firsts | {sc.label for sc in scenes}))


def parse(raw: dict, source: str = "<config>", base: Path | None = None) -> Config:
    """The Config of raw TOML tables ``raw`` from ``source`` (files relative to ``base``), every value checked."""
    base = Path(base or ".")
    check_keys(raw, TOP_KEYS, source, "")
    name, seed, variant = _parse_experiment(raw, source)
    cam = _table(raw, "camera", source)
    check_keys(cam, ("resolution", "position", "target", "up", "fov", "near", "far"), source, "camera")
    camera_resolution = _parse_camera_resolution(cam, source)
    camera = _parse_camera(cam, source)
    scenes = _parse_scenes(raw, source, base)
    lights = _parse_lights(raw, source, scenes)
    m = _table(raw, "map", source)
    mapspec = _parse_map(m, lights, source)
    check_reach(mapspec.virtual, sorted({sc.params.scale for sc in scenes if sc.params is not None}), source)
    schemes = _parse_schemes(raw, mapspec, source)
    budget, (repeats, lookups, builds), lambdas, report_images = _parse_run_tables(raw, source)
    motion = tuple(_parse_motion(t, source, f"motion[{i}]") for i, t in enumerate(_array_of_tables(raw, "motion", source)))
    _check_motion_lights(motion, lights, source)
    _check_motion_casters(motion, scenes, source)
    _check_motion_moments(motion, mapspec, source)
    contact = _parse_contact(raw, source, bool(motion))
    shrink = _parse_shrink(m, source, bool(motion))
    hybrid = parse_hybrid(raw, source, bool(motion), lights, mapspec)
    from .tune import parse_tune                 # [tune]: dsm tune's, checked here so a bad key fails at load
    tune = parse_tune(raw, source, seed, tuple(schemes))
    return Config(name=name, source=source, seed=seed, variant=variant, camera_resolution=camera_resolution,
                  camera=camera, motion=motion,
                  scenes=tuple(scenes), lights=tuple(lights), map=mapspec, schemes=tuple(schemes),
                  timing_repeats=repeats, timing_lookups=lookups, timing_builds=builds, memory_budget_mb=budget, oracle=OracleSpec(lambdas),
                  report_images=report_images, raw=raw, contact=contact, shrink=shrink, tune=tune, hybrid=hybrid,
                  execution=_parse_execution(_table(raw, "execution", source), source))


def _parse_experiment(raw: dict, source: str) -> tuple:
    """``[experiment]``: (name, seed, variant or None)."""
    exp = _table(raw, "experiment", source)
    check_keys(exp, ("name", "seed", "variant"), source, "experiment")
    name = _plain_name(exp.get("name", Path(source).stem if not source.startswith("<") else "experiment"), source)
    seed = number(exp.get("seed", 7), source, "experiment.seed", integer=True, minimum=0, maximum=SEED_MAX)
    variant = exp.get("variant")
    if variant is not None:
        choice(variant, source, "experiment.variant", VARIANTS)
    return name, seed, variant


def _parse_camera_resolution(cam: dict, source: str):
    """``[camera] resolution`` as (width, height) pixels (one number: square), None where not given."""
    if "resolution" not in cam:
        return None
    res = cam["resolution"]
    if isinstance(res, int) and not isinstance(res, bool):
        res = [res, res]
    if not isinstance(res, list) or len(res) != 2:
        raise ConfigError(source, "camera.resolution", f"expected [width, height], got {res!r}")
    return tuple(number(x, source, "camera.resolution", integer=True, minimum=1, maximum=16384) for x in res)


def _parse_scenes(raw: dict, source: str, base: Path) -> list:
    """Every ``[[scene]]`` table (at least one), swept, as SceneSpecs; files relative to ``base``."""
    from ..scenes.params import BUILTINS
    from ..scenes.spec import parse_scene
    scene_tables = _array_of_tables(raw, "scene", source)
    if not scene_tables:
        raise ConfigError(source, "scene", "at least one [[scene]] is required", BUILTINS)
    scenes = []
    for i, t in enumerate(scene_tables):
        scenes += parse_scene(t, source, f"scene[{i}]", base)
    return scenes


def _parse_lights(raw: dict, source: str, scenes) -> list:
    """Every ``[[light]]`` table as a LightSpec (none: the scenes' own lights), checked against ``scenes``."""
    lights = []
    for i, t in enumerate(_array_of_tables(raw, "light", source)):
        lights.append(_parse_light(t, source, f"light[{i}]"))
    if not lights:
        lights = [LightSpec("scene", label="scene")]
    _check_light_scenes(lights, scenes, source)
    return lights


def _parse_map(m: dict, lights, source: str) -> MapSpec:
    """The ``[map]`` table ``m`` as a MapSpec: sizes, filters, formats, views, cascades and kinds."""
    check_keys(m, ("resolution", "texels", "filter", "format", "view", "shrink", "virtual", "antialias") + CASCADE_KEYS
               + KIND_KEYS, source, "map")
    if "antialias" in m:        # dsm grad's key: a run would ignore it, so it says so
        raise ConfigError(source, "map.antialias", "is read only by dsm grad (Worchel & Alexa 2023's antialiased map, "
                          "differentiated); dsm run has no antialiased map: remove it")
    if "resolution" in m and "texels" in m:
        raise ConfigError(source, "map", "give either resolution (per face) or texels (total per view), not both",
                          ("resolution", "texels"))
    texels = tuple(number(r, source, "map.texels", integer=True, minimum=1, maximum=6 * 16384 ** 2)
                   for r in as_list(m.get("texels", [])))
    resolutions = tuple(number(r, source, "map.resolution", integer=True, minimum=1, maximum=16384)
                        for r in as_list(m.get("resolution", 512)))
    filters = tuple(_filter(f, source) for f in as_list(m.get("filter", "nearest")))
    formats = tuple(choice(f, source, "map.format", FORMATS) for f in as_list(m.get("format", "float32")))
    views = tuple(choice(v, source, "map.view", MAP_VIEWS) for v in as_list(m.get("view", "dual_paraboloid")))
    for key, vals in (("map.resolution", resolutions), ("map.filter", filters), ("map.format", formats),
                      ("map.view", views)):
        if not vals:
            raise ConfigError(source, key, "empty list")
        once(vals, source, key)
    once(texels, source, "map.texels")
    _check_map_lights(m, views, lights, source)
    cascade = _parse_cascades(m, source)
    if cascade and all(l.type not in ("directional", "scene") for l in lights):
        raise ConfigError(source, "map.cascades", "cascades are for directional lights and no [[light]] is "
                          f"directional (the lights are {', '.join(sorted({l.type for l in lights}))}); remove "
                          "map.cascades or add a directional light")
    kinds = _parse_kinds(m, formats, lights, cascade, source)
    virtual = parse_virtual(m, lights, source)
    if virtual and kinds != ("depth",):
        raise ConfigError(source, "map.virtual", "pre-filtered maps are built on one map per view; remove "
                          "[map.virtual] or keep map.kind = depth", ("depth",))
    if "leak_texels" in m and "kind" not in m:
        raise ConfigError(source, "map.leak_texels", "the leak split is made in runs that give map.kind (e.g. "
                          'kind = ["depth"]); add it', ("kind",))
    return MapSpec(resolutions, filters, formats, views, texels, cascade, kinds,
                   _parse_moments(m, kinds, formats, source),
                   "kind" in m, number(m.get("leak_texels", 2.0), source, "map.leak_texels", minimum=0.0), virtual)


def once(values, source: str, key: str):
    """ConfigError where a list of case dimension ``key`` gives a value twice (a repeat would run
    the same cases twice, under two ids)."""
    seen = set()
    for v in values:
        if v in seen:
            raise ConfigError(source, key, f"{v} is given twice: give each value once")
        seen.add(v)


def _check_map_lights(m: dict, views, lights, source: str):
    """ConfigError where ``[map] view`` is given and no [[light]] is one the views are for."""
    from .. import lights as light_types
    vsv_light = "vsv" in views and any("vsv" in light_types.get(l.type).views(views, l.shape) for l in lights)
    if "view" in m and not vsv_light and all(l.type not in ("point", "scene") and l.shape != "sphere" for l in lights):
        # a scene's own lights are known only once it is loaded; explicit ones are known now
        raise ConfigError(source, "map.view", "views are for point lights and no [[light]] is a point light "
                          f"(the lights are {', '.join(sorted({l.type for l in lights}))}); remove map.view or "
                          "add a point light" + (" (vsv: or a spot light)" if "vsv" in views else ""))


def _parse_schemes(raw: dict, mapspec: MapSpec, source: str) -> list:
    """Every ``[[scheme]]`` table, swept and presets expanded, as SchemeSpecs (none without a depth map)."""
    from ..schemes import ALL as REGISTRY, PRESETS, view_mismatch
    scheme_tables = _array_of_tables(raw, "scheme", source)
    if "depth" not in mapspec.kind and scheme_tables:
        raise ConfigError(source, "scheme", "[[scheme]] tables are the depth map's and map.kind does not name depth; "
                          "add depth to map.kind or remove them", MAP_KINDS)
    if not scheme_tables and "depth" in mapspec.kind:
        raise ConfigError(source, "scheme", "at least one [[scheme]] is required", [s.NAME for s in REGISTRY])
    schemes, where = [], {}
    for i, t in enumerate(scheme_tables):
        for spec in parse_scheme(t, source, f"scheme[{i}]", REGISTRY, PRESETS):
            if spec in where:           # the same instance twice would run (and report) the same cases twice
                again = "given twice in its sweep" if where[spec] == f"scheme[{i}]" else f"already {where[spec]}'s"
                raise ConfigError(source, f"scheme[{i}]", f"{spec.name} {spec.label} is {again}: give each "
                                  "instance once")
            where[spec] = f"scheme[{i}]"
            schemes.append(spec)
    if view_mismatch(schemes, mapspec.view):
        raise ConfigError(source, "map.view", view_mismatch(schemes, mapspec.view), MAP_VIEWS)
    return schemes


def _parse_run_tables(raw: dict, source: str) -> tuple:
    """``[memory]``, ``[timing]``, ``[oracle]`` and ``[report]``: (budget MB or None, (repeats, lookups, builds),
    lambdas, images)."""
    mem = _table(raw, "memory", source)
    check_keys(mem, ("budget_mb",), source, "memory")
    budget = (number(mem["budget_mb"], source, "memory.budget_mb", positive=True)
              if "budget_mb" in mem else None)
    tim = _table(raw, "timing", source)
    check_keys(tim, ("repeats", "lookups", "builds"), source, "timing")
    repeats = number(tim.get("repeats", 3), source, "timing.repeats", integer=True, minimum=1, maximum=100)
    lookups = choice(tim.get("lookups", "wavefront"), source, "timing.lookups", LOOKUP_MODES)
    builds = choice(tim.get("builds", "alone"), source, "timing.builds", BUILD_MODES)
    orc = _table(raw, "oracle", source)
    check_keys(orc, ("lambda",), source, "oracle")
    lambdas = as_list(orc.get("lambda", 1.0))
    if not lambdas:
        raise ConfigError(source, "oracle.lambda", "empty list")
    lambdas = tuple(dict.fromkeys(number(x, source, "oracle.lambda", minimum=0, maximum=LAMBDA_MAX) for x in lambdas))
    rep = _table(raw, "report", source)
    check_keys(rep, ("images",), source, "report")
    report_images = choice(rep.get("images", "all"), source, "report.images", REPORT_IMAGES)
    return budget, (repeats, lookups, builds), lambdas, report_images

CONTACT_MAX_STEPS = 256


def _parse_contact(raw: dict, source: str, motion: bool):
    """``[contact]`` (length, steps, thickness, jitter; one value each) as a ContactSpec, None without it."""
    if "contact" not in raw:
        return None
    t = _table(raw, "contact", source)
    if "preset" in t:
        from ..contact.presets import PRESETS as CONTACT_PRESETS
        name = choice(t["preset"], source, "contact.preset", sorted(CONTACT_PRESETS))
        extra = sorted(set(t) - {"preset"})
        if extra:
            raise ConfigError(source, f"contact.{extra[0]}", "a preset takes no other keys", ("preset",))
        t = dict(vars(CONTACT_PRESETS[name][0]))
    for k, v in t.items():
        if isinstance(v, list):
            raise ConfigError(source, f"contact.{k}", f"give one value (contact parameters are not swept), got {v!r}")
    if "length_depth_min" in t and "length_depth_scale" not in t:     # read only where the length grows with depth
        raise ConfigError(source, "contact.length_depth_min", "is read only with length_depth_scale > 0 (the length "
                          "grows with depth): give length_depth_scale, or remove length_depth_min",
                          ("length_depth_scale",))
    spec = sweep_params(ContactSpec, t, source, "contact")[0]
    if spec.steps > CONTACT_MAX_STEPS:
        raise ConfigError(source, "contact.steps", f"must be <= {CONTACT_MAX_STEPS}, got {spec.steps}")
    if spec.jitter > 1.0:
        raise ConfigError(source, "contact.jitter", f"must be <= 1 (a fraction of a step), got {spec.jitter:g}")
    if spec.length.value <= 0:
        raise ConfigError(source, "contact.length", f"must be > 0, got {spec.length}")
    if motion:
        raise ConfigError(source, "contact", "contact shadows are measured on still frames; remove [contact] or "
                          "the [[motion]] paths", ["motion"])
    return spec


def parse_hybrid(raw: dict, source: str, motion: bool, lights, mapspec) -> tuple:
    """``[hybrid]`` (one table or an array ``[[hybrid]]``): each a rule, its parameters and origin
    rules (lists sweep) as HybridSpecs, checked before any work; () without it."""
    if "hybrid" not in raw:
        return ()
    from ..hybrid import get as rule_of, names as rule_names
    tables = _array_of_tables(raw, "hybrid", source)
    if not tables:
        raise ConfigError(source, "hybrid", "empty: give at least one rule", rule_names())
    _check_hybrid_context(source, motion, lights, mapspec)
    out, seen = [], {}
    for i, t in enumerate(tables):
        where = f"hybrid[{i}]" if isinstance(raw["hybrid"], list) else "hybrid"
        if "rule" not in t:
            raise ConfigError(source, f"{where}.rule", "required: the rule that sends receivers to rays",
                              rule_names())
        rule = rule_of(choice(t["rule"], source, f"{where}.rule", rule_names()))
        fields = tuple(f.name for f in dataclasses.fields(rule.Params))
        check_keys(t, ("rule", "origin") + fields, source, where)
        origins = [choice(o, source, f"{where}.origin", HYBRID_ORIGINS) for o in as_list(t.get("origin", "spawn"))]
        if not origins:
            raise ConfigError(source, f"{where}.origin", "empty list", HYBRID_ORIGINS)
        once(origins, source, f"{where}.origin")
        params = sweep_params(rule.Params, t, source, where, skip=("rule", "origin"))
        for p in params:
            _check_upper(p, source, where)
        for spec in (HybridSpec(rule.NAME, p, o) for p in params for o in origins):
            if spec in seen:            # as a [[scheme]] instance: the same cases twice, or one silently dropped
                what = " ".join(x for x in (spec.rule, spec.label, f"from {spec.origin}") if x)
                raise ConfigError(source, where, f"{what} is already {seen[spec]}'s: give each instance once")
            seen[spec] = where
            out.append(spec)
    return tuple(out)


def _check_hybrid_context(source: str, motion: bool, lights, mapspec):
    """ConfigError where ``[hybrid]`` cannot run: motion paths, area lights, no depth map."""
    if motion:
        raise ConfigError(source, "hybrid", "hybrid rays are measured on still frames; remove [hybrid] or "
                          "the [[motion]] paths", ["motion"])
    from .. import lights as light_types
    if any(light_types.is_soft(l) for l in lights):
        raise ConfigError(source, "hybrid", "hybrid rays decide a hard light's visibility; an area light's V* is "
                          "a fraction: remove [hybrid] or the area lights", ["directional", "spot", "point"])
    if "depth" not in mapspec.kind:
        raise ConfigError(source, "hybrid", "hybrid rays replace a depth map's answers and map.kind does not name "
                          "depth", MAP_KINDS)


def _check_upper(params, source: str, where: str):
    """ConfigError where a float parameter passes its field's ``metadata["max"]``."""
    for f in dataclasses.fields(params):
        hi, val = f.metadata.get("max"), getattr(params, f.name)
        if hi is not None and isinstance(val, float) and val > hi:
            raise ConfigError(source, f"{where}.{f.name}", f"must be <= {hi:g}, got {val:g}")


def _parse_shrink(m: dict, source: str, motion: bool):
    """``[map] shrink``: the world distance casters move inward along their welded normals (None: off)."""
    if "shrink" not in m:
        return None
    d = number(m["shrink"], source, "map.shrink", minimum=0.0)
    if motion:
        raise ConfigError(source, "map.shrink", "caster shrinking is measured on still frames; remove map.shrink or "
                          "the [[motion]] paths", ["motion"])
    return d


def _parse_execution(t: dict, source: str) -> ExecutionSpec:
    """``[execution]``: backend (local | ray), address, cpus_per_task, gpus_per_task."""
    check_keys(t, ("backend", "address", "cpus_per_task", "gpus_per_task"), source, "execution")
    backend = choice(t.get("backend", "local"), source, "execution.backend", BACKENDS)
    address = t.get("address")
    if address is not None and (not isinstance(address, str) or not address):
        raise ConfigError(source, "execution.address", f"expected a Ray address (auto, ray://host:port) or "
                          f"\"local\", got {address!r}")
    if address is not None and backend != "ray":
        raise ConfigError(source, "execution.address", 'an address is for backend = "ray"', BACKENDS)
    cpus = number(t.get("cpus_per_task", 1.0), source, "execution.cpus_per_task", positive=True)
    gpus = number(t.get("gpus_per_task", 0.0), source, "execution.gpus_per_task", minimum=0)
    return ExecutionSpec(backend, address, float(cpus), float(gpus))


def _parse_camera(cam: dict, source: str):
    """[camera] position, target, up, fov, near, far (each optional; None without any)."""
    kw = {}
    for k in ("position", "target", "up"):
        if k in cam:
            kw[k] = vec3(cam[k], source, f"camera.{k}", nonzero=k == "up")
    if "fov" in cam:
        kw["fov"] = number(cam["fov"], source, "camera.fov", positive=True, maximum=179.0)
    for k in ("near", "far"):
        if k in cam:
            kw[k] = number(cam[k], source, f"camera.{k}", positive=True)
    if "near" in kw and "far" in kw and not kw["near"] < kw["far"]:
        raise ConfigError(source, "camera.far", f"must be above camera.near ({kw['near']:g}), got {kw['far']:g}")
    if "position" in kw and "target" in kw and kw["position"] == kw["target"]:
        raise ConfigError(source, "camera.target", "the target equals the position")
    spec = CameraSpec(**kw)
    return spec if spec.posed else None


def _parse_cascades(m: dict, source: str) -> tuple:
    """[map] cascades (a count 1 to 8 or an engine's layout, lists sweep) and the keys of a counted
    layout (split, lambda, fit, depth_bounds, stabilize, blend, max_distance; lists sweep)."""
    from ..maps.cascade_layouts import LAYOUTS
    given = [k for k in CASCADE_KEYS if k in m]
    if not given:
        return ()
    if "cascades" not in m:
        raise ConfigError(source, f"map.{given[0]}", "a cascade key needs map.cascades (a count or an engine layout)",
                          ["cascades"])
    counts = as_list(m["cascades"])
    if not counts:
        raise ConfigError(source, "map.cascades", "empty list")
    opts = {}
    for key, conv in (("split", lambda v, k: choice(v, source, k, CASCADE_SPLITS)),
                      ("lambda", lambda v, k: number(v, source, k, minimum=0.0, maximum=1.0)),
                      ("fit", lambda v, k: choice(v, source, k, CASCADE_FITS)),
                      ("depth_bounds", lambda v, k: choice(v, source, k, DEPTH_BOUNDS)),
                      ("stabilize", _boolean(source)),
                      ("blend", lambda v, k: number(v, source, k, minimum=0.0, maximum=0.5)),
                      ("max_distance", lambda v, k: number(v, source, k, positive=True))):
        if key in m:
            vals = as_list(m[key])
            if not vals:
                raise ConfigError(source, f"map.{key}", "empty list")
            opts[key] = [conv(v, f"map.{key}") for v in vals]
    out = []
    numeric = False
    for c in counts:
        if isinstance(c, str):
            if c not in LAYOUTS:
                raise ConfigError(source, "map.cascades", f"unknown engine layout {c!r}; give a count 1 to "
                                  f"{MAX_CASCADES} or an engine", sorted(LAYOUTS), got=c)
            out.append(LAYOUTS[c][0])
            continue
        n = number(c, source, "map.cascades", integer=True, minimum=1, maximum=MAX_CASCADES)
        numeric = True
        names = list(opts)
        for combo in itertools.product(*(opts[k] for k in names)):
            kw = dict(zip(names, combo))
            if "lambda" in kw:
                kw["lam"] = kw.pop("lambda")
            spec = CascadeSpec(count=n, **kw)
            if spec.split != "practical" and "lambda" in opts and len(opts["lambda"]) > 1:
                spec = replace(spec, lam=CascadeSpec.lam)     # lambda sweeps only the practical split
            if spec not in out:
                out.append(spec)
    if not numeric and opts:
        raise ConfigError(source, f"map.{next(iter(opts))}", "an engine layout sets its own cascade keys; give a "
                          "count in map.cascades to set them", ["cascades"])
    return tuple(out)


def _parse_kinds(m: dict, formats, lights, cascade, source: str) -> tuple:
    """``[map] kind`` (MAP_KINDS, default depth), checked against what a pre-filtered map cannot do."""
    from .. import lights as light_types
    from .. import prefilter
    from ..prefilter import MOMENT_FORMATS
    kinds = tuple(dict.fromkeys(choice(k, source, "map.kind", MAP_KINDS) for k in as_list(m.get("kind", "depth"))))
    if not kinds:
        raise ConfigError(source, "map.kind", "empty list", MAP_KINDS)
    if kinds == ("depth",):
        return kinds
    if "filter" in m and "depth" not in kinds:
        raise ConfigError(source, "map.filter", "filters are the depth map's (a pre-filtered map's filter is "
                          "map.blur); add depth to map.kind or remove map.filter", ("depth",))
    bad = [f for f in formats if f not in MOMENT_FORMATS]
    if bad:
        raise ConfigError(source, "map.format", f"{bad[0]!r}: pre-filtered maps store their moments in", MOMENT_FORMATS)
    for name in (k for k in kinds if k != "depth"):
        valid = prefilter.formats_of(prefilter.get(name))
        bad = [f for f in formats if f not in valid]
        if bad:
            raise ConfigError(source, "map.format", f"{bad[0]!r} is not a storage format of {name}'s moments", valid,
                              got=bad[0])
    if cascade:
        raise ConfigError(source, "map.cascades", "pre-filtered maps are built on one map per view; remove "
                          "map.cascades or keep map.kind = depth", ("depth",))
    if any(l.type in light_types.REGISTRY and light_types.is_soft(l) for l in lights):
        raise ConfigError(source, "map.kind", "pre-filtered maps are measured against one exact ray per receiver; "
                          "an area light's reference is a fraction: remove it or keep map.kind = depth", ("depth",))
    return kinds


KIND_KEY_ROLES = {"blur": "blurs moments", "blur_kernel": "blurs moments", "moment_samples": "supersamples moments",
                  "mipmaps": "mipmaps moments"}


def _parse_moments(m: dict, kinds, formats, source: str) -> tuple:
    """The MomentSpec instances of ``[map.<kind>]`` tables (lists sweep) times ``[map] blur`` widths."""
    from .. import prefilter
    for name in prefilter.NAMES:
        if name in m and name not in kinds:
            raise ConfigError(source, f"map.{name}", f"parameters of {name}, which map.kind does not name", kinds)
    blurs = tuple(number(w, source, "map.blur", integer=True, minimum=1, maximum=63) for w in as_list(m.get("blur", 1)))
    if not blurs:
        raise ConfigError(source, "map.blur", "empty list")
    if any(w % 2 == 0 for w in blurs):
        raise ConfigError(source, "map.blur", f"a box width is odd (centred on the texel), got {blurs}")
    once(blurs, source, "map.blur")
    for key in ("blur", "blur_kernel", "moment_samples", "mipmaps"):
        if key in m and kinds == ("depth",):
            raise ConfigError(source, f"map.{key}", f"{KIND_KEY_ROLES[key]}; map.kind names no pre-filtered map",
                              prefilter.NAMES)
    kernels = tuple(choice(k, source, "map.blur_kernel", BLUR_KERNELS) for k in as_list(m.get("blur_kernel", "box")))
    if not kernels:
        raise ConfigError(source, "map.blur_kernel", "empty list", BLUR_KERNELS)
    samples = tuple(number(n, source, "map.moment_samples", integer=True, minimum=1, maximum=8)
                    for n in as_list(m.get("moment_samples", 1)))
    if not samples:
        raise ConfigError(source, "map.moment_samples", "empty list")
    mips = tuple(as_list(m.get("mipmaps", False)))
    if not mips or not all(isinstance(x, bool) for x in mips):
        raise ConfigError(source, "map.mipmaps", f"expected true, false or a list of them, got {m.get('mipmaps')!r}",
                          ("true", "false"))
    for key, vals in (("map.blur_kernel", kernels), ("map.moment_samples", samples), ("map.mipmaps", mips)):
        once(vals, source, key)
    out = []
    for name in kinds:
        if name == "depth":
            continue
        t = m.get(name, {})
        if not isinstance(t, dict):
            raise ConfigError(source, f"map.{name}", f"expected a table [map.{name}]")
        if "preset" in t and not prefilter.presets.names(name):
            raise ConfigError(source, f"map.{name}.preset", f"{name} has no engine presets (dsm schemes lists them)",
                              sorted(k for k in prefilter.presets.PRESETS))
        if "preset" in t:
            presets = _kind_presets(name, t, source)
        else:
            presets = [(None, p) for p in sweep_params(prefilter.get(name).Params, t, source, f"map.{name}")]
        for _, p in presets:
            prefilter.check(name, p, formats, source, f"map.{name}")
            _check_read(t, p, source, f"map.{name}")
        out += [MomentSpec(name, p, w, preset, k, n, mp) for preset, p in presets for w in blurs for k in kernels
                for n in samples for mp in mips]
    return tuple(out)


def _check_read(table: dict, params, source: str, where: str):
    """ConfigError for a key ``table`` gives that ``params`` does not read (its field's ``read_when``:
    (another field, the value under which it is read))."""
    import dataclasses
    for f in dataclasses.fields(params):
        when = f.metadata.get("read_when")
        if when is not None and f.name in table and getattr(params, when[0]) != when[1]:
            raise ConfigError(source, f"{where}.{f.name}", f"is read only with {when[0]} = {when[1]!r} (this "
                              f"instance has {when[0]} = {getattr(params, when[0])!r}): remove it or set {when[0]}",
                              (when[0],))


def _kind_presets(name: str, t: dict, source: str) -> list:
    """[(preset name or None, Params)] of ``[map.<kind>] preset`` (a name or a list of them, which sweeps;
    ``"default"``: the kind's documented defaults, as a table without keys)."""
    from .. import prefilter
    if set(t) != {"preset"}:
        raise ConfigError(source, f"map.{name}.{sorted(set(t) - {'preset'})[0]}", "a preset takes no other keys",
                          ("preset",))
    names = as_list(t["preset"])
    if not names:
        raise ConfigError(source, f"map.{name}.preset", "empty list", ("default",) + prefilter.presets.names(name))
    once(names, source, f"map.{name}.preset")
    out = []
    for n in names:
        n = choice(n, source, f"map.{name}.preset", ("default",) + prefilter.presets.names(name))
        out.append((None, prefilter.get(name).Params()) if n == "default" else (n, prefilter.presets.PRESETS[name][n]))
    return out


def _parse_motion(t: dict, source: str, where: str) -> MotionSpec:
    """One [[motion]] path: frames, a camera path and/or a light path, fixed points."""
    check_keys(t, ("frames", "camera", "offset", "angle", "keys", "light", "light_axis", "light_angle",
                   "light_offset", "light_keys", "points", "label", "casters", "cache"), source, where)
    kw = {"frames": number(t.get("frames", 8), source, f"{where}.frames", integer=True, minimum=2, maximum=1000),
          "camera": choice(t.get("camera", "none"), source, f"{where}.camera", CAMERA_PATHS),
          "light": choice(t.get("light", "none"), source, f"{where}.light", LIGHT_PATHS),
          "points": number(t.get("points", 4000), source, f"{where}.points", integer=True, minimum=1,
                           maximum=10_000_000)}
    need = {"dolly": "offset", "pan": "angle", "orbit": "angle", "keyframes": "keys"}.get(kw["camera"])
    if need and need not in t:
        raise ConfigError(source, f"{where}.{need}", f"camera path {kw['camera']!r} needs {need}")
    if "offset" in t:
        kw["offset"] = vec3(t["offset"], source, f"{where}.offset")
    if "angle" in t:
        kw["angle"] = number(t["angle"], source, f"{where}.angle")
    if "keys" in t:
        keys = t["keys"]
        if not isinstance(keys, list) or len(keys) < 2 or not all(isinstance(k, dict) for k in keys):
            raise ConfigError(source, f"{where}.keys", "expected a list of at least two tables {position, target}")
        out = []
        for j, k in enumerate(keys):
            check_keys(k, ("position", "target"), source, f"{where}.keys[{j}]")
            if "position" not in k or "target" not in k:
                raise ConfigError(source, f"{where}.keys[{j}]", "a keyframe needs position and target")
            out.append((vec3(k["position"], source, f"{where}.keys[{j}].position"),
                        vec3(k["target"], source, f"{where}.keys[{j}].target")))
            if out[-1][0] == out[-1][1]:
                raise ConfigError(source, f"{where}.keys[{j}].target", "the target equals the position")
        kw["keys"] = tuple(out)
    if kw["light"] == "turn" and "light_angle" not in t:
        raise ConfigError(source, f"{where}.light_angle", "light path 'turn' needs light_angle (degrees)")
    if "light_axis" in t:
        kw["light_axis"] = vec3(t["light_axis"], source, f"{where}.light_axis", nonzero=True)
    if "light_angle" in t:
        kw["light_angle"] = number(t["light_angle"], source, f"{where}.light_angle")
    kw.update(_parse_light_move(t, kw["light"], source, where))
    kw["cache"] = _cache_policy(t.get("cache", "none"), source, f"{where}.cache")
    kw["casters"] = _parse_casters(t.get("casters", []), source, where)
    label = t.get("label", "")
    if not isinstance(label, str):
        raise ConfigError(source, f"{where}.label", f"expected a string, got {label!r}")
    spec = MotionSpec(**kw)
    if not label:
        parts = [] if spec.camera == "none" else [f"camera {spec.camera}"]
        parts += {"none": [], "turn": [f"sun turn {spec.light_angle:g}deg"]}.get(spec.light, [f"light {spec.light}"])
        label = " + ".join(parts) or "static"
    return replace(spec, label=label)


def _cache_policy(raw, source: str, key: str) -> str:
    """A [[motion]] cache value: ``none``, ``static`` or ``stagger:N`` (a map cast every N frames, 1 <= N <= 1000)."""
    if isinstance(raw, str) and raw.startswith("stagger:"):
        n = raw.split(":", 1)[1]
        if not n.isdigit() or not 1 <= int(n) <= 1000:
            raise ConfigError(source, key, f"{raw!r}: stagger:N takes a period N in frames, an integer from 1 to 1000",
                              CACHE_POLICIES)
        return f"stagger:{int(n)}"
    if raw not in CACHE_POLICIES or raw == "stagger:N":
        raise ConfigError(source, key, f"unknown value {raw!r}", CACHE_POLICIES, got=raw)
    return raw


def _parse_casters(raw, source: str, where: str) -> tuple:
    """[[motion.casters]]: each a shape's name, its translation, linear (``offset``) or keyframed (``keys``),
    and/or its turn (``angle`` degrees about ``axis`` through its centre)."""
    if isinstance(raw, dict):
        raw = [raw]
    if not isinstance(raw, list) or not all(isinstance(c, dict) for c in raw):
        raise ConfigError(source, f"{where}.casters", "expected a list of tables {shape, offset | keys, angle, axis}")
    out = []
    for j, c in enumerate(raw):
        at = f"{where}.casters[{j}]"
        check_keys(c, ("shape", "offset", "keys", "angle", "axis", "static"), source, at)
        if not isinstance(c.get("static", False), bool):
            raise ConfigError(source, f"{at}.static", f"expected true or false, got {c['static']!r}")
        if not isinstance(c.get("shape"), str) or not c["shape"]:
            raise ConfigError(source, f"{at}.shape", "a moving caster needs the shape's name (a string)")
        if ("offset" in c and "keys" in c) or not {"offset", "keys", "angle"} & set(c):
            raise ConfigError(source, at, "give offset (a linear path) or keys (keyframes), one of them, and/or "
                              "angle (a turn)", ("offset", "keys", "angle"))
        keys = c.get("keys", [])
        if "keys" in c and (not isinstance(keys, list) or len(keys) < 2):
            raise ConfigError(source, f"{at}.keys", "expected a list of at least two translations [x, y, z]")
        out.append(CasterPath(c["shape"], vec3(c.get("offset", [0, 0, 0]), source, f"{at}.offset"),
                              tuple(vec3(k, source, f"{at}.keys[{i}]") for i, k in enumerate(keys)),
                              number(c.get("angle", 0.0), source, f"{at}.angle"),
                              vec3(c.get("axis", [0, 0, 1]), source, f"{at}.axis", nonzero=True),
                              c.get("static", False)))
    if len({c.shape for c in out}) < len(out):
        raise ConfigError(source, f"{where}.casters", "a shape moves along one path; it is named twice")
    return tuple(out)


def _parse_light_move(t: dict, path: str, source: str, where: str) -> dict:
    """A spot or point light moving: ``light_offset`` (move) or ``light_keys`` (keyframes)."""
    kw = {}
    need = {"move": "light_offset", "keyframes": "light_keys"}.get(path)
    if need and need not in t:
        raise ConfigError(source, f"{where}.{need}", f"light path {path!r} needs {need}")
    if "light_offset" in t:
        kw["light_offset"] = vec3(t["light_offset"], source, f"{where}.light_offset")
    if "light_keys" in t:
        keys = t["light_keys"]
        if not isinstance(keys, list) or len(keys) < 2 or not all(isinstance(k, dict) for k in keys):
            raise ConfigError(source, f"{where}.light_keys", "expected a list of at least two tables "
                              "{position, target (optional, a spot's aim)}")
        out = []
        for j, k in enumerate(keys):
            check_keys(k, ("position", "target"), source, f"{where}.light_keys[{j}]")
            if "position" not in k:
                raise ConfigError(source, f"{where}.light_keys[{j}]", "a light keyframe needs position", ["position"])
            out.append((vec3(k["position"], source, f"{where}.light_keys[{j}].position"),
                        vec3(k["target"], source, f"{where}.light_keys[{j}].target") if "target" in k else None))
            if out[-1][0] == out[-1][1]:
                raise ConfigError(source, f"{where}.light_keys[{j}].target", "the target equals the position")
        if len({tg is None for _, tg in out}) > 1:
            raise ConfigError(source, f"{where}.light_keys", "give target on every light keyframe or on none")
        kw["light_keys"] = tuple(out)
    return kw


def _boolean(source):
    def conv(v, key):
        """``v`` checked to be a boolean; else a ConfigError at ``key``."""
        if not isinstance(v, bool):
            raise ConfigError(source, key, f"expected true or false, got {v!r}")
        return v
    return conv


def _table(raw, key, source) -> dict:
    t = raw.get(key, {})
    if not isinstance(t, dict):
        raise ConfigError(source, key, f"expected a table [{key}]")
    return t


def _array_of_tables(raw, key, source) -> list:
    t = raw.get(key, [])
    if isinstance(t, dict):
        t = [t]
    if not isinstance(t, list) or not all(isinstance(x, dict) for x in t):
        raise ConfigError(source, key, f"expected an array of tables [[{key}]]")
    return t


def _filter(raw, source) -> str:
    """A map.filter value: one of FILTERS, ``"pcf_wide:K"`` (a K x K texel kernel, 2 <= K <= 64) or
    ``"smrt:<preset>"`` / ``"smrt:RxS[:rule]"`` (shadow-map ray tracing, dsm.maps.smrt)."""
    from ..maps import smrt_presets as smrt
    if isinstance(raw, str) and smrt.is_smrt(raw):
        try:
            smrt.settings(raw)
        except ValueError as err:
            raise ConfigError(source, "map.filter", str(err)) from None
        return raw
    if isinstance(raw, str) and raw.startswith("pcf_wide:"):
        k = raw.split(":", 1)[1]
        if not k.isdigit() or not 2 <= int(k) <= 64:
            raise ConfigError(source, "map.filter", f"{raw!r}: pcf_wide:K takes a kernel width K in texels, "
                              "an integer from 2 to 64")
        return raw
    return choice(raw, source, "map.filter", FILTERS)


def _parse_light(t: dict, source: str, where: str) -> LightSpec:
    """One [[light]] table, parsed by its type's module (dsm.lights)."""
    from .. import lights
    kind = choice(t.get("type"), source, f"{where}.type", lights.TYPES) if "type" in t else None
    if kind is None:
        raise ConfigError(source, f"{where}.type", "missing", lights.TYPES)
    return lights.get(kind).parse(t, source, where)


def _check_motion_casters(motion, scenes, source):
    """Each moving caster names a shape of every built-in scene (a mesh file's names are checked once loaded)."""
    from ..scenes.builtins import builtin_geometry
    for sc in scenes:
        if not sc.builtin or not any(mo.casters for mo in motion):
            continue
        names = list(builtin_geometry(sc.builtin, sc.params)[0])
        for i, mo in enumerate(motion):
            for j, c in enumerate(mo.casters):
                if c.shape not in names:
                    raise ConfigError(source, f"motion[{i}].casters[{j}].shape",
                                      f"no shape named {c.shape!r} in {sc.builtin}", names)


def _check_motion_moments(motion, mapspec, source):
    """[[motion]] re-builds a pre-filtered map's moments per frame from the frame's first layer: a
    supersampled or mipmapped instance (which casts or reads what a frame's map does not hold) is refused."""
    for key, what in (("moment_samples", lambda s: s.samples > 1), ("mipmaps", lambda s: s.mipmaps)):
        if motion and any(what(s) for s in mapspec.moments):
            raise ConfigError(source, f"map.{key}", f"[[motion]] measures pre-filtered maps built from each frame's "
                              f"first layer; remove [[motion]] or {key}", ("moment_samples = 1", "mipmaps = false"))


def _check_motion_lights(motion, lights_of_config, source):
    """Each [[motion]] light path needs a light whose type follows it (or the scene's own)."""
    from .. import lights
    soft = [j for j, l in enumerate(lights_of_config) if l.type in lights.REGISTRY and lights.is_soft(l)]
    if motion and soft:       # the fixed points' V* is one ray; an area light's reference is a fraction per frame
        raise ConfigError(source, f"light[{soft[0]}].type", "[[motion]] measures hard lights: its fixed points' V* "
                          "is one ray, where an area light's is a Monte Carlo fraction; remove the area light or "
                          "the [[motion]] paths", tuple(t for t, m in lights.REGISTRY.items() if not m.SOFT))
    for i, mo in enumerate(motion):
        if mo.light == "none":
            continue
        follow = [name for name, m in lights.REGISTRY.items() if mo.light in m.MOTION]
        if all(l.type != "scene" and mo.light not in lights.get(l.type).MOTION for l in lights_of_config):
            raise ConfigError(source, f"motion[{i}].light", f"light path {mo.light!r} needs a "
                              f"{' or '.join(follow)} [[light]]; the config has none", follow)


def parse_scheme(t: dict, source: str, where: str, registry, presets) -> list:
    """The SchemeSpecs of one ``[[scheme]]`` table: a preset's one, or a named scheme's over its swept lists."""
    names = [s.NAME for s in registry]
    if "preset" in t:
        preset = choice(t["preset"], source, f"{where}.preset", sorted(presets))
        extra = set(t) - {"preset"}
        if extra:
            raise ConfigError(source, f"{where}.{sorted(extra)[0]}", "a preset takes no other keys", ("preset",))
        # a preset is a combined instance per light type: the plan resolves it per light
        # (schemes.preset_for_light); until then it carries the directional values
        from ..schemes.presets import spec as preset_spec
        return [preset_spec(preset)]
    if "name" not in t:
        raise ConfigError(source, f"{where}.name", "missing", names)
    name = choice(t["name"], source, f"{where}.name", names)
    module = next(s for s in registry if s.NAME == name)
    return [SchemeSpec(name, p) for p in sweep_params(module.Params, t, source, where, skip=("name",))]
