"""The runner: a loop over the plan's maps, with the failure policy, timing and the report.

The plan (:mod:`dsm.config.plan`) lists the maps in order: scene, light, view, resolution, culling.
The runner walks it, doing each shared stage once through :mod:`dsm.pipeline` (the G-buffer
per scene, receivers and the exact reference per light, receivers per view, one map per
culling choice with the layers its schemes need) and each case (a scheme instance, filter and
format on a map) as a value: :func:`dsm.case.evaluate` gives its lookup, counts and class
image, :mod:`dsm.case.row` its row, and the run's sink (:mod:`dsm.experiment.sink`) writes them.

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
from dataclasses import dataclass, field
from pathlib import Path

import drjit as dr
import numpy as np

from .. import pipeline
from ..case import Case, MapContext, evaluate, row as case_row
from ..case.row import BuildCost
from ..config import plan as planmod, read as cfgmod
from ..core import env, record, timing
from ..maps import headroom, shadowmap
from ..report import publish, tables as report, io as report_io
from . import display, motion, motion_display, resume, wavefront
from .builds import Builds
from .contexts import Contexts, SceneRun, ViewRun
from .results import Results
from .sink import Sink


RUN_JSON_EVERY_S = 1.0
# run.json's note on a run measured without its report (dsm run --no-report, dsm.run(report=False))
NO_REPORT_NOTE = ("not drawn (--no-report): `dsm report <folder>` draws the figures, table.md and report.html from "
                  "the run's files (display renders and motion GIFs need a run with its report)")


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
    """Runs a config's plan into folder ``out``: each shared stage once, then each case through
    :func:`dsm.case.evaluate` into the run's sink (dsm.experiment.sink)."""
    def __init__(self, config: cfgmod.Config, out: Path, variant: str | None = None, progress: bool = True,
                 keep_images: bool = True, resume_previous: bool = False, files: bool = True,
                 report: bool = True):
        self.cfg = config
        self.out = Path(out)
        self.variant = env.use_variant(variant or config.variant)
        self.progress = progress
        self.plan = planmod.make(config)
        self.record = record.RunRecord()     # everything measured: rows, statuses, maps, rays, oracles ...
        # files=False: metrics.csv and run.json only (no image, data file or report): a caller that
        # reads the Results and throws the folder away (dsm benchmark's cases)
        self.files = files
        # report=False: the measurements and data files without the composed report (figures, GIFs, display
        # renders, table.md, report.html), which dsm report draws later from the files; a caller that reads the
        # numbers (a pytest threshold) skips the drawing, most of a small run's time
        self.report = report
        self.sink = Sink(self.out, self.record, config.report_images, keep_images, files)
        self.builds = Builds(config, self.record)
        self.case_no = 0
        self.cases_kept = 0           # rows written again from the run being resumed (not measured here)
        self.versions = env.versions()
        self.state = "running"
        self.bar = None
        self.timing = {}              # seconds measuring and writing the report
        self.plan_dict = None         # run.json's plan, made once
        self.run_json_at = -math.inf  # when run.json was last written (perf_counter seconds)
        # case ids and identity keys from the plan (dsm.experiment.resume); a resumed run reuses matching cases
        self.keys = dict(resume.case_keys(config, self.plan, resume.kit_version(self.versions)))
        self.first_case = list(itertools.accumulate((m.cases for m in self.plan.maps), initial=0))
        self.resume_previous = resume_previous
        self.kept, self.stale = {}, []
        self.contexts = Contexts(config, self.record, self.builds, self._fail)

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
            previous = resume.Previous(self.out)
            self._say_versions(previous.versions)
            self.kept, self.stale = previous.arrange(list(self.keys.items()))
        self.sink.open()
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
            self._measured(t0, c0)
            self._write_run_json(force=True)      # a run ended by an error other than Ctrl-C is still "running"
            if self.files:
                publish.write_data(self.out, self.record)
                self._report() if self.report else self._no_report()
                self._write_run_json(force=True)
        return Results(self.out, self.record.rows, self._run_json(), self.sink.images, self.record.oracle_rows,
                       self.record.curves)

    def _say_versions(self, before: dict | None):
        """One line on stderr when the run being resumed ran on other dsm, Mitsuba or Dr.Jit versions."""
        change = env.engine_change(before, self.versions) if before is not None else None
        if change:
            print(f"dsm: --resume: {self.out} was measured with other versions ({change}); results differ bit for "
                  "bit between versions, so its cases run again", file=sys.stderr)

    def _measured(self, t0: float, c0: float):
        """run.json's measuring time, CPU, peak memory and kernel launches (the case images
        are drawn as cases finish, so a killed run keeps them: their time is the report's)."""
        self.timing["measure_s"] = time.perf_counter() - t0 - self.sink.images_s
        self.timing["measure_cpu_s"] = _cpu() - c0 - self.sink.images_cpu_s
        self.timing["measure_peak_rss_bytes"] = peak_rss()     # against the plan's peak_bytes_est
        self.timing["kernel_launches"] = self._launches()

    def _report(self):
        """The report, after every timed measurement, composed from the run's files alone (as
        dsm report does): figures, table.md, cascades.md, report.html."""
        t1, c1 = time.perf_counter(), _cpu()
        self._display_renders()
        self._motion_gifs()
        try:
            self.timing["report_parts"] = publish.write_report(self.out, (), self.record.curves,
                                                               plots=self.state == "complete")
        except Exception as e:          # the measurements are saved; the report can be rebuilt
            self._fail("report (dsm report rebuilds it)", e)
        self.timing["report_s"] = time.perf_counter() - t1 + self.sink.images_s
        self.timing["report_cpu_s"] = _cpu() - c1 + self.sink.images_cpu_s

    def _no_report(self):
        """run.json's report time (the case images drawn as cases finished) and a note saying how to draw the rest."""
        self.timing["report_s"], self.timing["report_cpu_s"] = self.sink.images_s, self.sink.images_cpu_s
        self.record.status.append({"what": "report", "status": "note", "error": NO_REPORT_NOTE})

    def _display_renders(self):
        """Each scene and light's display renders (dsm.experiment.display), in the report's time: a
        complete run that writes every image ([report] images = "all") only; what was left out is a note in
        run.json's status."""
        if self.state != "complete" or self.cfg.report_images != "all" or not (self.out / "metrics.csv").is_file():
            return
        try:
            # the pairs from metrics.csv, the run's data file: a cluster's driver holds no rows of its own
            rows = report_io.read_csv(self.out / "metrics.csv")
            notes = display.write_renders(self.out, self.cfg, {(r["scene"], r["light"]) for r in rows})
        except Exception as e:          # the page falls back to the case's own images
            notes = [f"display renders: {type(e).__name__}: {e}"]
        self.record.status += [{"what": "display render", "status": "note", "error": n} for n in notes]

    def _motion_gifs(self):
        """Each motion case's GIF (dsm.experiment.motion_display), in the report's time: frames of
        display renders in a complete run that writes every image, else the frames' class images."""
        pending, self.record.motion_gifs = self.record.motion_gifs, []
        if not pending:
            return
        display = self.state == "complete" and self.cfg.report_images == "all"
        try:
            notes = motion_display.write_gifs(self.out, self.cfg, pending, display)
        except Exception as e:          # the measurements are saved; a GIF is never worth failing them
            notes = [f"motion GIFs: {type(e).__name__}: {e}"]
        self.record.status += [{"what": "motion GIF", "status": "note", "error": n} for n in notes]

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
        timing.enable_history()        # a task's kernel times come from its own process's kernel history
        self.sink.open()
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
                scene = self._scene(self.cfg.scenes[si], scene_maps)
            except StageFailed:
                continue
            if self.cfg.motion:                 # camera and light paths: dsm.experiment.motion's frame loop
                self._run_motion(scene, scene_maps)
                continue
            for li, light_maps in itertools.groupby(scene_maps, key=lambda m: m.light_index):
                light_maps = list(light_maps)
                try:
                    setup = self._light(scene, li, light_maps)
                except StageFailed:
                    continue
                light = LightMaps.of(self.plan.stacks, light_maps)
                for _, view_maps in itertools.groupby(light_maps, key=lambda m: (m.view, m.resolution, m.cascade)):
                    self._run_view(scene, setup, list(view_maps), light)
            self._write_run_json()

    def _run_motion(self, scene: SceneRun, maps):
        """Every [[motion]] path over one scene's maps (dsm.experiment.motion), a failure the scene's."""
        label = scene.data.label
        try:
            self._stage(f"motion of scene {label}", maps, lambda: motion.run_scene(
                self, scene, maps, self.builds.closed(scene.data), self.builds.extents[label]))
        except StageFailed:
            pass
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
    def _scene(self, spec, maps) -> SceneRun:
        def load():
            """The scene loaded, its G-buffer (timed) and its usable lights; ValueError when it has none."""
            data = pipeline.load_checked_scene(spec, self.cfg.camera_resolution, self.cfg.camera)
            out, t = timing.measure(lambda: (pipeline.gbuffer(data),), 0)
            gbuffer = out[-1]
            gbuffer.ms = t.ms
            lights = data.lights_for(self.cfg.lights)
            if not lights:
                raise ValueError("the scene has no usable point/spot/directional emitter and the config names "
                                 "no [[light]]")
            return SceneRun(data, gbuffer, lights)
        scene = self._stage(f"scene {spec.label}", maps, load)
        data, gbuffer = scene.data, scene.gbuffer
        self.record.gbuffer_ms[data.label] = gbuffer.ms
        self.builds.scene_loaded(data)
        self.record.rays["gbuffer"] += gbuffer.width * gbuffer.height
        if data.notes:
            self.record.status.append({"what": f"scene {data.label}", "status": "note", "error": "; ".join(data.notes)})
        return scene

    def _light(self, scene: SceneRun, li: int, maps):
        label, data = maps[0].light, scene.data

        def setup():
            """The light setup (receivers and exact reference) of light ``li`` of the loaded scene."""
            if li >= len(scene.lights):
                raise ValueError(f"the plan expects light {label} but the loaded scene has {len(scene.lights)} lights")
            return pipeline.light_setup(data, scene.gbuffer, scene.lights[li], label, self.cfg.timing_repeats,
                                        self.cfg.seed)
        out = self._stage(f"scene {data.label} light {label}", maps, setup)
        self.record.rays["reference"] += out.reference_rays       # one per receiver, or an area light's samples
        if out.ref is not None:
            self.record.reference_regions.append({"scene": data.label, "light": label, **out.ref.stats()})
        return out

    def _view(self, scene: SceneRun, setup, light, m):
        """The view of map plan ``m`` fitted to the light's receivers: once per kind and resolution of
        the light (a stacked map's and its view group's are one object), a cascaded view each time."""
        key = (m.view, m.resolution)
        if m.cascade is None and key in light.views:
            return light.views[key]
        data = scene.data
        pts = pipeline.points_np(setup.p) if setup.p is not None else np.zeros((0, 3))
        view = pipeline.make_view(setup.light, m.resolution, pts, data.bbox, m.view, m.cascade, data.sensor, data.scale)
        if setup.light.shape == "emitter":      # SMRT's ray targets: the luminaire's triangles, which need the scene
            view.light_surface = pipeline.area_geometry(setup.light, data.scene)
        if m.cascade is None:
            light.views[key] = view
        return view

    def _built(self, scene: SceneRun, setup, light, m):
        """Map plan ``m``'s Built when the plan stacks it ([timing] builds = "together"), its stack built
        when its first map comes up; None: built alone (a stack that fails is noted, its maps built alone)."""
        stack_plans = light.stack_of.get(id(m))
        if stack_plans is None:
            return None
        if id(stack_plans[0]) not in light.tried:
            light.tried.add(id(stack_plans[0]))
            try:
                views = [self._view(scene, setup, light, x) for x in stack_plans]
                light.built.update(zip(map(id, stack_plans),
                                       self.builds.stack(scene.data, views, stack_plans, setup.light.type)))
            except KeyboardInterrupt:
                raise
            except Exception as e:
                self.record.status.append({"what": f"scene {scene.data.label} light {setup.label} view "
                                           f"{stack_plans[0].view} maps "
                                           + "+".join(str(x.resolution) for x in stack_plans) + " built together",
                                           "status": "note", "error": f"{type(e).__name__}: {e}; built alone"})
        return light.built.pop(id(m), None)          # the map's own from here: freed after its cases

    def _run_view(self, scene: SceneRun, setup, maps, light):
        """One view and resolution of a light: its receivers, then each of its maps (one per culling);
        ``light``: the light's views and maps built together (LightMaps)."""
        kind, R = maps[0].view, maps[0].resolution

        def receivers() -> ViewRun:
            """The fitted view, the receivers inside it, their lookups and seams, the attached-shadow pixels."""
            view = self._view(scene, setup, light, maps[0])
            inside = setup.subset(view.inside(setup.p).numpy().astype(bool)) if setup.p is not None else setup
            rx = seam = None
            if inside.p is not None and len(inside.pixels):
                rx = pipeline.receivers(view, inside, scene.data.diagonal)
                seam = view.seam_distance(rx.u_map, rx.v_map, rx.face)
                dr.eval(rx.depth, rx.u_map, rx.v_map, rx.face, rx.texel_world, rx.to_light, seam)
                seam = seam.numpy()
            return ViewRun(view, inside, rx, seam, inside.backfacing_inside(view))
        try:
            where = f"scene {scene.data.label} light {setup.label} view {kind} map {R}"
            view_run = self._stage(where, maps, receivers)
        except StageFailed:
            return
        first_layer = None
        for m in maps:
            try:
                # a stack's other views are fitted to the receivers inside this one
                built = self._built(scene, view_run.setup, light, m)
                first_layer = self._run_map(scene, view_run, m, first_layer, built)
            except StageFailed:
                continue

    # ------------------------------------------------------------ one map
    def _map_build(self, scene: SceneRun, view_run: ViewRun, m, built) -> tuple:
        """(map, build Timing, stored copy per format) of map plan ``m``: built and timed alone (with its
        peak bytes), or ``built`` in a stack (dsm.experiment.stacks); a failure is the map's stage's."""
        def build():
            """(map, build time, stored): the map and its copy per stored format."""
            if built is not None:
                smap, build_time = built.smap, built.times[frozenset(m.needs)]
            else:
                smap, build_time = self.builds.alone(scene.data, view_run.view, m)
            return smap, build_time, {fmt: pipeline.store(smap, fmt) for fmt in self.cfg.map.format}
        what = (f"scene {scene.data.label} light {view_run.setup.label} view {view_run.view.kind} map {m.resolution} "
                f"culling {m.culling}")
        return self._stage(what, [m], build)

    def _run_map(self, scene: SceneRun, view_run: ViewRun, m, first_layer, built=None):
        """Build one map (the plan's layers, culling and tile), store its formats, run its cases.
        ``first_layer``: (the first layer's build time, maps sharing it) from the view's first map, or
        None; ``built``: the map built in a stack (dsm.experiment.stacks), or None. Returns ``first_layer``."""
        smap, build_time, stored = self._map_build(scene, view_run, m, built)
        self._record_map(scene.data, view_run, m, smap, build_time)
        self.record.quantized += sum(1 for fmt in self.cfg.map.format if fmt != "float32")
        ctx = self.contexts.make(scene, view_run, m, smap, stored)
        build_times = dict(built.times) if built is not None else {frozenset(m.needs): build_time}
        # the first layer without culling, so a case's extra layers show as build_ms - build_first_ms:
        # a stacked map's share of its stack's; a map alone its own, measured once a view group
        if built is not None:
            first_layer = (built.first, built.shared)
        elif first_layer is None or first_layer[1] > 1:
            first_layer = (build_time if m.culling == "none" and not m.needs
                           else self.builds.timed(scene.data, view_run.view, set(), "none", m.tile)[1], 1)
        self.case_no = self.first_case[self.plan.maps.index(m)]     # case ids from the plan
        specs = [pipeline.preset_for_light(spec, view_run.setup.light.type) for spec in m.specs]   # a preset's values here
        depth = {spec: [self._next(spec, filt, fmt, h) for filt in self.cfg.map.filter for fmt in self.cfg.map.format
                        for h in resume.hybrids(self.cfg)] for spec in specs}
        attached, looked = self._lookups(ctx, [c for cases in depth.values() for c in cases])
        for spec, cases in depth.items():
            own = frozenset(pipeline.needs_of([spec]))                  # this instance's own layers, for build_ms
            if own not in build_times:
                # the build of exactly what this scheme needs (its data comes from the shared map)
                build_times[own] = self.builds.timed(scene.data, view_run.view, own, m.culling, m.tile)[1]
            cost = BuildCost(build_times[own], first_layer[0], smap.peak_bytes, smap.shared)
            for case in cases:
                self._run_case(ctx, case, cost, looked.get(case.lookup_key), attached.get(case.lookup_key))
                self.bar.update(1)
        # a pre-filtered instance's build_ms: the depth map's first layer, which its moments are made of
        cost = BuildCost(first_layer[0], first_layer[0], smap.peak_bytes, smap.shared)
        for spec in m.moments:
            for fmt in self.cfg.map.format:
                self._run_case(ctx, self._next(spec, spec.filter, fmt), cost)
                self.bar.update(1)
        return first_layer

    def _next(self, spec, filt: str, fmt: str, hybrid=None) -> Case:
        """The next case of the plan: its id counted."""
        self.case_no += 1
        return Case(f"{self.case_no:04d}", spec, filt, fmt, hybrid)

    def _lookups(self, ctx: MapContext, cases: list) -> tuple:
        """(attached, looked) of one map's depth cases not kept from a resumed run, by (spec, filter,
        format): with ``[timing] lookups = "wavefront"`` every lookup from the map's wavefront
        (dsm.experiment.wavefront; its wave time into the map's record), else each case times its
        own lookup and only its attached-shadow V and plane fallbacks come from one wavefront."""
        # a lookup once however many hybrid instances its case runs with
        family = list(dict.fromkeys(c.lookup_key for c in cases))
        todo = list(dict.fromkeys(c.lookup_key for c in cases if self.keys.get(c.id) not in self.kept))
        if self.cfg.timing_lookups == "per_case":
            return wavefront.attached_only(todo, ctx.stored, ctx.receivers, ctx.backfacing, ctx.seed), {}
        looked, wave = wavefront.run(todo, ctx.stored, ctx.receivers, ctx.backfacing, ctx.seed, ctx.repeats, family)
        self.record.maps[-1].update(wave)
        return {}, looked

    def _record_map(self, scene, view_run: ViewRun, m, smap, build_time):
        """The map's record in run.json (its layers, tiles, rays, build) and its rays counted."""
        self.record.maps.append({"scene": scene.label, "light": view_run.setup.label, "view": view_run.view.kind,
                                 "resolution": m.resolution, "culling": m.culling,
                                 "layers": ["z1", "shape"] + [k for k in shadowmap.LAYERS if getattr(smap, k) is not None],
                                 "tiles": smap.tiles, "rays": dict(smap.rays), "rehits": smap.rehits,
                                 "build_shared": smap.shared,
                                 "build_ms": build_time.ms,      # its layers' build, kernel time (a stacked map's: its share)
                                 "build_peak_bytes": smap.peak_bytes, "build_peak_bytes_est": m.peak_bytes,
                                 "formats": list(m.formats)})
        self.record.add_rays(smap.rays)
        if smap.unfinished:
            self.record.status.append({"what": f"map {scene.label} {view_run.setup.label} R={m.resolution} "
                                               f"culling={m.culling}",
                                       "status": "warning", "error": f"{smap.unfinished} texels still searching "
                                       f"after {shadowmap.MAX_STEPS} surfaces"})

    # ------------------------------------------------------------ one case
    def _run_case(self, ctx: MapContext, case: Case, cost: BuildCost, looked=None, attached=None):
        """One case evaluated (dsm.case.evaluate) into the sink, or its row again when the run being
        resumed finished it; ``looked``/``attached``: its lookups from the map's wavefront."""
        if self.keys.get(case.id) in self.kept:          # finished by the run being resumed: its row again
            row, status, cascade_rows = self.kept[self.keys[case.id]]
            self.record.cascade_rows += cascade_rows
            self.sink.add(resume.parse_row(row), status)
            self.cases_kept += 1
            self._write_run_json()
            return
        ident = case_row.identity(ctx.where, case)
        try:
            result = evaluate(ctx, case, looked, attached)
            sweep = self.cfg.map.moments if case.prefiltered else self.cfg.schemes
            extra = case_row.sweep_columns(case.spec, sweep)
            if self.cfg.map.leak_split:          # [map] kind given: every case's map kind
                extra.update(case_row.map_kind_columns(case, result.moments.ms if result.moments else None))
            row = case_row.row(ident, case_row.still_measured(ctx, result),
                               {**case_row.still_costs(ctx, result, cost), **extra})
            self.sink.still_case(ctx, ident, result)
            # a case without receivers says nothing about the scheme: it is reported as empty
            status = {k: ident[k] for k in ("scene", "light", "view", "scheme", "params", "resolution")}
            self.sink.add(row, {"what": f"case {case.id}", **status, "status": "ok" if result.n_receivers else "empty",
                                "key": self.keys.get(case.id)})
            self._write_run_json()
        except Exception as e:
            spec = case.spec
            self._fail(f"case {case.id} ({ctx.where.scene}, {ctx.setup.label}, {spec.name} {spec.label}, "
                       f"R={ctx.view.resolution})", e)

    def next_case(self) -> str:
        """The next case's id ("0001", ...), counted (motion's cases, in the plan's order)."""
        self.case_no += 1
        return f"{self.case_no:04d}"

    def case_done(self, row: dict, status: dict):
        """A finished case's row and status into the sink, and the progress bar moved on by one."""
        self.sink.add(row, status)
        self.bar.update(1)

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


def run(config, out=None, variant=None, progress=False, report: bool = True) -> Results:
    """Run an experiment (a Config, a dict or a path to a TOML file) and return its Results; without
    ``out``, in a temporary folder removed once the Results is no longer referenced; ``report=False``:
    no figures or report.html (dsm report draws them later from the folder)."""
    config = pipeline.prepare(config, variant)
    if out is None:
        # a folder of its own, kept while the Results lives (its images are what a failing test names)
        # and removed with it: no folder per call left behind; Results.out says where it is
        import shutil
        import tempfile
        import weakref
        out = Path(tempfile.mkdtemp(prefix=f"dsm-{config.name}-"))
        res = Runner(config, out, variant, progress, report=report).run()
        weakref.finalize(res, shutil.rmtree, out, True)
        return res
    return Runner(config, Path(out), variant, progress, report=report).run()
