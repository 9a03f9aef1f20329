"""The runner: a loop over the plan's maps, with the failure policy, timing and the report.

The plan (:mod:`dsm.config.plan`) lists the maps in order: scene, light, view, resolution, culling.
The runner walks it, doing each shared stage once through :mod:`dsm.pipeline` (the G-buffer
per scene, receivers and the exact reference per light, receivers per view, one map per
culling choice with the layers its schemes need) and each case (a scheme instance, filter and
format on a map) as a lookup, metrics, an error image and a row of metrics.csv.

Failure policy: a stage that fails is recorded in run.json (and printed, and listed in
table.md) with the cases it would have fed, and the rest still run; rows are written as they
finish and run.json at most every RUN_JSON_EVERY_S after a case, so nothing done is lost
(a case finished after the last write of a killed run is run again by ``--resume``).
"""
from __future__ import annotations

import itertools
import math
import sys
import time
import traceback
import weakref
from dataclasses import dataclass, field
from pathlib import Path

import drjit as dr
import numpy as np

from ..config import read as cfgmod
from ..maps import cascades, headroom, shadowmap
from ..core import env, timing
from ..report import figures, publish, tables as report, io as report_io
from ..truth import metrics
from . import motion, resume, stacks, wavefront
from ..core import record
from .. import pipeline
from ..report.sections import cascades as cascade_files, soft as soft_report
from ..contact import march as contact
from ..report.sections import contact_images
from ..config import plan as planmod
from ..maps.receiver import Receiver


@dataclass
class Results:
    """What a run produced: the rows of metrics.csv, run.json's content and the images."""
    out: Path
    rows: list
    run: dict
    images: dict = field(default_factory=dict)   # case id -> class image (H, W) uint8
    oracle: list = field(default_factory=list)   # the rows of oracle.csv (per map, format and lambda)
    curves: list = field(default_factory=list)   # per map and format: (row, world Curve, texel Curve)

    def where(self, **kw) -> "Results":
        """The results whose rows have every given column at the given value."""
        unknown = sorted(set(kw) - set(report.COLUMNS))
        if unknown:
            raise KeyError(f"Results.where: no column {', '.join(unknown)} (columns: see dsm.core.record.NAMES, "
                           "e.g. scheme, params, scene, light, view, resolution, filter, format)")
        rows = [r for r in self.rows if all(r.get(k) == v for k, v in kw.items())]
        return Results(self.out, rows, self.run, {r["case"]: self.images.get(r["case"]) for r in rows},
                       self.oracle, self.curves)

    def column(self, name) -> np.ndarray:
        """The values of column ``name`` over the rows, as a numpy array (a KeyError names the columns)."""
        if name not in report.COLUMNS:
            raise KeyError(f"Results.column: no column {name!r} (columns: see dsm.core.record.NAMES, e.g. acne_rate, "
                           "peterpan_rate, error_rate, n_receivers)")
        return np.array([r[name] for r in self.rows])

    def rgb(self, case) -> np.ndarray:
        """The case's error image as (H, W, 3) uint8 in the report's colours."""
        if isinstance(case, dict):
            case = case["case"]
        if case not in self.images or self.images[case] is None:
            ids = sorted(k for k, v in self.images.items() if v is not None)
            raise KeyError(f"Results.rgb: no image of case {case!r} (cases are ids like {ids[0]!r} to {ids[-1]!r}, "
                           "or rows)" if ids else f"Results.rgb: no image of case {case!r}: this run kept no images")
        return metrics.CLASS_COLORS[self.images[case]]

    def table(self, columns=("scheme", "params", "resolution", "acne_rate", "peterpan_rate", "error_rate",
                             "build_ms", "lookup_ms")) -> str:
        """The rows as a Markdown table of the chosen columns (for notebooks and terminals)."""
        fmt = lambda v: f"{v:.4f}" if isinstance(v, float) and abs(v) < 10 else (f"{v:.1f}" if isinstance(v, float) else str(v))
        lines = ["| " + " | ".join(columns) + " |", "|---" * len(columns) + "|"]
        lines += ["| " + " | ".join(fmt(r.get(c, "")) for c in columns) + " |" for r in self.rows]
        return "\n".join(lines)

    def _repr_markdown_(self):
        return self.table()

    def __getattr__(self, name):
        if name in report.COLUMNS:
            return self.column(name)
        raise AttributeError(name)

    def __len__(self):
        return len(self.rows)


RUN_JSON_EVERY_S = 1.0


@dataclass
class LightMaps:
    """One light's views and maps built together while its maps run ([timing] builds = "together")."""
    stack_of: dict                                  # id(map plan) -> its stack (all of it among the light's maps)
    views: dict = field(default_factory=dict)       # (view kind, R) -> the view, fitted once (no cascades)
    built: dict = field(default_factory=dict)       # id(map plan) -> stacks.Built, until its cases run
    tried: set = field(default_factory=set)         # id of each stack's first map, built (or failed) once

    @classmethod
    def of(cls, plan_stacks, light_maps) -> "LightMaps":
        """The light's record: the plan's stacks whose maps are all among ``light_maps``."""
        ids = {id(m) for m in light_maps}
        return cls({id(m): st for st in plan_stacks if all(id(x) in ids for x in st) for m in st})


class StageFailed(Exception):
    """A stage failed and was recorded; the cases it feeds are skipped."""


