"""``[map.virtual]``: a directional light's virtual shadow map (dsm.maps.virtual), or a spot light's
(``rule = "punctual"``: dsm.maps.virtual_punctual), read into VirtualSpecs.

``preset`` (``"ue5"``, ``"eevee"``, ``"eevee_punctual"``; a list sweeps) gives the engine's values; any
other key of the table overrides that value in every preset.
"""
from __future__ import annotations

from dataclasses import replace

from ..core.types import VIRTUAL_PRESETS, VIRTUAL_RULES, ConfigError, as_list, check_keys, choice, number

VIRTUAL_KEYS = ("preset", "page_size", "resolution", "first_level", "last_level", "levels", "lod_bias", "rule",
                "unit_cm", "border", "max_pages", "lod_min")
MAX_LEVELS = 64                 # levels a view holds (faces)
MAX_PAGES_SIDE = 1024           # pages along a level's side (the page table holds levels x this^2)
# float32's relative step (2^-23): a coarsest level narrower than this times the scene's scale spans less than one
# float32 step of a coordinate of one scene unit, so no receiver there can lie in it apart from its neighbours
FLOAT32_STEP = 2.0 ** -23


def _values(t: dict, source: str) -> dict:
    """The table's keys other than ``preset``, checked one by one."""
    key = lambda k: f"map.virtual.{k}"
    conv = {"page_size": lambda v: number(v, source, key("page_size"), integer=True, minimum=1, maximum=4096),
            "resolution": lambda v: number(v, source, key("resolution"), integer=True, minimum=1, maximum=2 ** 20),
            "first_level": lambda v: number(v, source, key("first_level"), integer=True, minimum=-60, maximum=60),
            "last_level": lambda v: number(v, source, key("last_level"), integer=True, minimum=-60, maximum=60),
            "lod_bias": lambda v: number(v, source, key("lod_bias"), minimum=-16.0, maximum=16.0),
            "rule": lambda v: choice(v, source, key("rule"), VIRTUAL_RULES),
            "unit_cm": lambda v: number(v, source, key("unit_cm"), positive=True),
            "border": lambda v: number(v, source, key("border"), minimum=0.0, maximum=0.5),
            "max_pages": lambda v: number(v, source, key("max_pages"), integer=True, minimum=1),
            "lod_min": lambda v: number(v, source, key("lod_min"))}
    return {k: conv[k](t[k]) for k in VIRTUAL_KEYS if k in t and k not in ("preset", "levels")}


def _levels(t: dict, spec, source: str):
    """``levels`` (a count from first_level) as last_level; given with last_level, a ConfigError."""
    if "levels" not in t:
        return spec
    if "last_level" in t:
        raise ConfigError(source, "map.virtual.levels", "give levels or last_level, not both",
                          ("levels", "last_level"))
    n = number(t["levels"], source, "map.virtual.levels", integer=True, minimum=1, maximum=MAX_LEVELS)
    return replace(spec, last_level=spec.first_level + n - 1)


def _check(spec, source: str):
    """ConfigError where a spec's values do not make a page grid or a level range."""
    if spec.resolution % spec.page_size:
        raise ConfigError(source, "map.virtual.resolution", f"{spec.resolution} is not a whole number of pages "
                          f"of page_size {spec.page_size}")
    if spec.resolution // spec.page_size > MAX_PAGES_SIDE:
        raise ConfigError(source, "map.virtual.page_size", f"{spec.resolution // spec.page_size} pages a side; "
                          f"at most {MAX_PAGES_SIDE} (raise page_size or lower resolution)")
    if spec.last_level < spec.first_level:
        raise ConfigError(source, "map.virtual.last_level", f"{spec.last_level} is below first_level "
                          f"{spec.first_level}")
    if spec.count > MAX_LEVELS:
        raise ConfigError(source, "map.virtual.last_level", f"{spec.count} levels; at most {MAX_LEVELS}")
    if spec.punctual:
        _check_punctual(spec, source)


