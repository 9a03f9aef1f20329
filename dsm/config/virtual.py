"""``[map.virtual]``: a directional light's virtual shadow map (dsm.maps.virtual) read into VirtualSpecs.

``preset`` (``"ue5"``, ``"eevee"``; a list sweeps) gives the engine's values; any other key of
the table overrides that value in every preset.
"""
from __future__ import annotations

from dataclasses import replace

from ..core.types import VIRTUAL_PRESETS, VIRTUAL_RULES, ConfigError, as_list, check_keys, choice, number

VIRTUAL_KEYS = ("preset", "page_size", "resolution", "first_level", "last_level", "levels", "lod_bias", "rule",
                "unit_cm", "border", "max_pages")
MAX_LEVELS = 64                 # levels a view holds (faces)
MAX_PAGES_SIDE = 1024           # pages along a level's side (the page table holds levels x this^2)


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
            "max_pages": lambda v: number(v, source, key("max_pages"), integer=True, minimum=1)}
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
    if all(light.type not in ("directional", "scene") for light in lights):
        raise ConfigError(source, "map.virtual", "a virtual shadow map is a directional light's and no [[light]] is "
                          f"directional (the lights are {', '.join(sorted({l.type for l in lights}))}); remove "
                          "[map.virtual] or add a directional light")
    return tuple(out)
