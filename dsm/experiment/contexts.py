"""The MapContext of each still map of a run (dsm.case.context): its receivers per stored format,
the oracles (oracle.csv, the curves, and the per-texel oracle's ``wrong`` each nearest case's
split reads), its pre-filtered instances' moment maps and the contact march, each made once."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import pipeline
from ..case import MapContext, Where
from ..contact import march as contact
from ..core import record, timing
from ..maps.receiver import Receiver
from .builds import Builds


@dataclass
class SceneRun:
    """One loaded scene as its maps share it: its data, the camera's G-buffer and its usable lights."""
    data: object          # dsm.scenes.data.SceneData
    gbuffer: object       # dsm.scenes.gbuffer.GBuffer
    lights: list          # LightSpec per usable light


@dataclass
class ViewRun:
    """One view and resolution of a light, as its maps share it."""
    view: object
    setup: object                 # the light set-up inside the view
    receivers: Receiver | None    # in the view's depth function; None without receivers
    seam_texels: np.ndarray | None
    backfacing: tuple             # the attached-shadow pixels inside the view: (positions, normals) or (None, None)


class Contexts:
    """Makes a run's map contexts; ``fail(what, exception)`` records a failure that costs no case
    (an oracle's: its map's nearest cases go on without the resolution/bias split)."""

    def __init__(self, config, run_record: record.RunRecord, builds: Builds, fail):
        self.cfg = config
        self.record = run_record
        self.builds = builds
        self.fail = fail
        self.depth_buffer = (None, None)   # [contact]: (scene label, its camera depth buffer), made when a case asks
        self.marched = (None, None)        # [contact]: (receivers, (occluded, Timing)) of the last march

    def make(self, scene: SceneRun, view_run: ViewRun, m, smap, stored) -> MapContext:
        """What the map's cases share: receivers in the depth function each stored format compares
        in (formats.stored_view; formats sharing one share them), the oracles, moments and march."""
        data, setup, view = scene.data, view_run.setup, view_run.view
        back_p, back_n = view_run.backfacing
        by_view = {}
        for fmt in stored:
            v = stored[fmt].view
            if id(v) not in by_view:
                front = (view_run.receivers if view_run.receivers is None or v is view
                         else Receiver.make(v, setup.p, setup.n, data.diagonal, setup.camera))
                back = Receiver.make(v, back_p, back_n, data.diagonal, setup.camera) if back_p is not None else None
                by_view[id(v)] = (front, back)
        cascade_layout = view.spec.label if view.cascaded or view.virtual else ""
        where = Where(data.label, setup.label, view.kind, view.resolution, view.n_texels, smap.culling, cascade_layout)
        measures = {"seams", "split", "attached", "cascade"} | ({"contact"} if self.cfg.contact is not None else set())
        ctx = MapContext(where, data, scene.gbuffer, setup, view, smap, stored,
                         {fmt: by_view[id(stored[fmt].view)][0] for fmt in stored}, self.cfg.seed,
                         self.cfg.timing_repeats, frozenset(measures | ({"leak"} if self.cfg.map.leak_split else set())),
                         backfacing={fmt: by_view[id(stored[fmt].view)][1] for fmt in stored},
                         seam_texels=view_run.seam_texels, leak_texels=self.cfg.map.leak_texels,
                         moments=self._moments(scene.data, smap), march=lambda rx: self._march(scene, setup, rx))
        ctx.wrong = {fmt: self._oracles(ctx, m, fmt) for fmt in stored}
        return ctx

    def _moments(self, scene, smap):
        """A function (spec, format) -> (MomentMap, build Timing) on ``smap``, built (timed) once per
        moment key; a supersampled instance's build casts its own rays (timed with it)."""
        cache = {}                    # instances sharing their moments share one build (dsm.prefilter)

        def get(spec, fmt):
            """The cached build, made on first use (inside the case's failure policy)."""
            key = pipeline.moment_key(spec, fmt)
            if key not in cache:
                def build():
                    """The moment map's arrays (evaluated by the clock) and the map."""
                    fine = None if spec.samples == 1 else pipeline.supersampled_map(
                        self.builds.casters(scene), smap.view, spec.samples, self.builds.extents[scene.label])
                    mm = pipeline.moment_map(spec, smap, fmt, fine)
                    return (*mm.b, mm)
                out, t = timing.measure_calls(build, self.cfg.timing_repeats)
                if spec.samples > 1:        # one build's rays (the timed repeats cast them again)
                    self.record.add_rays({"map_texel": smap.view.n_texels * spec.samples ** 2})
                cache[key] = (out[-1], t)
            return cache[key]
        return get

    def _march(self, scene: SceneRun, setup, rx) -> tuple:
        """(occluded per receiver, its Timing) of the contact march of receivers ``rx``: once per
        receiver set (the march reads receivers and light only: every case of them shares it)."""
        if self.depth_buffer[0] != scene.data.label:     # the current scene's only: the runner walks scene by scene
            self.depth_buffer = (scene.data.label, contact.depth_buffer(scene.gbuffer))
        if self.marched[0] is not rx:      # the receivers kept: their id stays theirs
            light_world = setup.light.position if pipeline.is_positional(setup.light) else None
            out, t = timing.measure(lambda: (contact.march(self.depth_buffer[1], rx, self.cfg.contact, self.cfg.seed,
                                                           light_world),), self.cfg.timing_repeats)
            self.marched = (rx, (out[-1].numpy().astype(bool), t))
        return self.marched[1]

    def _oracles(self, ctx: MapContext, m, fmt: str):
        """The oracles of one map and stored format over the view's receivers (oracle.csv, the
        trade-off curves); returns per receiver whether the per-texel oracle at the first lambda
        gets it wrong (the resolution's share of a nearest case's errors), None on failure."""
        rx, setup, view = ctx.receivers[fmt], ctx.setup, ctx.view
        if rx is None:
            return np.zeros(0, bool)
        if setup.ref is not None or not view.depth_oracles:
            return None               # an area light (the oracles are a hard V*'s); a VSV grid (no depth bias)
        meta = {"scene": ctx.where.scene, "light": setup.label, "view": view.kind, "resolution": m.resolution,
                "culling": m.culling, "format": fmt}
        try:
            th = pipeline.thresholds(rx, ctx.stored[fmt])
            wrong = None
            for lam in self.cfg.oracle.lambdas:
                o = pipeline.oracles(th, setup.v_star, lam)
                row = {**meta, **o["row"]}
                self.record.oracle_rows.append(row)
                if wrong is None:
                    wrong = o["wrong"]
                    self.record.curves.append((row, o["curve_world"], o["curve_texel"]))
            return wrong
        except Exception as e:       # recorded; the map's nearest cases go on without the split
            self.fail(f"oracles of scene {ctx.where.scene} light {setup.label} view {view.kind} map {m.resolution} "
                       f"culling {m.culling} format {fmt}", e)
            return None
