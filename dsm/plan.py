"""The plan: what a config asks to compute, before anything runs.

From the config alone (built-in scenes, XML emitters and film sizes are read as text; no
Mitsuba scene is loaded) it derives:

- the cases: scene x light x view x resolution x scheme instance x filter x format;
- the shared work: one G-buffer per scene, one reference per scene/light, one map per
  scene/light/view/resolution/culling choice, holding only the layers its schemes need
  (``slope`` for slope-scaled, ``z2`` for midpoint/dual, a layered search for culling), and a
  quantized copy only for a stored format other than float32;
- rays by kind: ``gbuffer`` (one per pixel) and ``map_texel`` (one per texel of every map)
  exactly; ``reference`` (one per receiver) and ``map_continue`` (the layered search's rays
  past the first hit) as upper bounds, since they depend on what the rays meet;
- the buffers, each map's working set per texel, the estimated peak memory and the tile
  (wavefront) size that keeps a build within the memory budget.

``dsm run`` follows the plan (the same grouping, the plan's tiles) and records the rays
actually cast; tests hold the two to each other.
"""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

from . import schemes as schemes_mod
from .config import Config
from .shadowmap import MAX_STEPS

VIEW_FACES = {"orthographic": 1, "perspective": 1, "paraboloid": 1, "dual_paraboloid": 2, "cube": 6}
# bytes per pixel / texel, measured with Dr.Jit's allocation watermark on llvm_ad_rgb (the
# first layer fuses into one kernel: nothing but its outputs is ever stored)
GBUFFER_BYTES = 150        # surface interaction, positions, normals, shape ids
REFERENCE_BYTES = 64       # per receiver: gathered interaction, result, occluder distance
BUILD_BYTES = {"first": 8, "slope": 12, "layered": 84, "layered_slope": 132}   # working set incl. outputs
STORED_BYTES = 4           # per texel and stored layer (z1, shape, slope, z2)
MIN_TILE = 1 << 16


@dataclass
class MapPlan:
    scene: str
    light: str
    view: str
    resolution: int
    faces: int
    culling: str
    needs: tuple                  # optional layers: slope, z2
    layered: bool                 # a search along the ray (second layer or culling)
    formats: tuple                # stored formats other than float32: one quantized copy each
    schemes: list
    cases: int
    tile: int = 0

    @property
    def texels(self) -> int:
        return self.faces * self.resolution ** 2

    @property
    def layers(self) -> tuple:
        return ("z1", "shape") + tuple(self.needs)

    @property
    def build_bytes_per_texel(self) -> int:
        """Working set of a build per texel of a tile, beyond the stored layers."""
        kind = ("layered" if self.layered else "first") + ("_slope" if self.layered and "slope" in self.needs else "")
        if kind == "first" and "slope" in self.needs:
            kind = "slope"
        return max(BUILD_BYTES[kind] - STORED_BYTES * len(self.layers), 0)

    @property
    def stored_bytes(self) -> int:
        """The stored layers and each quantized copy of z1 (and z2)."""
        return self.texels * STORED_BYTES * (len(self.layers) + len(self.formats) * (1 + ("z2" in self.needs)))

    @property
    def peak_bytes(self) -> int:
        return self.stored_bytes + min(self.tile or self.texels, self.texels) * self.build_bytes_per_texel