class Runner:
    """Runs a config's plan into folder ``out``: each shared stage once, then each case's lookup, metrics and row."""
    def __init__(self, config: cfgmod.Config, out: Path, variant: str | None = None, progress: bool = True,
                 keep_images: bool = True, resume_previous: bool = False):
        self.cfg = config
        self.out = Path(out)
        self.variant = env.use_variant(variant or config.variant)
        self.progress = progress
        self.keep_images = keep_images
        self.plan = planmod.make(config)
        self.record = record.RunRecord()     # everything measured: rows, statuses, maps, rays, oracles ...
        self.images = {}
        self.case_no = 0
        self.cases_kept = 0           # rows written again from the run being resumed (not measured here)
        self.extents = {}             # per scene: the spawn bound's per-shape extents
        self.versions = env.versions()
        self.state = "running"
        self.bar = None
        self.timing = {}              # seconds measuring and writing the report
        self.plan_dict = None         # run.json's plan, made once
        self.run_json_at = -math.inf  # when run.json was last written (perf_counter seconds)
        # case ids and identity keys from the plan (dsm.experiment.resume); a resumed run reuses matching cases
        self.keys = dict(resume.case_keys(config, self.plan, "git:" + self.versions["dsm_git_commit"]))
        self.first_case = list(itertools.accumulate((m.cases for m in self.plan.maps), initial=0))
        self.resume_previous = resume_previous
        self.kept, self.stale = {}, []
        self.depth_buffers = {}       # [contact]: the current scene's camera depth buffer (made when a case asks)
        self.marches = {}             # [contact]: per receiver set, (receivers, occluded, timing) of its march
        self.cosines = (None, None)   # the shadow images' receiver set (weakly: never kept alive) and its cosines
        self.shrunk = (None, None)    # [map] shrink: (scene label, its shrunk copy)

    # ------------------------------------------------------------ top level
    def run(self) -> Results:
        """Run every case. run.json is rewritten (atomically) with the run's state: ``running``
        (after a case, at most every RUN_JSON_EVERY_S), then ``complete``, or ``interrupted`` after
        Ctrl-C (re-raised once the folder says what it holds); a killed run leaves ``running`` and
        every case finished by its last write (``--resume`` runs the rest)."""
        timing.enable_history()
        timing.reset_launches()
        t0, c0 = time.perf_counter(), _cpu()
        self.out.mkdir(parents=True, exist_ok=True)
        if self.resume_previous:
            self.kept, self.stale = resume.Previous(self.out).arrange(list(self.keys.items()))
        (self.out / "images").mkdir(exist_ok=True)
        self.csv = report_io.CsvWriter(self.out / "metrics.csv")
        self.state = "running"
        self._write_run_json()
        self.bar = report.progress(total=self.plan.cases, enabled=self.progress)
        try:
            self._run_plan()
        except KeyboardInterrupt:
            self.state = "interrupted"
            raise
        else:
            self.state = "complete"
        finally:
            self.bar.close()
            # the case images are written as cases finish (so a killed run keeps them): report time
            self.timing["measure_s"] = time.perf_counter() - t0 - self.timing.get("images_s", 0.0)
            self.timing["measure_cpu_s"] = _cpu() - c0 - self.timing.get("images_cpu_s", 0.0)
            self.timing["measure_peak_rss_bytes"] = peak_rss()     # against the plan's peak_bytes_est
            self.timing["kernel_launches"] = self._launches()
            self._write_run_json(force=True)      # a run ended by an error other than Ctrl-C is still "running"
            publish.write_data(self.out, self.record)
            # the report, after every timed measurement, composed from the run's files alone (as
            # dsm report does): figures, table.md, cascades.md, report.html
            t1, c1 = time.perf_counter(), _cpu()
            try:
                self.timing["report_parts"] = publish.write_report(self.out, (), self.record.curves,
                                                                   plots=self.state == "complete")
            except Exception as e:          # the measurements are saved; the report can be rebuilt
                self._fail("report (dsm report rebuilds it)", e)
            self.timing["report_s"] = time.perf_counter() - t1 + self.timing.get("images_s", 0.0)
            self.timing["report_cpu_s"] = _cpu() - c1 + self.timing.get("images_cpu_s", 0.0)
            self._write_run_json(force=True)
        return Results(self.out, self.record.rows, self._run_json(), self.images, self.record.oracle_rows, self.record.curves)

    def _launches(self) -> dict:
        """JIT kernel launches while measuring (Dr.Jit's kernel history, this process only: a
        cluster run's tasks launch theirs elsewhere, so it is null there), outside and inside
        the timed repeats, and outside per case run here."""
        timing.drain_launches()
        n = len(self.record.rows) - self.cases_kept
        out = dict(timing.LAUNCHES)
        out["outside_per_case"] = out["outside_repeats"] / n if n else None
        return out

    def run_maps(self, maps, kept=None):
        """Run only ``maps`` (part of the plan: a Ray task's map group) into this runner's folder,
        without run.json or the report; ``kept``: finished cases to write again (key -> (row, status)).
        The rows, status, oracle rows, curves and map records stay on the runner."""
        self.out.mkdir(parents=True, exist_ok=True)
        (self.out / "images").mkdir(exist_ok=True)
        self.csv = report_io.CsvWriter(self.out / "metrics.csv")
        self.bar = report.progress(total=sum(m.cases for m in maps), enabled=False)
        self.kept = kept or {}
        self.state = "task"
        self._run_plan(maps)

    def _run_plan(self, maps=None):
        maps = self.plan.maps if maps is None else maps
        for spec in self.cfg.scenes:
            if spec.missing:
                self.record.status.append({"what": f"scene {spec.label}", "status": "skipped", "error": spec.missing})
        for si, scene_maps in itertools.groupby(maps, key=lambda m: m.scene_index):
            scene_maps = list(scene_maps)
            try:
                sd, gb, lights = self._scene(self.cfg.scenes[si], scene_maps)
            except StageFailed:
                continue
            if self.cfg.motion:                 # camera and light paths: dsm.experiment.motion's frame loop
                try:
                    self._stage(f"motion of scene {sd.label}", scene_maps, lambda: motion.run_scene(
                        self, sd, lights, scene_maps, self._closed(sd), self.extents[sd.label]))
                except StageFailed:
                    pass
                self._write_run_json()
                continue
            for li, light_maps in itertools.groupby(scene_maps, key=lambda m: m.light_index):
                light_maps = list(light_maps)
                try:
                    setup = self._light(sd, gb, lights, li, light_maps)
                except StageFailed:
                    continue
                light = LightMaps.of(self.plan.stacks, light_maps)
                for _, view_maps in itertools.groupby(light_maps, key=lambda m: (m.view, m.resolution, m.cascade)):
                    self._run_view(sd, gb, setup, list(view_maps), light)
            self._write_run_json()

    # ------------------------------------------------------------ failure policy
    def _fail(self, what, exc, skipped_maps=()):
        """Record a failure (run.json, console, table.md) and count the cases it takes with it."""
        error = f"{type(exc).__name__}: {exc}"
        self.record.status.append({"what": what, "status": "failed", "error": error,
                            "traceback": traceback.format_exc(limit=6)})
        print(f"dsm: failed: {what}: {error}", file=sys.stderr)     # seen where the user looks, not only in run.json
        self.bar.update(sum(m.cases for m in skipped_maps))

    def _stage(self, what, maps, fn):
        """Run one shared stage; on an exception record it and raise StageFailed."""
        try:
            return fn()
        except (KeyboardInterrupt, StageFailed):
            raise
        except Exception as e:
            self._fail(what, e, maps)
            raise StageFailed(what) from None

    # ------------------------------------------------------------ stages
    def _scene(self, spec, maps):
        def load():
            """The scene loaded, its G-buffer (timed) and its usable lights; ValueError when it has none."""
            sd = pipeline.load_scene(spec, self.cfg.camera_resolution, self.cfg.camera)
            gb, t = timing.measure(lambda: (pipeline.gbuffer(sd),), 0)
            gb = gb[-1]
            gb.ms = t.ms
            lights = sd.lights_for(self.cfg.lights)
            if not lights:
                raise ValueError("the scene has no usable point/spot/directional emitter and the config names "
                                 "no [[light]]")
            return sd, gb, lights
        sd, gb, lights = self._stage(f"scene {spec.label}", maps, load)
        self.record.gbuffer_ms[sd.label] = gb.ms
        self.extents[sd.label] = pipeline.spawn_extents(sd.scene)   # once per scene, outside the timed builds
        self.record.rays["gbuffer"] += gb.width * gb.height
        if sd.notes:
            self.record.status.append({"what": f"scene {sd.label}", "status": "note", "error": "; ".join(sd.notes)})
        return sd, gb, lights

    def _light(self, sd, gb, lights, li, maps):
        label = maps[0].light

        def setup():
            """The light setup (receivers and exact reference) of light ``li`` of the loaded scene."""
            if li >= len(lights):
                raise ValueError(f"the plan expects light {label} but the loaded scene has {len(lights)} lights")
            return pipeline.light_setup(sd, gb, lights[li], label, self.cfg.timing_repeats, self.cfg.seed)
        out = self._stage(f"scene {sd.label} light {label}", maps, setup)
        self.record.rays["reference"] += out.reference_rays       # one per receiver, or an area light's samples
        if out.ref is not None:
            self.record.reference_regions.append({"scene": sd.label, "light": label, **out.ref.stats()})
        return out

    def _view(self, sd, setup, light, m):
        """The view of map plan ``m`` fitted to the light's receivers: once per kind and resolution of
        the light (a stacked map's and its view group's are one object), a cascaded view each time."""
        key = (m.view, m.resolution)
        if m.cascade is None and key in light.views:
            return light.views[key]
        pts = pipeline.points_np(setup.p) if setup.p is not None else np.zeros((0, 3))
        view = pipeline.make_view(setup.light, m.resolution, pts, sd.bbox, m.view, m.cascade, sd.sensor, sd.scale)
        if m.cascade is None:
            light.views[key] = view
        return view

    def _built(self, sd, setup, light, m):
        """Map plan ``m``'s Built when the plan stacks it ([timing] builds = "together"), its stack built
        when its first map comes up; None: built alone (a stack that fails is noted, its maps built alone)."""
        st = light.stack_of.get(id(m))
        if st is None:
            return None
        if id(st[0]) not in light.tried:
            light.tried.add(id(st[0]))
            try:
                light.built.update(zip(map(id, st), self._build_stack(sd, setup, light, st)))
            except KeyboardInterrupt:
                raise
            except Exception as e:
                self.record.status.append({"what": f"scene {sd.label} light {setup.label} view {st[0].view} maps "
                                           + "+".join(str(x.resolution) for x in st) + " built together",
                                           "status": "note", "error": f"{type(e).__name__}: {e}; built alone"})
        return light.built.pop(id(m), None)          # the map's own from here: freed after its cases

    def _build_stack(self, sd, setup, light, st) -> list:
        """Each map of stack ``st`` built together and timed (dsm.experiment.stacks.Built)."""
        views = [self._view(sd, setup, light, m) for m in st]
        own = {frozenset(pipeline.needs_of([pipeline.preset_for_light(spec, setup.light.type)]))
               for m in st for spec in m.specs}
        casters = self._casters(sd)
        culling = st[0].culling
        modes = (culling, pipeline.map_cull_modes(casters, views[0], culling, self._closed(sd) if culling != "none"
                                                  else None), pipeline.map_cull_modes(casters, views[0]))
        return stacks.build(casters, views, st[0].needs, modes, own, self.extents[sd.label], self.cfg.timing_repeats)

    def _run_view(self, sd, gb, setup, maps, light):
        """One view and resolution of a light: its receivers, then each of its maps (one per culling);
        ``light``: the light's views and maps built together (LightMaps)."""
        kind, R = maps[0].view, maps[0].resolution

        def receivers():
            """(view, setup, rx, seam, back): the fitted view, the receivers inside it, their lookups and seams."""
            view = self._view(sd, setup, light, maps[0])
            s = setup.subset(view.inside(setup.p).numpy().astype(bool)) if setup.p is not None else setup
            rx = seam = None
            if s.p is not None and len(s.pixels):
                rx = pipeline.receivers(view, s, sd.diagonal)
                seam = view.seam_distance(rx.u_map, rx.v_map, rx.face)
                dr.eval(rx.depth, rx.u_map, rx.v_map, rx.face, rx.texel_world, rx.to_light, seam)
                seam = seam.numpy()
            return view, s, rx, seam, s.backfacing_inside(view)
        try:
            view, setup, rx, seam, back = self._stage(f"scene {sd.label} light {setup.label} view {kind} map {R}",
                                                      maps, receivers)
        except StageFailed:
            return
        first_t = None
        for m in maps:
            try:
                first_t = self._run_map(sd, gb, setup, view, rx, seam, back, m, first_t, self._built(sd, setup, light, m))
            except StageFailed:
                continue

    def _closed(self, sd):
        """Per-shape closedness, computed once per scene and recorded in run.json."""
        for info in self.record.scene_info:
            if info["scene"] == sd.label:
                return [s["closed"] for s in info["shapes"]]
        closed, why = pipeline.closedness(sd)
        self.record.scene_info.append({"scene": sd.label, "shapes": [
            {"name": n, "closed": c, "why": w} for n, c, w in zip(sd.shape_names, closed, why)]})
        return closed

    def _build(self, sd, view, needs, culling, tile):
        closed = self._closed(sd) if culling != "none" else None
        extents = self.extents[sd.label]
        casters = self._casters(sd)
        return timing.measure_kernel(lambda: _map_arrays(casters, view, needs, culling, closed, tile, extents),
                                     self.cfg.timing_repeats)

    def _casters(self, sd):
        """The scene the maps are cast against: the scene, or its copy shrunk by ``[map] shrink`` (once per scene)."""
        if self.cfg.shrink is None:
            return sd.scene
        if self.shrunk[0] != sd.label:
            self.shrunk = (sd.label, pipeline.shrunk_scene(sd.scene, self.cfg.shrink))
        return self.shrunk[1]

    def _map_build(self, sd, setup, view, m, built) -> tuple:
        """(map, build Timing, stored copy per format) of map plan ``m``: built and timed alone (with its
        peak bytes), or ``built`` in a stack (dsm.experiment.stacks); a failure is the map's stage's."""
        def build():
            """(map, build time, stored): the map and its copy per stored format."""
            if built is not None:
                smap, bt = built.smap, built.times[frozenset(m.needs)]
            else:
                timing.reset_peak()
                smap, bt = self._build(sd, view, set(m.needs), m.culling, m.tile)
                smap = smap[-1]
                smap.peak_bytes = timing.peak_bytes()
            return smap, bt, {fmt: pipeline.store(smap, fmt) for fmt in self.cfg.map.format}
        what = f"scene {sd.label} light {setup.label} view {view.kind} map {m.resolution} culling {m.culling}"
        return self._stage(what, [m], build)

    def _run_map(self, sd, gb, setup, view, rx, seam, back, m, first_t, built=None):
        """Build one map (the plan's layers, culling and tile), store its formats, run its cases.
        ``first_t``: (the first layer's build time, maps sharing it) from the view's first map, or None;
        ``built``: the map built in a stack (dsm.experiment.stacks), or None. Returns ``first_t``."""
        smap, bt, stored = self._map_build(sd, setup, view, m, built)
        self._record_map(sd, setup, view, m, smap, bt)
        self.record.quantized += sum(1 for fmt in self.cfg.map.format if fmt != "float32")
        # receivers in the depth function each stored format compares in (formats.stored_view)
        bp, bn = back
        by_view = {}                  # formats sharing a depth function share their receivers
        for fmt in stored:
            v = stored[fmt].view
            if id(v) not in by_view:
                front = rx if rx is None or v is view else Receiver.make(v, setup.p, setup.n, sd.diagonal, setup.camera)
                by_view[id(v)] = (front, Receiver.make(v, bp, bn, sd.diagonal, setup.camera) if bp is not None else None)
        rxs = {fmt: by_view[id(stored[fmt].view)][0] for fmt in stored}
        backs = {fmt: by_view[id(stored[fmt].view)][1] for fmt in stored}
        wrong = {fmt: self._oracles(sd, setup, view, m, stored[fmt], rxs[fmt], fmt) for fmt in stored}
        build_times = dict(built.times) if built is not None else {frozenset(m.needs): bt}
        # the first layer without culling, so a case's extra layers show as build_ms - build_first_ms:
        # a stacked map's share of its stack's; a map alone its own, measured once a view group
        if built is not None:
            first_t = (built.first, built.shared)
        elif first_t is None or first_t[1] > 1:
            first_t = (bt if m.culling == "none" and not m.needs else self._build(sd, view, set(), "none", m.tile)[1], 1)
        self.case_no = self.first_case[self.plan.maps.index(m)]     # case ids from the plan
        specs = [pipeline.preset_for_light(spec, setup.light.type) for spec in m.specs]   # a preset's values here
        extras, looked = self._lookups(specs, stored, rxs, backs)
        for spec in specs:
            own = frozenset(pipeline.needs_of([spec]))                  # this instance's own layers, for build_ms
            if own not in build_times:
                # the build of exactly what this scheme needs (its data comes from the shared map)
                build_times[own] = self._build(sd, view, own, m.culling, m.tile)[1]
            for filt in self.cfg.map.filter:
                for fmt in self.cfg.map.format:
                    self._run_case(sd, gb, setup, view, stored[fmt], (build_times[own], first_t[0]), rxs[fmt], seam,
                                   spec, filt, fmt, backs[fmt], wrong[fmt] if filt == "nearest" else None,
                                   extra=extras.get((spec, filt, fmt)), looked=looked.get((spec, filt, fmt)))
                    self.bar.update(1)
        moment_maps = {}              # instances sharing their moments share one build (dsm.prefilter)
        for spec in m.moments:
            for fmt in self.cfg.map.format:
                # build_ms: the depth map's first layer, which the moments are made of (moments_ms apart)
                self._run_case(sd, gb, setup, view, smap, (first_t[0], first_t[0]), rxs[fmt], seam, spec, spec.filter, fmt,
                               backs[fmt], None, moment=self._moments(moment_maps, spec, smap, fmt, sd))
                self.bar.update(1)
        return first_t

    def _lookups(self, specs, stored, rxs, backs) -> tuple:
        """(extras, looked) of one map's depth cases not kept from a resumed run, by (spec, filter,
        format): with ``[timing] lookups = "wavefront"`` every lookup from the map's wavefront
        (dsm.experiment.wavefront; its wave time into the map's record), else each case times its
        own lookup and only its attached-shadow V and plane fallbacks come from one wavefront."""
        family = [(spec, filt, fmt) for spec in specs for filt in self.cfg.map.filter for fmt in self.cfg.map.format]
        cases = [c for i, c in enumerate(family, self.case_no + 1) if self.keys.get(f"{i:04d}") not in self.kept]
        if self.cfg.timing_lookups == "per_case":
            return wavefront.attached_only(cases, stored, rxs, backs, self.cfg.seed), {}
        looked, wave = wavefront.run(cases, stored, rxs, backs, self.cfg.seed, self.cfg.timing_repeats, family)
        self.record.maps[-1].update(wave)
        return {}, looked

    def _moments(self, cache, spec, smap, fmt, sd):
        """A function giving (MomentMap, build Timing) of ``spec`` on ``smap``, built (timed) once per
        moment key; a supersampled instance's build casts its own rays (timed with it)."""
        key = pipeline.moment_key(spec, fmt)

        def get():
            """The cached build, made on first use (inside the case's failure policy)."""
            if key not in cache:
                def build():
                    """The moment map's arrays (evaluated by the clock) and the map."""
                    fine = None if spec.samples == 1 else pipeline.supersampled_map(
                        self._casters(sd), smap.view, spec.samples, self.extents[sd.label])
                    mm = pipeline.moment_map(spec, smap, fmt, fine)
                    return (*mm.b, mm)
                out, t = timing.measure(build, self.cfg.timing_repeats)
                if spec.samples > 1:        # one build's rays (the timed repeats cast them again)
                    self.record.add_rays({"map_texel": smap.view.n_texels * spec.samples ** 2})
                cache[key] = (out[-1], t)
            return cache[key]
        return get

    def _oracles(self, sd, setup, view, m, smap, rx, fmt):
        """The oracles of one map and stored format over the view's receivers (oracle.csv, the
        trade-off curves); returns per receiver whether the per-texel oracle at the first lambda
        gets it wrong (the resolution's share of a nearest case's errors), None on failure."""
        if rx is None:
            return np.zeros(0, bool)
        if setup.ref is not None or not view.depth_oracles:
            return None               # an area light (the oracles are a hard V*'s); a VSV grid (no depth bias)
        meta = {"scene": sd.label, "light": setup.label, "view": view.kind, "resolution": m.resolution,
                "culling": m.culling, "format": fmt}
        try:
            th = pipeline.thresholds(rx, smap)
            wrong = None
            for lam in self.cfg.oracle.lambdas:
                o = pipeline.oracles(th, setup.v_star, lam)
                row = {**meta, **o["row"]}
                self.record.oracle_rows.append(row)
                if wrong is None:
                    wrong = o["wrong"]
                    self.record.curves.append((row, o["curve_world"], o["curve_texel"]))
            return wrong
        except (KeyboardInterrupt, StageFailed):
            raise
        except Exception as e:
            self._fail(f"oracles of scene {sd.label} light {setup.label} view {view.kind} map {m.resolution} "
                       f"culling {m.culling} format {fmt}", e)
            return None

    def _record_map(self, sd, setup, view, m, smap, bt):
        self.record.maps.append({"scene": sd.label, "light": setup.label, "view": view.kind, "resolution": m.resolution,
                          "culling": m.culling, "layers": ["z1", "shape"] + [k for k in shadowmap.LAYERS
                                                                           if getattr(smap, k) is not None],
                          "tiles": smap.tiles, "rays": dict(smap.rays), "rehits": smap.rehits, "build_shared": smap.shared,
                          "build_ms": bt.ms,      # its layers' build, kernel time (a stacked map's: its share)
                          "build_peak_bytes": smap.peak_bytes, "build_peak_bytes_est": m.peak_bytes,
                          "formats": list(m.formats)})
        for k, v in smap.rays.items():
            self.record.rays[k] = self.record.rays.get(k, 0) + v
        if smap.unfinished:
            self.record.status.append({"what": f"map {sd.label} {setup.label} R={m.resolution} culling={m.culling}",
                                "status": "warning", "error": f"{smap.unfinished} texels still searching "
                                f"after {shadowmap.MAX_STEPS} surfaces"})

    def _run_case(self, sd, gb, setup, view, smap, build, rx, seam, spec, filt, fmt, rx_back=None, wrong=None,
                  moment=None, extra=None, looked=None):
        """One case: a scheme instance and filter on a stored depth map, or (``moment``: its
        MomentMap's builder) a pre-filtered instance on the depth map's moments; ``extra``: its
        attached-shadow V and plane fallbacks from the map's wavefront, ``looked``: all its lookups
        from there (dsm.experiment.wavefront.Looked; else looked up here)."""
        case = self.next_case()
        if self.keys.get(case) in self.kept:          # finished by the run being resumed: its row again
            row, st, cascade_rows = self.kept[self.keys[case]]
            self.record.cascade_rows += cascade_rows
            self.add_case(resume.parse_row(row), st)
            self.cases_kept += 1
            self._write_run_json()
            return
        meta = {"case": case, "scene": sd.label, "light": setup.label, "view": view.kind, "scheme": spec.name,
                "culling": smap.culling,
                "preset": spec.preset or "", "params": spec.label, "resolution": view.resolution,
                "total_texels": view.n_texels,
                "filter": filt, "format": fmt, "cascade_layout": view.spec.label if view.cascaded else ""}
        try:
            mt = None
            if moment is None:
                look = lambda r: pipeline.visibility(spec, r, smap, filt, self.cfg.seed)
            else:
                mmap, mt = moment()
                look = lambda r: pipeline.moment_visibility(spec, r, mmap, smap)
            uses_plane = moment is None and pipeline.scheme_module(spec.name).USES_PLANE
            if looked is not None:
                v_np, tap_np, lt, extra = looked.v, looked.tap_shape, looked.timing, (looked.v_back, looked.misses)
            else:
                v_np, tap_np, lt = self._looked_up(rx, look)
            if extra is None:         # not in a map's wavefront (pre-filtered, or its tracing failed there)
                extra = (look(rx_back)[0].numpy() if rx_back is not None else np.zeros(0),
                         pipeline.plane_fallbacks(spec, rx, smap) if uses_plane and rx is not None else 0)
            v_back, fallbacks = extra
            m, occ = self._case_metrics(sd, gb, setup, view, rx, seam, v_back, wrong, v_np, tap_np, meta)
            fallback = fallbacks if uses_plane else metrics.UNDEFINED
            row = self._case_row(meta, setup, m, rx, spec, moment, mt, build, smap, lt, v_np, fallback)
            row["lookup_shared"] = looked.shared if looked is not None else 1
            self._case_images(meta, gb, setup, v_np, wrong, occ, rx)
            # a case without receivers says nothing about the scheme: it is reported as empty
            self.add_case(row, {"what": f"case {case}", **{k: meta[k] for k in ("scene", "light", "view", "scheme",
                                                                                "params", "resolution")},
                                "status": "ok" if m["n_receivers"] else "empty", "key": self.keys.get(case)})
            self._write_run_json()
        except Exception as e:
            self._fail(f"case {case} ({sd.label}, {setup.label}, {spec.name} {spec.label}, R={view.resolution})", e)

    def _looked_up(self, rx, look) -> tuple:
        """(visibility, tap shapes (numpy), the lookup's Timing) of receivers ``rx``."""
        if rx is None:
            return np.zeros(0), np.zeros(0, np.uint32), timing.Timing(0.0, 0.0, 0.0, 0, 0)
        (v, tap_shape), lt = timing.measure_kernel(lambda: look(rx), self.cfg.timing_repeats)
        return v.numpy(), tap_shape.numpy(), lt

    def _case_metrics(self, sd, gb, setup, view, rx, seam, v_back, wrong, v_np, tap_np, meta) -> tuple:
        """(the case's counts and rates, the contact march's occlusion or None; ``v_back``: V of the
        attached-shadow receivers); a cascaded map's per-cascade rows, curve and index image recorded on the way."""
        m = pipeline.metrics(v_np, setup, tap_np, seam, view.has_seams)
        m.update(pipeline.split(v_np, setup.v_star, wrong))     # NaN unless nearest (the oracles' lookup)
        occ = None
        if self.cfg.contact is not None:      # screen-space contact shadows after the lookup
            cols, occ = self._contact(sd, gb, setup, rx, v_np)
            m.update(cols)
        if view.cascaded:         # a cascaded map: per cascade, texels per pixel, distance plot
            extra, per, curve, faces = pipeline.cascade_metrics(view, rx, v_np, setup.v_star)
            m.update(extra)
            self.record.cascade_rows += [{**meta, **r} for r in per]
            self.record.cascade_curves.append((meta, curve))
            folder = self.out / "images" / figures.image_folder(meta)
            folder.mkdir(parents=True, exist_ok=True)
            cascade_files.write_index_image(folder / f"{meta['case']}_cascade.png", setup.pixels, faces, gb.width, gb.height)
        # Weiskopf & Ertl's self-unshadowing: pixels in attached shadow (facing away) that the map calls lit
        m["n_backfacing"] = int(v_back.size)
        m["backface_lit_rate"] = float((v_back >= 0.5).mean()) if v_back.size else metrics.UNDEFINED
        return m, occ

    def _case_row(self, meta, setup, m, rx, spec, moment, mt, build, smap, lt, v_np, fallback) -> dict:
        """The case's metrics.csv row: its keys, exclusions, metrics, headroom, timings and sweep
        (``fallback``: its plane fallbacks, or UNDEFINED for a scheme without a plane)."""
        bt, first_t = build
        texel = float(np.median(rx.texel_world.numpy())) if rx is not None else metrics.UNDEFINED
        sweep_key, sweep_value = report.sweep_of(spec, self.cfg.schemes if moment is None else self.cfg.map.moments)
        extent = setup.max_abs_coordinate if rx is not None else metrics.UNDEFINED
        row = {**meta, **setup.exclusions, **m, **headroom.headroom(extent, texel), "texel_size": texel,
               "n_plane_fallback": fallback,
               "build_ms": bt.ms, "build_first_ms": first_t.ms, "build_compile_ms": bt.compile_ms, "build_peak_mb": smap.peak_bytes / 2 ** 20,
               "build_shared": smap.shared,
               "lookup_ms": lt.ms, "lookup_compile_ms": lt.compile_ms, "lookup_kernels_compiled": lt.cache_misses,
               "reference_ms": setup.reference_ms, "sweep_key": sweep_key, "sweep_value": sweep_value}
        if self.cfg.map.leak_split:          # [map] kind given: every case's leak split (dsm.truth.metrics)
            texel_np = rx.texel_world.numpy() if rx is not None else np.zeros(0)
            row.update({"map_kind": spec.name if moment is not None else "depth",
                        **metrics.leak_split(v_np, setup.v_star, setup.occluder_dist, texel_np,
                                             self.cfg.map.leak_texels),
                        "moments_ms": mt.ms if moment is not None else metrics.UNDEFINED})
        return row

    def _case_images(self, meta, gb, setup, v_np, wrong, occ, rx):
        """The case's images (classes, shading, contact march, area-light V), written now."""
        # the case's images: report work, timed apart; its CPU is this thread's (the images are drawn
        # here, single-threaded), so Dr.Jit's workers winding down the case's kernels stay measuring's
        t_img, c_img = time.perf_counter(), time.thread_time()
        case = meta["case"]
        classes = np.zeros(gb.width * gb.height, np.uint8)
        leak = None
        if self.cfg.map.leak_split and rx is not None:     # [map] kind given: the leaks in their own colour
            leak = metrics.leak_mask(v_np, setup.v_star, setup.occluder_dist, rx.texel_world.numpy(),
                                     self.cfg.map.leak_texels)
        classes[setup.pixels] = pipeline.classify(v_np, setup.v_star, wrong, leak)
        classes = classes.reshape(gb.height, gb.width)
        shade = report.shade(classes.shape, gb, setup, v_np, pipeline.is_positional(setup.light),
                             self._cosines(setup)) if self.cfg.report_images == "all" else None
        item = publish.image_item(meta, classes, shade, self.cfg.report_images)
        if item is not None:        # written now (Pillow, ~1 ms, between timings): a killed run keeps them
            figures.write_images(self.out, [item])
        if occ is not None and self.cfg.report_images != "none":         # what the contact march did
            folder = self.out / "images" / figures.image_folder(meta)
            folder.mkdir(parents=True, exist_ok=True)
            contact_images.write_image(folder / f"{case}_contact.png", setup.pixels,
                                       contact_images.classes(v_np, setup.v_star, occ), gb.width, gb.height)
        if setup.ref is not None and self.cfg.report_images != "none":    # area light: V, V*, |V - V*|
            soft_report.write_images(self.out, [soft_report.image_item(meta, gb.width, gb.height, setup.pixels,
                                                                       v_np, setup.v_frac)])
        self.timing["images_s"] = self.timing.get("images_s", 0.0) + time.perf_counter() - t_img
        self.timing["images_cpu_s"] = self.timing.get("images_cpu_s", 0.0) + time.thread_time() - c_img
        if self.keep_images:
            self.images[case] = classes

    def _cosines(self, setup):
        """The receivers' cosines to the light for the shadow images, once per receiver set (every
        case of a map shares its set)."""
        if setup.n is None:
            return None
        held = self.cosines[0]() if self.cosines[0] is not None else None
        if held is not setup:
            self.cosines = (weakref.ref(setup), report.receiver_cosines(setup, pipeline.is_positional(setup.light)))
        return self.cosines[1]

    def _contact(self, sd, gb, setup, rx, v_np) -> tuple:
        """(columns, occluded per receiver) of one case's contact step: its receivers' march (once per
        receiver set, timed) applied to the case's V."""
        if rx is None:
            none = np.zeros(0, bool)
            return {**contact.case_metrics(v_np, setup.v_star, none), "contact_ms": 0.0}, none
        if sd.label not in self.depth_buffers:     # the current scene's only: the runner walks scene by scene
            self.depth_buffers = {sd.label: contact.depth_buffer(gb)}
        db = self.depth_buffers[sd.label]
        if id(rx) not in self.marches:    # the march reads receivers and light only: every case of them shares it
            light_world = setup.light.position if pipeline.is_positional(setup.light) else None
            out, t = timing.measure(lambda: (contact.march(db, rx, self.cfg.contact, self.cfg.seed, light_world),),
                                    self.cfg.timing_repeats)
            self.marches = {id(rx): (rx, out[-1].numpy().astype(bool), t)}    # the receivers kept: their id stays theirs
        _, occ, t = self.marches[id(rx)]
        return {**contact.case_metrics(v_np, setup.v_star, occ, setup.v_frac), "contact_ms": t.ms}, occ

    def next_case(self) -> str:
        """The next case's id ("0001", ...), counted."""
        self.case_no += 1
        return f"{self.case_no:04d}"

    def case_done(self, row: dict, status: dict):
        """A finished case's row and status recorded, and the progress bar moved on by one."""
        self.add_case(row, status)
        self.bar.update(1)

    def add_case(self, row: dict, status: dict):
        """One finished case: its row into metrics.csv (refused unless it fits the schema,
        record.check_row) and the record, and its status."""
        self.csv.write(row)
        self.record.rows.append(row)
        self.record.status.append(status)

    # ------------------------------------------------------------ run.json
    def _run_json(self):
        info = report.run_info(self.cfg, self.variant, self.record.rays, self.record.status, self.versions, dr.thread_count())
        info["state"] = self.state
        info["scenes"] = self.record.scene_info
        info["gbuffer_ms"] = self.record.gbuffer_ms     # one cold pass per scene (compile included)
        if self.plan_dict is None:            # the plan does not change while it runs
            self.plan_dict = self.plan.as_dict()
        info["plan"] = self.plan_dict
        info["maps"] = self.record.maps
        info["quantized_copies"] = self.record.quantized
        info["reference_regions"] = self.record.reference_regions
        info["precision_limited"] = [r["case"] for r in headroom.limited(self.record.rows)]
        info["timing"] = self.timing
        if self.resume_previous:
            info["resumed_cases"] = len(self.kept)
            info["stale_cases"] = self.stale       # cases of the folder the config no longer names (kept)
        return info

    def _write_run_json(self, force: bool = False):
        """run.json now: ``force`` (a run's end, whatever its state), else while running at most every
        RUN_JSON_EVERY_S."""
        if self.state == "task":      # one map group of a cluster run: its driver writes run.json
            return
        # while running, at most every RUN_JSON_EVERY_S (compact): each write is the whole record,
        # and after every case they took a third of the default experiment's measuring time;
        # indented once the run has ended
        now = time.perf_counter()
        if self.state == "running" and not force and now - self.run_json_at < RUN_JSON_EVERY_S:
            return
        self.run_json_at = now
        report_io.write_json(self.out / "run.json", self._run_json(), None if self.state == "running" else 1)


def peak_rss() -> int:
    """This process's peak resident memory so far, in bytes: Linux's VmHWM (of this program's own
    address space: getrusage's ru_maxrss keeps the parent's size across fork and exec), else
    ru_maxrss (kilobytes, bytes on macOS)."""
    import resource
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(rss if sys.platform == "darwin" else rss * 1024)


def _cpu() -> float:
    """CPU seconds of this process (every thread) and of its finished children (the drawing workers)."""
    import resource
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ru.ru_utime + ru.ru_stime


def _map_arrays(scene, view, needs, culling="none", closed=None, tile=None, extents=None):
    smap = pipeline.build_map(scene, view, needs, culling, closed, tile, extents)
    return (*shadowmap.arrays(smap), smap)


def run(config, out=None, variant=None, progress=False) -> Results:
    """Run an experiment (a Config, a dict or a path to a TOML file) and return its Results."""
    config = pipeline.prepare(config, variant)
    if out is None:
        import tempfile
        out = Path(tempfile.mkdtemp(prefix=f"dsm-{config.name}-"))
    return Runner(config, Path(out), variant, progress).run()