def _check_punctual(spec, source: str):
    """ConfigError where a spot's levels do not halve into whole pages: level l holds resolution / 2^l texels."""
    if spec.first_level < 0:
        raise ConfigError(source, "map.virtual.first_level", f"{spec.first_level}: a punctual map's level l halves "
                          "the resolution l times, so levels start at 0 or above")
    if spec.last_level > 30 or (spec.resolution // spec.page_size) % (2 ** spec.last_level):
        raise ConfigError(source, "map.virtual.last_level", f"{spec.last_level}: level {spec.last_level} of a "
                          f"punctual map holds {spec.resolution} / 2^{spec.last_level} texels, not a whole number of "
                          f"pages of page_size {spec.page_size}; valid: 2^last_level divides resolution / page_size "
                          f"({spec.resolution // spec.page_size})")


def check_reach(specs: tuple, scales, source: str):
    """ConfigError, before any work, where a virtual map's coarsest level is narrower than float32's step at one
    scene unit of a scene's ``scale`` (:data:`FLOAT32_STEP`): no receiver can lie in any of its levels. It names the
    keys and their valid range. Levels wide enough that still hold no receiver (the receivers all farther from the
    camera than the coarsest level reaches, as ``levels = 1`` leaves) depend on where the camera's receivers lie:
    known only once the scene is loaded, that case fails alone (dsm.maps.virtual) and the others run."""
    for spec in specs:
        for scale in scales if not spec.punctual else ():      # a spot's levels are resolutions, not widths
            need = FLOAT32_STEP * scale                   # the narrowest coarsest level, scene units
            if spec.level_width(spec.last_level, scale) >= need:
                continue
            cm = spec.level_width(spec.last_level, 1.0) * spec.unit_cm      # its physical width
            lowest = next((lv for lv in range(spec.last_level, 61) if spec.level_width(lv, scale) >= need), None)
            levels = (f"last_level >= {lowest} (at most 60)" if lowest is not None
                      else "no last_level up to 60 reaches it")
            width = spec.level_width(spec.last_level, scale)
            raise ConfigError(source, "map.virtual", f"the coarsest level (last_level {spec.last_level}, "
                              f"{cm:.3g} cm) is {width:.3g} scene units wide at scale "
                              f"{scale:g}, under float32's step at one scene unit ({need:.3g}): no receiver can lie in "
                              f"its levels; valid: map.virtual.unit_cm <= {cm / need * scale:.3g}, or {levels} "
                              f"(map.virtual.first_level, last_level or levels)")


def parse_virtual(m: dict, lights, source: str) -> tuple:
    """The VirtualSpecs of ``[map.virtual]`` (empty without it), checked before any work."""
    if "virtual" not in m:
        return ()
    t = m["virtual"]
    if not isinstance(t, dict):
        raise ConfigError(source, "map.virtual", f"expected a table ([map.virtual] with preset = \"ue5\"), got {t!r}",
                          VIRTUAL_KEYS)
    check_keys(t, VIRTUAL_KEYS, source, "map.virtual")
    names = as_list(t.get("preset", "ue5"))
    if not names:
        raise ConfigError(source, "map.virtual.preset", "empty list", tuple(VIRTUAL_PRESETS))
    if len(set(names)) != len(names):
        raise ConfigError(source, "map.virtual.preset", f"a preset given twice in {names}")
    values = _values(t, source)
    out = []
    for name in names:
        spec = replace(VIRTUAL_PRESETS[choice(name, source, "map.virtual.preset", tuple(VIRTUAL_PRESETS))], **values)
        spec = _levels(t, spec, source)
        _check(spec, source)
        out.append(spec)
    _check_lights(out, lights, source)
    return tuple(out)


def _check_lights(specs, lights, source: str):
    """ConfigError where a preset has no light of its kind: a clipmap a directional light, punctual a spot
    or a point light."""
    for spec in specs:
        kinds = ("spot", "point") if spec.punctual else ("directional",)
        kind = " or ".join(kinds)
        if all(light.type not in kinds + ("scene",) for light in lights):
            raise ConfigError(source, "map.virtual", f"{spec.preset or spec.rule}: a virtual shadow map of rule "
                              f"{spec.rule} is a {kind} light's and no [[light]] is one (the lights are "
                              f"{', '.join(sorted({l.type for l in lights}))}); remove [map.virtual], choose another "
                              f"preset or add a {kind} light", tuple(VIRTUAL_PRESETS))