@dataclass
class Plan:
    config: str
    scenes: list = field(default_factory=list)      # (label, width, height, lights [(label, type)])
    maps: list = field(default_factory=list)
    budget_bytes: int = 0

    @property
    def cases(self) -> int:
        return sum(m.cases for m in self.maps)

    @property
    def rays(self) -> dict:
        """Exact counts by kind."""
        return {"gbuffer": sum(w * h for _, w, h, _ in self.scenes),
                "map_texel": sum(m.texels for m in self.maps)}

    @property
    def rays_bound(self) -> dict:
        """Upper bounds of the data-dependent kinds."""
        ref = sum(w * h * len(lights) for _, w, h, lights in self.scenes)
        cont = sum(m.texels * ((MAX_STEPS - 1) if m.layered and m.culling != "none" else 1)
                   for m in self.maps if m.layered)
        return {"reference": ref, "map_continue": cont}

    def peak_bytes(self) -> int:
        peak = 0
        for label, w, h, lights in self.scenes:
            base = w * h * (GBUFFER_BYTES + REFERENCE_BYTES)
            maps = [m for m in self.maps if m.scene == label]
            work = max((m.peak_bytes for m in maps), default=0)
            peak = max(peak, base + work)
        return peak

    def map_for(self, scene, light, view, resolution, culling):
        for m in self.maps:
            if (m.scene, m.light, m.view, m.resolution, m.culling) == (scene, light, view, resolution, culling):
                return m
        return None

    def tile_for(self, scene, light, view, resolution, culling) -> int:
        m = self.map_for(scene, light, view, resolution, culling)
        return m.tile if m else 0

    def text(self) -> str:
        mb = 1 / 2 ** 20
        lines = [f"plan for {self.config}", f"  cases: {self.cases}",
                 f"  scenes: {len(self.scenes)}, maps: {len(self.maps)}, memory budget {self.budget_bytes * mb:.0f} MB"]
        for label, w, h, lights in self.scenes:
            lines.append(f"  scene {label}: G-buffer {w}x{h} ({w * h * GBUFFER_BYTES * mb:.1f} MB), lights: "
                         + ", ".join(f"{lab} ({t})" for lab, t in lights))
        lines.append("  maps (one per scene/light/view/resolution/culling; layers only as the schemes need):")
        lines.append(f"    {'scene':18s} {'light':12s} {'view':16s} {'R':>5s} {'culling':12s} {'layers':22s} "
                     f"{'formats':14s} {'texels':>10s} {'tiles':>5s} {'MB':>8s}  schemes")
        for m in self.maps:
            tiles = -(-m.texels // m.tile) if m.tile else 1
            mem = m.peak_bytes * mb
            lines.append(f"    {m.scene[:18]:18s} {m.light[:12]:12s} {m.view:16s} {m.resolution:5d} {m.culling:12s} "
                         f"{'+'.join(m.layers) + (' (layered)' if m.layered else ''):22s} "
                         f"{','.join(m.formats) or '-':14s} {m.texels:10d} {tiles:5d} {mem:8.1f}  "
                         + ", ".join(m.schemes))
        lines.append("  rays (exact): " + ", ".join(f"{k} {v:,}" for k, v in self.rays.items()))
        lines.append("  rays (at most): " + ", ".join(f"{k} {v:,}" for k, v in self.rays_bound.items()))
        lines.append(f"  estimated peak memory: {self.peak_bytes() * mb:.1f} MB")
        return "\n".join(lines)

    def as_dict(self) -> dict:
        return {"cases": self.cases, "rays": self.rays, "rays_bound": self.rays_bound,
                "peak_bytes_est": self.peak_bytes(), "budget_bytes": self.budget_bytes,
                "maps": [{"scene": m.scene, "light": m.light, "view": m.view, "resolution": m.resolution,
                          "culling": m.culling, "layers": list(m.layers), "layered": m.layered,
                          "formats": list(m.formats), "texels": m.texels, "tile": m.tile, "cases": m.cases,
                          "peak_bytes_est": m.peak_bytes}
                         for m in self.maps]}


def views_for(light_type: str, point_views) -> tuple:
    """The view kinds a light gets: its own for directional and spot, the config's for points."""
    return {"directional": ("orthographic",), "spot": ("perspective",)}.get(light_type, tuple(point_views))


def memory_budget(cfg: Config) -> int:
    if cfg.memory_budget_mb:
        return int(cfg.memory_budget_mb * 2 ** 20)
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        total = 8 << 30
    return total // 4


def _xml_film(path, width) -> tuple:
    root = ET.parse(path).getroot()
    defaults = {el.get("name"): el.get("value") for el in root.iter("default")}
    w, h = 768, 576                      # Mitsuba's film defaults
    for el in root.iter("film"):
        for it in el.iter("integer"):
            val = it.get("value", "")
            val = defaults.get(val[1:], val) if val.startswith("$") else val
            if it.get("name") == "width":
                w = int(val)
            if it.get("name") == "height":
                h = int(val)
        break
    return width, max(1, round(width * h / w))


def _xml_emitters(path) -> list:
    """Emitter types in document order (includes followed)."""
    out = []
    root = ET.parse(path).getroot()
    for el in root.iter():
        if el.tag == "emitter":
            out.append(el.get("type"))
        if el.tag == "include" and el.get("filename"):
            inc = path.parent / el.get("filename")
            if inc.suffix == ".xml" and inc.is_file():
                out += _xml_emitters(inc)
    return out


def _xml_lights(path) -> list:
    types = _xml_emitters(path)
    usable = [t for t in types if t in ("point", "spot", "directional")]
    if usable:
        return usable
    return ["point" if "area" in types else "directional"]      # scenes.default_light


def scene_lights(spec, cfg: Config) -> list:
    """[(label, type)] of the lights a scene gets, as the runner labels them."""
    from .scenes import builtin_geometry
    own = []
    if spec.builtin:
        own = [builtin_geometry(spec.builtin, spec.params)[2].type]
    elif spec.file.suffix.lower() == ".xml":
        own = _xml_lights(spec.file)
    else:
        own = ["directional"]
    types = []
    for light in cfg.lights:
        types += own if light.type == "scene" else [light.type]
    return [(f"{i}:{t}", t) for i, t in enumerate(types)]


def make(cfg: Config) -> Plan:
    plan = Plan(cfg.source, budget_bytes=memory_budget(cfg))
    per_case = len(cfg.map.filter) * len(cfg.map.format)
    fmts = tuple(f for f in cfg.map.format if f != "float32")
    groups = {}
    for spec in cfg.schemes:
        groups.setdefault(schemes_mod.culling_of(spec.params), []).append(spec)
    W, H = cfg.camera_resolution
    for sc in cfg.scenes:
        if sc.missing:
            continue
        w, h = _xml_film(sc.file, W) if sc.file is not None and sc.file.suffix.lower() == ".xml" else (W, H)
        lights = scene_lights(sc, cfg)
        plan.scenes.append((sc.label, w, h, lights))
        for label, ltype in lights:
            for view in views_for(ltype, cfg.map.view):
                faces = VIEW_FACES[view]
                for R in cfg.map.resolutions_for(faces):
                    for culling, group in groups.items():
                        needs = schemes_mod.needs_of(group)
                        m = MapPlan(sc.label, label, view, R, faces, culling, tuple(sorted(needs)),
                                    "z2" in needs or culling != "none", fmts,
                                    [f"{s.name} {s.label}".strip() for s in group], len(group) * per_case)
                        plan.maps.append(m)
    base = max((w * h * (GBUFFER_BYTES + REFERENCE_BYTES) for _, w, h, _ in plan.scenes), default=0)
    for m in plan.maps:
        room = plan.budget_bytes - base - m.stored_bytes
        fit = max(room // max(m.build_bytes_per_texel, 1), MIN_TILE)
        m.tile = int(min(m.texels, fit))
    return plan
