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
  (wavefront) size that keeps a build within the memory budget; :func:`check_memory` refuses a
  config whose estimate exceeds this machine's memory before any work (instead of a crash).

``dsm run`` follows the plan (the same grouping, the plan's tiles) and records the rays
actually cast; tests hold the two to each other.
"""
from __future__ import annotations

import dataclasses
import os
import xml.etree.ElementTree as ET
from typing import NamedTuple
from dataclasses import dataclass, field

from ..core.labels import params_label
from ..truth import intervals
from ..scenes import size as scene_size
from .. import lights as light_types
from .. import prefilter
from .. import schemes as schemes_mod
from ..core.types import DEFAULT_CAMERA, POINT_VIEWS, VIEW_FACES, Config, ConfigError, MapSpec
from ..maps import costs as cost_rules
from ..maps.shadowmap import MAX_STEPS
from ..contact import presets as contact_presets

# bytes per pixel / texel, measured with Dr.Jit's allocation watermark on llvm_ad_rgb (the
# first layer fuses into one kernel: nothing but its outputs is ever stored)
GBUFFER_BYTES = 150        # surface interaction, positions, normals, shape ids (150.0 B/px measured, 256^2-2048^2)
REFERENCE_BYTES = 64       # per receiver: gathered interaction, result, occluder distance
# per camera pixel on the host: each case's class image and shadow render (numpy, matplotlib's
# RGBA conversion for the PNGs) and allocator slack; measured as a one-case run's peak RSS growth
# (244-275 B/px at 1024^2-4096^2) less the G-buffer and reference bytes above
HOST_BYTES = 60
PIXEL_BYTES = GBUFFER_BYTES + REFERENCE_BYTES + HOST_BYTES
BUILD_BYTES = {"first": 8, "slope": 12, "layered": 84, "layered_slope": 132}   # working set incl. outputs
STORED_BYTES = 4           # per texel and stored layer (z1, shape, slope, z2)
# a pre-filtered map's build per texel: numpy's float64 moments and blur (peak 104 B/texel for
# four moments at W = 9, tracemalloc, R = 1024) and the four float32 moments on the device
MOMENT_BYTES = 120
# a supersampled moment build per ray (its first-layer cast, z1, and the float64 moments before their
# per-texel mean): 28 B measured as the peak of R = 512 with 8 x 8 rays a texel (472 MB), rounded up
SUPERSAMPLE_BYTES = 32
MIN_TILE = 1 << 16
# a map's lookup wavefront (dsm.experiment.wavefront) holds every case's outputs at once: per
# receiver V (4 B), the nearest tap's shape (4 B) and the plane-miss mask (1 B), per back-facing
# receiver V (4 B); a wave holds at most WAVE_BYTES of them (more cases go into further waves),
# twice over while they are copied to numpy
WAVE_RECEIVER_BYTES = 9
WAVE_BACK_BYTES = 4
WAVE_BYTES = 128 << 20
# [timing] builds = "together": a sweep's small maps (one light and view kind, straight-line
# builds of the same layers) are built as one wavefront (dsm.maps.stacked) while their estimated
# peaks add up to at most STACK_BYTES; they stay in memory together until their cases have run
STACK_BYTES = 64 << 20
# per triangle of the scene: Mitsuba's mesh buffers, Embree's BVH, the loader's temporaries and
# the kit's per-triangle tables (spawn extents, closedness); measured as the peak RSS growth of
# `dsm run` on grid meshes of 1e4 to 1e7 triangles (381 to 410 B per triangle at 1e6 and 1e7),
# plus the 28 B of padding in each triangle's 16-float packet of the spawn tables (maps/spawn.py)
TRIANGLE_BYTES = 412
# the process itself (Python, Mitsuba, Dr.Jit's LLVM backend, numpy, matplotlib): the peak RSS
# (VmHWM) of `dsm run` on a 1e4-triangle mesh with a 64^2 camera and a 256^2 map, 129 MiB, less those
PROCESS_BYTES = 125 << 20


def wave_cases(receivers: int, back_receivers: int = 0) -> int:
    """How many cases of one map a lookup wavefront holds within ``WAVE_BYTES`` (at least one)."""
    per_case = receivers * WAVE_RECEIVER_BYTES + back_receivers * WAVE_BACK_BYTES
    return max(1, WAVE_BYTES // per_case) if per_case else 1 << 30


@dataclass
class MapPlan:
    """One map to build: scene, light, view, resolution, culling, its layers and formats, and the cases it serves."""
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
    specs: tuple = ()             # the scheme instances (SchemeSpec) read from this map, in config order
    scene_index: int = 0          # of the config's scenes
    light_index: int = 0          # of the scene's lights (the label's number)
    # a directional light's CascadeSpec or VirtualSpec, a spot's punctual VirtualSpec (faces = its count), else None
    cascade: object = None
    moments: tuple = ()           # pre-filtered instances (MomentSpec) built from this map's z1 (culling none)
    supersampled_rays: int = 0    # rays of the supersampled first layers its moment maps cast (one each)
    hybrid_cases: int = 0         # [hybrid]: its depth cases with a rule's rays (each at most one a receiver)

    @property
    def texels(self) -> int:
        """Texels of the map: faces * resolution^2; a virtual map's its physical page pool."""
        if getattr(self.cascade, "virtual", False):
            return self.cascade.physical_texels
        return self.faces * self.resolution ** 2

    @property
    def layers(self) -> tuple:
        """The stored layers: ``z1`` and ``shape``, then the optional ones the schemes need."""
        return ("z1", "shape") + tuple(self.needs)

    @property
    def read_bytes(self) -> tuple:
        """(fewest, most) bytes one of its cases' lookups reads (dsm.maps.costs: the layers it reads at
        their stored width, never the shape ids); a virtual map's at most, its pool being the bound."""
        fmts = ("float32",) + tuple(self.formats)
        per = [cost_rules.layer_bytes(("z1",) + tuple(k for k in ("z2", "slope") if k in schemes_mod.needs_of([sp])), f)
               for sp in self.specs for f in fmts]
        per += [cost_rules.moment_bytes(prefilter.get(m.name).count(m.params), f, m.mipmaps)
                for m in self.moments for f in fmts]
        return (round(min(per) * self.texels), round(max(per) * self.texels)) if per else (0, 0)

    @property
    def build_rays(self) -> tuple:
        """(rays, exact): the rays its build casts: one a texel (exact) without a layered search or a
        virtual map's pool; else at most, as only the build knows."""
        if getattr(self.cascade, "virtual", False):
            return self.texels, False
        if not self.layered:
            return self.texels, True
        return self.texels * (MAX_STEPS if self.culling != "none" else 2), False

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
        """Estimated peak bytes of the map's build: its stored layers plus one tile's working set
        (and a moment map's build, where the map serves pre-filtered instances)."""
        # a supersampled instance's moments are made of samples^2 values a texel
        # a mip chain adds a third (dsm.prefilter.mipmaps); a supersampled build its rays' working set
        moments = int(self.texels * max(MOMENT_BYTES * (4 / 3 if s.mipmaps else 1)
                                        + (SUPERSAMPLE_BYTES * s.samples ** 2 if s.samples > 1 else 0)
                                        for s in self.moments)) if self.moments else 0
        return self.stored_bytes + min(self.tile or self.texels, self.texels) * self.build_bytes_per_texel + moments


@dataclass
class Plan:
    """What a config asks to compute: its scenes and maps, with ray counts and memory estimates, before any run."""
    config: str
    scenes: list = field(default_factory=list)      # (label, width, height, lights [(label, type)])
    maps: list = field(default_factory=list)
    budget_bytes: int = 0
    absent: list = field(default_factory=list)      # optional scene files that are absent
    lambdas: int = 1                                # [oracle] lambda values
    area_samples: dict = field(default_factory=dict)  # (scene, light label) -> an area light's max_samples
    area_short: list = field(default_factory=list)  # area lights whose max_samples cannot reach their tolerance
    triangles: dict = field(default_factory=dict)   # scene label -> (triangles, the [[scene]] key naming it)
    frames: int = 0                                 # [[motion]]: frames over all paths (maps built per frame, at most)
    contact: object = None                          # [contact]: the ContactSpec of every case's march, None: none
    shrink: float | None = None                     # [map] shrink: casters moved inward (world units), None: off
    lookups: str = "wavefront"                      # [timing] lookups (dsm.experiment.wavefront)
    stacks: list = field(default_factory=list)      # [timing] builds = "together": lists of maps built together
    builds: str = "alone"                           # [timing] builds

    @property
    def oracle_receivers(self) -> int:
        """Receivers the oracles sort, at most: per map and stored format, every camera pixel of its scene."""
        px = {label: w * h for label, w, h, _ in self.scenes}
        return sum(px.get(m.scene, 0) * (1 + len(m.formats)) for m in self.maps)

    @property
    def cases(self) -> int:
        """The number of cases over all maps."""
        return sum(m.cases for m in self.maps)

    @property
    def rays(self) -> dict:
        """Exact counts by kind (map_texel only where no virtual map's pages decide it: rays_bound)."""
        out = {"gbuffer": sum(w * h for _, w, h, _ in self.scenes)}
        if not any(getattr(m.cascade, "virtual", False) for m in self.maps):    # else its pages decide
            out["map_texel"] = sum(m.texels + m.supersampled_rays for m in self.maps)
        return out

    @property
    def rays_bound(self) -> dict:
        """Upper bounds of the data-dependent kinds."""
        # one ray per receiver; an area light's reference at most max_samples per receiver
        ref = sum(w * h * self.area_samples.get((label, lab), 1) for label, w, h, lights in self.scenes
                  for lab, _ in lights)
        cont = sum(m.texels * ((MAX_STEPS - 1) if m.layered and m.culling != "none" else 1)
                   for m in self.maps if m.layered)
        texel = {} if "map_texel" in self.rays else {"map_texel": sum(m.texels + m.supersampled_rays for m in self.maps)}
        px = {label: w * h for label, w, h, _ in self.scenes}
        hybrid = sum(px.get(m.scene, 0) * m.hybrid_cases for m in self.maps)     # a rule's rays: one a receiver
        return {"reference": ref, **texel, "map_continue": cont, **({"hybrid": hybrid} if hybrid else {})}

    def peak_bytes(self) -> int:
        """Estimated peak bytes of the run: the most, over scenes, of its pixels' buffers plus its largest map."""
        return max((self._scene_peak(s)[0] for s in self.scenes), default=0)

    def _scene_peak(self, scene) -> tuple:
        """(peak bytes, parts) of one scene: the process, its pixels' buffers, its geometry, its
        largest map and its largest lookup wave; parts names the last four ({"camera", "geometry",
        "map", "lookups"}: bytes; a wave's receivers, front and back, at most the camera's pixels)."""
        label, w, h, _ = scene
        wave = 2 * w * h * WAVE_RECEIVER_BYTES
        parts = {"camera": w * h * PIXEL_BYTES,
                 "geometry": self.triangles.get(label, (0, ""))[0] * TRIANGLE_BYTES,
                 "map": self._maps_peak(label),
                 "lookups": max((min(m.cases, wave_cases(w * h)) * wave for m in self.maps
                                 if m.scene == label), default=0) if self.lookups == "wavefront" else 0}
        return PROCESS_BYTES + sum(parts.values()), parts

    def _maps_peak(self, label) -> int:
        """The most map memory of scene ``label`` at once: its largest map; where maps are built
        together, a light's stacked maps' stored layers (each kept until its cases have run) plus the
        largest build of that light (a stack's working set, or a map alone)."""
        mine = [m for m in self.maps if m.scene == label]
        worst = max((m.peak_bytes for m in mine), default=0)
        by_light = {}
        for st in self.stacks:
            if st[0].scene == label:
                by_light.setdefault(st[0].light, []).append(st)
        for light, sts in by_light.items():
            stored = sum(m.stored_bytes for st in sts for m in st)
            build = max([sum(m.peak_bytes - m.stored_bytes for m in st) for st in sts]
                        + [m.peak_bytes for m in mine if m.light == light])
            worst = max(worst, stored + build)
        return worst

    def warnings(self) -> list:
        """One line per thing a user should know before running: maps cast in tiles to stay
        within the memory budget, a peak above it even so, absent optional scene files."""
        mb = 1 / 2 ** 20
        out = []
        tiled = [m for m in self.maps if m.tile and m.tile < m.texels]
        peak = self.peak_bytes()
        line = []
        if tiled:
            worst = max(tiled, key=lambda m: m.stored_bytes + m.texels * m.build_bytes_per_texel)
            untiled = worst.stored_bytes + worst.texels * worst.build_bytes_per_texel
            line.append(f"{len(tiled)} map(s) are cast in tiles to stay within the memory budget of "
                        f"{self.budget_bytes * mb:.0f} MB (largest: {worst.scene} {worst.view} R={worst.resolution}, "
                        f"{untiled * mb:.0f} MB in one pass)")
        if peak > self.budget_bytes:
            line.append(f"the estimated peak memory {peak * mb:.0f} MB exceeds the memory budget of "
                        f"{self.budget_bytes * mb:.0f} MB{' even so' if tiled else ''} (camera buffers and stored "
                        "layers are not tiled)")
        if line:
            out.append("; ".join(line))
        if self.absent:
            out.append("absent optional scene files (skipped): " + ", ".join(map(str, self.absent)))
        out += [f"area light reference of {line}" for line in self.area_short]
        return out

    def text(self) -> str:
        """The plan as text: scenes, a line per map, ray counts, oracle receivers, peak memory and warnings."""
        mb = 1 / 2 ** 20
        lines = [f"plan for {self.config}", f"  cases: {self.cases}",
                 f"  scenes: {len(self.scenes)}, maps: {len(self.maps)}, memory budget {self.budget_bytes * mb:.0f} MB"]
        for label, w, h, lights in self.scenes:
            tris = self.triangles.get(label, (0, ""))[0]
            lines.append(f"  scene {label}: {tris:,} triangles ({tris * TRIANGLE_BYTES * mb:.1f} MB), "
                         f"G-buffer {w}x{h} ({w * h * GBUFFER_BYTES * mb:.1f} MB), lights: "
                         + ", ".join(f"{lab} ({t})" for lab, t in lights))
        lines.append("  maps (one per scene/light/view/resolution/culling; layers only as the schemes need):")
        sw, lw = self.name_widths()
        lines.append(f"    {'scene':{sw}s} {'light':{lw}s} {'view':16s} {'R':>5s} {'culling':12s} {'layers':22s} "
                     f"{'formats':14s} {'texels':>10s} {'tiles':>5s} {'MB':>8s} {'read MB':>11s} {'rays':>13s}  schemes")
        for m in self.maps:
            tiles = -(-m.texels // m.tile) if m.tile else 1
            mem = m.peak_bytes * mb
            lines.append(f"    {m.scene:{sw}s} {m.light:{lw}s} {m.view:16s} {m.resolution:5d} {m.culling:12s} "
                         f"{'+'.join(m.layers) + (' (layered)' if m.layered else ''):22s} "
                         f"{','.join(m.formats) or '-':14s} {m.texels:10d} {tiles:5d} {mem:8.1f} {_read(m):>11s} "
                         f"{_rays(m):>13s}  "
                         + ", ".join(params_label(x, exact=True) for x in m.schemes) + (f"  [cascades: {m.cascade.label}]" if m.cascade else ""))
        lines.append(self._cost_line())
        lines.append("  rays (exact): " + ", ".join(f"{k} {v:,}" for k, v in self.rays.items()))
        lines.append("  rays (at most): " + ", ".join(f"{k} {v:,}" for k, v in self.rays_bound.items()))
        n_fmt = sum(1 + len(m.formats) for m in self.maps)
        lines.append(f"  oracles (nearest lookup): receivers sorted per map and stored format ({n_fmt} x "
                     f"{self.lambdas} lambda): at most {self.oracle_receivers:,} (camera pixels per map and format)")
        if self.frames:
            lines.append(f"  motion: {self.frames} frames over all paths; each map is built per frame at most "
                         f"({self.frames} x {len(self.maps)} builds, fewer where the fitted projection stays)")
        if self.contact is not None:
            c = self.contact
            lines.append(f"  contact shadows: a march ({contact_presets.describe(c)}) per receiver of each view, "
                         "through each scene's camera depth buffer")
        if self.shrink is not None:
            lines.append(f"  caster shrinking: maps cast against a copy of each scene's meshes moved {self.shrink:g} "
                         "inward along their welded vertex normals")
        lines.append(self._lookups_line())
        lines += self._builds_lines()
        lines.append(f"  estimated peak memory: {self.peak_bytes() * mb:.1f} MB (the process "
                     f"{PROCESS_BYTES * mb:.0f} MB, camera buffers, geometry, the largest map and lookup wave "
                     "of a scene)")
        lines += [f"  warning: {w}" for w in self.warnings()]
        return "\n".join(lines)

    def _cost_line(self) -> str:
        """What the table's cost columns mean."""
        return ("  read MB: the bytes a case's lookup reads (its layers at their stored width; fewest-most over the "
                "map's cases; <= where a virtual map's pages are known only once built); rays: its build's (<= where "
                "a layered search or a virtual map's pages decide); metrics.csv gives each case's map_bytes, map_rays, taps")

    def _lookups_line(self) -> str:
        """How the cases' lookups run ([timing] lookups): per case, or each map's in waves of how many."""
        if self.lookups != "wavefront":
            return "  lookups: each case's alone (timed per case)"
        px = {label: w * h for label, w, h, _ in self.scenes}
        waves = sum(-(-m.cases // wave_cases(px.get(m.scene, 0))) for m in self.maps if m.cases)
        return (f"  lookups: each map's cases in one wavefront (at most {waves} waves for {len(self.maps)} maps, at most "
                f"{WAVE_BYTES >> 20} MB of outputs a wave), each kernel timed alone once")

    def stack_indices(self) -> list:
        """The stacks as lists of indices into ``maps`` (by identity: maps compare by value)."""
        at = {id(m): i for i, m in enumerate(self.maps)}
        return [[at[id(m)] for m in st] for st in self.stacks]

    def name_widths(self) -> tuple:
        """The scene and light columns' widths: the longest name each (a name is never cut: ``0:directional``)."""
        return (max([len("scene")] + [len(m.scene) for m in self.maps]),
                max([len("light")] + [len(m.light) for m in self.maps]))

    def _builds_lines(self) -> list:
        """How the maps are built ([timing] builds): each alone, or a sweep's small maps stacked (a line each)."""
        sw, lw = self.name_widths()
        if not self.stacks:
            why = ("" if self.builds == "alone" else " ([timing] builds = \"together\" found no two maps to stack: "
                   "a motion or cluster run, cascades, tiled maps or one map a light, view and culling)")
            return [f"  builds: each map alone (its build_ms measured alone){why}"]
        n = sum(len(st) for st in self.stacks)
        return [f"  builds: {n} maps in {len(self.stacks)} stack{'s' if len(self.stacks) > 1 else ''}, each stack "
                "one wavefront timed as a whole "
                f"(at most {STACK_BYTES >> 20} MB a stack, within the memory budget; a map's build_ms is its share of "
                f"texels), "
                f"{len(self.maps) - n} maps alone:"] + [
            f"    {st[0].scene:{sw}s} {st[0].light:{lw}s} {st[0].view:16s} culling {st[0].culling:12s} "
            "R = " + " + ".join(str(m.resolution) for m in st) for st in self.stacks]

    def as_dict(self) -> dict:
        """The plan's counts and per-map rows as a JSON-ready dict."""
        return {"cases": self.cases, "rays": self.rays, "rays_bound": self.rays_bound,
                "oracle_receivers_bound": self.oracle_receivers,
                "peak_bytes_est": self.peak_bytes(), "budget_bytes": self.budget_bytes,
                "triangles": {label: t for label, (t, _) in self.triangles.items()},
                "stacks": self.stack_indices(),
                "maps": [{"scene": m.scene, "light": m.light, "view": m.view, "resolution": m.resolution,
                          "culling": m.culling, "layers": list(m.layers), "layered": m.layered,
                          "formats": list(m.formats), "texels": m.texels, "tile": m.tile, "cases": m.cases,
                          "peak_bytes_est": m.peak_bytes, "cascade": m.cascade.label if m.cascade else None}
                         for m in self.maps],
                **({"contact": dataclasses.asdict(self.contact)} if self.contact is not None else {}),
                **({"shrink": self.shrink} if self.shrink is not None else {})}


def _read(m: Map) -> str:
    """A map's read MB cell: fewest-most, ``<=`` for a virtual map."""
    lo, hi = (x / 2 ** 20 for x in m.read_bytes)
    text = f"{hi:.3g}" if lo == hi else f"{lo:.3g}-{hi:.3g}"
    return ("<=" if getattr(m.cascade, "virtual", False) else "") + text


def _rays(m: Map) -> str:
    """A map's rays cell: exact, or ``<=`` a bound."""
    rays, exact = m.build_rays
    return ("" if exact else "<=") + f"{rays:,}"


def views_for(light_type: str, point_views, shape: str = "") -> tuple:
    """The view kinds a light gets: its own for directional and spot, the config's for points and
    sphere lights, ``fitted`` for other area lights (perspective or paraboloid, from the receivers)."""
    return light_types.get(light_type).views(point_views, shape)


def physical_memory() -> int:
    """This machine's memory in bytes: physical RAM, or a lower cgroup (container) limit."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        total = 8 << 30
    for limit in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = open(limit).read().strip()
        except OSError:
            continue
        if text.isdigit() and 0 < int(text) < total:
            total = int(text)
    return total


def memory_budget(cfg: Config) -> int:
    """The memory budget in bytes: ``memory_budget_mb`` when set, else a quarter of this machine's memory."""
    if cfg.memory_budget_mb:
        return int(cfg.memory_budget_mb * 2 ** 20)
    return physical_memory() // 4


def check_memory(plan: "Plan", source: str = "<config>", available: int | None = None):
    """Refuse, before any work, a plan whose estimated peak exceeds this machine's memory
    (``available`` bytes, default :func:`physical_memory`): such a run is killed or crashes
    (a 16384^2 camera dies with SIGSEGV). Raises ConfigError naming the part to lower."""
    available = physical_memory() if available is None else available
    gb = 1 / 2 ** 30
    for scene in plan.scenes:
        peak, parts = plan._scene_peak(scene)
        if peak <= available:
            continue
        label, w, h, _ = scene
        cause = max(parts, key=parts.get)
        if cause == "camera":
            key, what = "camera.resolution", f"{w}x{h} camera pixels x {PIXEL_BYTES} B = {parts['camera'] * gb:.1f} GiB"
        elif cause == "geometry":
            tris, key = plan.triangles[label]
            what = f"{tris:,} triangles x {TRIANGLE_BYTES} B = {parts['geometry'] * gb:.1f} GiB"
        elif cause == "lookups":
            key, what = "timing.lookups", (f"a lookup wavefront's outputs = {parts['lookups'] * gb:.1f} GiB "
                                           "(\"per_case\" holds one case's)")
        else:
            m = max((m for m in plan.maps if m.scene == label), key=lambda m: m.peak_bytes)
            key, what = "map.resolution", (f"the {m.view} map at R={m.resolution} with {'+'.join(m.layers)} "
                                           f"= {m.peak_bytes * gb:.1f} GiB")
        raise ConfigError(source, key, f"scene {label}: the estimated peak memory {peak * gb:.1f} GiB exceeds this "
                          f"machine's {available * gb:.1f} GiB ({what}); "
                          + ("use a smaller mesh" if cause == "geometry" else f"lower {key}"))


def _xml_root(path, spec=None):
    try:
        return ET.parse(path).getroot()
    except (ET.ParseError, OSError) as e:
        where = f"{spec.where}.file" if spec is not None else "file"
        raise ConfigError(getattr(spec, "source", "") or str(path), where,
                          f"cannot read {path}: not valid XML ({e})") from None


def _xml_film(path, camera_resolution, spec=None) -> tuple:
    """The camera of an XML scene: its film's size, or [camera] resolution's width at the film's aspect."""
    root = _xml_root(path, spec)
    defaults = {el.get("name"): el.get("value") for el in root.iter("default")}
    w, h = 768, 576                      # Mitsuba's film defaults
    for el in root.iter("film"):
        for it in el.iter("integer"):
            val = it.get("value", "")
            val = defaults.get(val[1:], val) if val.startswith("$") else val
            try:
                if it.get("name") == "width":
                    w = int(val)
                if it.get("name") == "height":
                    h = int(val)
            except ValueError:
                pass                     # Mitsuba reports it on loading
        break
    w, h = max(w, 1), max(h, 1)
    if camera_resolution is None:
        return w, h
    width = camera_resolution[0]
    return width, max(1, round(width * h / w))


def _xml_emitters(path, spec=None) -> list:
    """Emitter types in document order (includes followed)."""
    out = []
    root = _xml_root(path, spec)
    for el in root.iter():
        if el.tag == "emitter":
            out.append(el.get("type"))
        if el.tag == "include" and el.get("filename"):
            inc = path.parent / el.get("filename")
            if inc.suffix == ".xml" and inc.is_file():
                out += _xml_emitters(inc, spec)
    return out


def _xml_lights(path, spec=None) -> list:
    types = _xml_emitters(path, spec)
    usable = [t for t in types if t in ("point", "spot", "directional")]
    if usable:
        return usable
    return ["point" if "area" in types else "directional"]      # scenes.default_light


def scene_light_specs(spec, cfg: Config) -> list:
    """The config's LightSpec behind each of :func:`scene_lights` (None for a scene's own light)."""
    out = []
    for light in cfg.lights:
        if not light.applies_to(spec.label):
            continue
        if light.type == "scene":
            out += [None] * len(scene_lights(spec, dataclasses.replace(cfg, lights=(light,))))
        elif light.type == "area" and light.shape == "emitter":
            out += [light] * _area_emitters(spec)
        else:
            out.append(light)
    return out


def _area_emitters(spec) -> int:
    """Area emitters of a scene (an XML file's ``<emitter type="area">``; none elsewhere)."""
    if spec.file is None or spec.file.suffix.lower() != ".xml":
        return 0
    return sum(1 for t in _xml_emitters(spec.file, spec) if t == "area")


def scene_lights(spec, cfg: Config) -> list:
    """[(label, type)] of the lights a scene gets, as the runner labels them."""
    from ..scenes.builtins import builtin_geometry
    own = []
    if spec.builtin:
        own = [builtin_geometry(spec.builtin, spec.params)[2].type]
    elif spec.file.suffix.lower() == ".xml":
        own = _xml_lights(spec.file, spec)
    else:
        own = ["directional"]
    types = []
    for light in cfg.lights:
        if not light.applies_to(spec.label):
            continue
        if light.type == "area" and light.shape == "emitter":
            types += ["area"] * _area_emitters(spec)
        else:
            types += own if light.type == "scene" else [light.type]
    return [(f"{i}:{t}", t) for i, t in enumerate(types)]


def _layouts(views, cascade_specs, punctual_views: tuple = ()):
    """(view, cascade layout or None) pairs: a directional light's orthographic view once per layout
    (cascades, clipmap virtual maps), a light's ``punctual_views`` (a spot's perspective, a point light's
    cube) once per punctual virtual map."""
    punctual = [c for c in cascade_specs if getattr(c, "virtual", False) and c.punctual]
    clipmaps = [c for c in cascade_specs if not any(c is x for x in punctual)]
    for view in views:
        if view == "orthographic" and clipmaps:
            yield from ((view, c) for c in clipmaps)
        elif view in punctual_views and punctual:
            yield from ((view, c) for c in punctual)
        else:
            yield view, None


def check_emitters(cfg: Config):
    """ConfigError naming the light and the scene where an area light of ``shape = "emitter"``
    applies to a scene without an area emitter (it would give that scene no case, silently)."""
    from ..core.types import AREA_SHAPES
    for i, light in enumerate(cfg.lights):
        if light.type != "area" or light.shape != "emitter":
            continue
        for spec in cfg.scenes:
            if not spec.missing and light.applies_to(spec.label) and not _area_emitters(spec):
                raise ConfigError(cfg.source, f"light[{i}].shape", f'"emitter": scene {spec.label} has no area emitter '
                                  '(an <emitter type="area"> of a Mitsuba XML scene); give the light a shape or '
                                  "limit it to scenes with luminaires (scenes = [...])", AREA_SHAPES)


def reference_shortfall(light) -> str:
    """Why an area light's ``max_samples`` cannot reach its ``tolerance`` for a receiver that sees
    all or none of the light (:func:`dsm.truth.intervals.samples_to_certify`), or "" where it can."""
    need = intervals.samples_to_certify(light.tolerance, light.confidence)
    if light.max_samples >= need:
        return ""
    return (f"max_samples {light.max_samples} cannot certify a lit or umbra receiver within tolerance "
            f"{light.tolerance:g} at confidence {light.confidence:g} (needs {need}): such receivers end at the cap "
            "with a wider interval")


def scene_triangles(spec) -> tuple:
    """(triangles, the [[scene]] key naming the scene) of a scene spec, before it is loaded."""
    if spec.builtin:
        from ..scenes.builtins import builtin_geometry
        shapes = builtin_geometry(spec.builtin, spec.params)[0]
        return sum(len(f) for _, f in shapes.values()), f"{spec.where}.builtin"
    return scene_size.file_triangles(spec.file), f"{spec.where}.file"


def _check_every_scheme_read(cfg: Config, used: set, views_seen: set):
    """ConfigError where a [[scheme]] instance reads no map the config's lights get (it would be
    dropped without a case): a VSV lookup without a point or spot light, a depth scheme where
    map.view gives the point lights only a voxel grid."""
    if not cfg.schemes or all(sc.missing for sc in cfg.scenes):   # optional files absent: nothing planned
        return
    for s in cfg.schemes:
        if id(s) in used:
            continue
        own = schemes_mod.get(s.name).VIEWS
        why = (f"it reads only a {' or '.join(own)} grid, which point and spot lights get"
               if own is not None else "it reads a depth map: add a depth view to map.view")
        raise ConfigError(cfg.source, "map.view", f"scheme {s.name} {s.label}".rstrip() + " reads no map of this "
                          f"config (its lights get {', '.join(sorted(views_seen)) or 'no'} views): {why}",
                          tuple(own) if own is not None else POINT_VIEWS)


def make(cfg: Config) -> Plan:
    """The Plan of ``cfg``: a MapPlan per scene/light/view/resolution/culling, each tiled to fit the budget."""
    from .read import absent_files
    check_emitters(cfg)
    plan = Plan(cfg.source, budget_bytes=memory_budget(cfg), absent=absent_files(cfg),
                lambdas=len(cfg.oracle.lambdas), contact=getattr(cfg, "contact", None), shrink=getattr(cfg, "shrink", None),
                lookups=getattr(cfg, "timing_lookups", "wavefront"))
    groups = _culling_groups(cfg)
    used, views_seen = set(), set()        # the scheme instances some map reads; the views the lights get
    for si, sc in enumerate(cfg.scenes):
        if not sc.missing:
            _plan_scene(plan, cfg, si, sc, groups, used, views_seen)
    _check_every_scheme_read(cfg, used, views_seen)
    _check_planned(cfg, plan, views_seen)
    if cfg.motion:          # every case runs once per [[motion]] path, its map built per frame
        plan.frames = sum(mo.frames for mo in cfg.motion)
        for m in plan.maps:
            m.cases *= len(cfg.motion)
    base = max((w * h * PIXEL_BYTES for _, w, h, _ in plan.scenes), default=0)
    for m in plan.maps:
        room = plan.budget_bytes - base - m.stored_bytes
        fit = max(room // max(m.build_bytes_per_texel, 1), MIN_TILE)
        m.tile = int(min(m.texels, fit))
    plan.builds = getattr(cfg, "timing_builds", "alone")
    # a motion run builds its maps per frame, a Ray task runs one map: neither stacks
    if plan.builds == "together" and not cfg.motion and cfg.execution.backend != "ray":
        plan.stacks = stacks(plan, max(plan.budget_bytes - base, 0))
    return plan


def stacks(plan: Plan, room: int = STACK_BYTES) -> list:
    """The maps of ``plan`` built together (lists of two or more, in plan order): maps of one scene,
    light, single view kind (no cascade) and culling that need the same layers and are not tiled,
    while their estimated peaks add up to at most STACK_BYTES and ``room`` (the memory budget
    beyond the camera's buffers, which tiles a map alone), then a new stack starts."""
    cap = min(STACK_BYTES, room)
    out, open_ = [], {}
    for m in plan.maps:
        if not (m.cascade is None and m.tile >= m.texels and m.view not in schemes_mod.EXCLUSIVE_VIEWS
                and m.peak_bytes <= cap):
            continue
        key = (m.scene_index, m.light_index, m.view, m.culling, m.needs)
        run = open_.setdefault(key, [])
        if run and sum(x.peak_bytes for x in run) + m.peak_bytes > cap:
            out.append(run)
            run = open_[key] = []
        run.append(m)
    out += open_.values()
    at = {id(m): i for i, m in enumerate(plan.maps)}
    return sorted((st for st in out if len(st) > 1), key=lambda st: at[id(st[0])])


def _culling_groups(cfg: Config) -> dict:
    """The config's scheme instances by the culling of the map they read ({culling: [SchemeSpec]})."""
    groups = {}
    for spec in cfg.schemes:
        groups.setdefault(schemes_mod.culling_of(spec.params), []).append(spec)
    if cfg.map.moments:       # moment maps are built from the first layer, as rays see it: culling none
        groups.setdefault("none", [])
    return groups


def _plan_scene(plan: Plan, cfg: Config, si: int, sc, groups: dict, used: set, views_seen: set):
    """Scene ``si``'s camera size, lights, triangles and maps into ``plan``; the scheme instances read
    into ``used``, the views its lights get into ``views_seen``."""
    if sc.file is not None and sc.file.suffix.lower() == ".xml":
        w, h = _xml_film(sc.file, cfg.camera_resolution, sc)
    else:
        w, h = cfg.camera_resolution or DEFAULT_CAMERA
    lights = scene_lights(sc, cfg)
    specs = scene_light_specs(sc, cfg)
    plan.scenes.append((sc.label, w, h, lights))
    plan.triangles[sc.label] = scene_triangles(sc)
    for li, (label, ltype) in enumerate(lights):
        shape = specs[li].shape if specs[li] is not None else ""
        if light_types.get(ltype).SOFT:              # a Monte Carlo reference: its samples per receiver
            plan.area_samples[(sc.label, label)] = specs[li].max_samples
            short = reference_shortfall(specs[li])
            if short:
                plan.area_short.append(f"{sc.label} {label}: {short}")
        for view, cascade in _layouts(views_for(ltype, cfg.map.view, shape), cfg.map.cascade + cfg.map.virtual,
                                       light_types.get(ltype).PUNCTUAL_VIEWS):
            faces = cascade.count if cascade is not None else VIEW_FACES[view]
            virtual = getattr(cascade, "virtual", False)     # its own resolution: [map.virtual] resolution
            for R in ((cascade.resolution,) if virtual else cfg.map.resolutions_for(faces)):
                slot = _Slot(sc.label, si, label, li, ltype, view, cascade, faces, R)
                for culling, config_group in groups.items():
                    m = _map_plan(cfg, slot, culling, config_group, used, views_seen)
                    if m is not None:
                        plan.maps.append(m)


class _Slot(NamedTuple):
    """One scene, light, view and resolution of the plan, before its cullings."""
    scene_label: str
    scene_index: int
    light_label: str
    light_index: int
    light_type: str
    view: str
    cascade: object
    faces: int
    resolution: int


def _map_plan(cfg: Config, slot: _Slot, culling: str, config_group, used: set, views_seen: set):
    """The MapPlan of one slot (scene, light, view, resolution) and culling; None where no scheme reads it."""
    view, faces, R, ltype = slot.view, slot.faces, slot.resolution, slot.light_type
    per_case = len(cfg.map.filter) * len(cfg.map.format) * max(1, len(cfg.hybrid))   # [hybrid]: a case each
    fmts = tuple(f for f in cfg.map.format if f != "float32")
    # engine presets are combined instances per light type, resolved here
    read = [s for s in config_group if schemes_mod.reads_view(s, view)]  # a VSV grid: its own
    used.update(id(s) for s in read)
    views_seen.add(view)
    group = [schemes_mod.preset_for_light(s, ltype) for s in read]
    # moments are a depth map's (a voxel grid holds no depth), on its culling-none map
    moments = (cfg.map.moments if culling == "none" and view not in schemes_mod.EXCLUSIVE_VIEWS
               else ())
    if not group and not moments:
        return None
    needs = schemes_mod.needs_of(group)
    fine = {prefilter.build_key(s, f): faces * (R * s.samples) ** 2 for s in moments for f in cfg.map.format
            if s.samples > 1}       # one supersampled cast per moment build (dsm.prefilter.build_key)
    return MapPlan(slot.scene_label, slot.light_label, view, R, faces, culling, tuple(sorted(needs)),
                   "z2" in needs or culling != "none", fmts,
                   [f"{s.name} {s.label}".strip() for s in group]
                   + [f"{s.name} {s.label} {s.filter}" for s in moments],
                   len(group) * per_case + len(moments) * len(cfg.map.format),
                   specs=tuple(group), scene_index=slot.scene_index, light_index=slot.light_index, cascade=slot.cascade,
                   moments=moments, supersampled_rays=sum(fine.values()),
                   hybrid_cases=len(group) * per_case if cfg.hybrid else 0)


def _check_planned(cfg: Config, plan: Plan, views_seen: set):
    """ConfigError where the planned maps cannot take the config's options: a contact length in
    "range" units on a voxel grid, moments or cascades that no planned map gets."""
    contact = getattr(cfg, "contact", None)
    grids = sorted(views_seen & schemes_mod.EXCLUSIVE_VIEWS)
    for key in ("length", "thickness") if contact is not None and grids else ():
        if getattr(contact, key).unit == "range":     # a voxel grid's depth is a fraction of its alpha range
            raise ConfigError(cfg.source, f"contact.{key}", f"a \"k range\" length is a fraction of a depth map's "
                              f"depth range, which a {grids[0]} grid has not (its depth is the fraction of its "
                              "alpha range): give it in world or texel units", ("world", "texel"))
    if cfg.map.moments and plan.maps and not any(m.moments for m in plan.maps):
        raise ConfigError(cfg.source, "map.kind", "pre-filtered maps are built from a depth map and no light of the "
                          "config's scenes gets one (a vsv view is a voxel grid); add a depth view to map.view",
                          POINT_VIEWS)
    if cfg.map.virtual and plan.maps and not any(getattr(m.cascade, "virtual", False) for m in plan.maps):
        raise ConfigError(cfg.source, "map.virtual", "a virtual shadow map is a directional light's (with rule "
                          "punctual a spot light's, or a point light's cube view) and no light of the config's scenes "
                          "gets one; remove [map.virtual], add such a [[light]], or add cube to map.view for a point "
                          "light", ("directional", "spot", "point with map.view cube"))
    sized = cfg.map.texels or cfg.map.resolution != MapSpec.resolution      # [map]'s sizes, given
    if sized and plan.maps and all(getattr(m.cascade, "virtual", False) for m in plan.maps):
        key = "texels" if cfg.map.texels else "resolution"       # a scene's own lights: known only once loaded
        raise ConfigError(cfg.source, f"map.{key}", f"{list(getattr(cfg.map, key))} sizes no map here: every map is "
                          "[map.virtual]'s, map.virtual.resolution virtual texels a level side; remove "
                          f"map.{key}, or give map.virtual.resolution, or add map.cascades to compare with")
    if cfg.map.cascade and plan.maps and not any(m.cascade is not None for m in plan.maps):
        raise ConfigError(cfg.source, "map.cascades", "cascades are for directional lights and no light of the "
                          "config's scenes is directional; remove map.cascades or add a directional [[light]]")
