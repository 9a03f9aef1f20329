"""A run's map builds: the scene the maps are cast against, per-shape closedness and error
extents (once per scene), and each map built and timed, alone or in a stack (dsm.experiment.stacks)."""
from __future__ import annotations

from .. import pipeline
from ..core import record, timing
from ..maps import shadowmap
from . import stacks


class Builds:
    """Builds the plan's maps of a run, in kernel time (``[timing] repeats`` calls); per scene
    once: its shrunk copy ([map] shrink), closedness (into run.json's scenes) and extents."""

    def __init__(self, config, run_record: record.RunRecord):
        self.cfg = config
        self.record = run_record
        self.extents = {}             # per scene: the spawn bound's per-shape extents
        self.shrunk = (None, None)    # [map] shrink: (scene label, its shrunk copy)

    def scene_loaded(self, scene):
        """A scene's per-shape extents, once, outside the timed builds."""
        self.extents[scene.label] = pipeline.spawn_extents(scene.scene)

    def closed(self, scene) -> list:
        """Per-shape closedness, computed once per scene and recorded in run.json."""
        for info in self.record.scene_info:
            if info["scene"] == scene.label:
                return [s["closed"] for s in info["shapes"]]
        closed, why = pipeline.closedness(scene)
        self.record.scene_info.append({"scene": scene.label, "shapes": [
            {"name": n, "closed": c, "why": w} for n, c, w in zip(scene.shape_names, closed, why)]})
        return closed

    def casters(self, scene):
        """The scene the maps are cast against: the scene, or its copy shrunk by ``[map] shrink`` (once per scene)."""
        if self.cfg.shrink is None:
            return scene.scene
        if self.shrunk[0] != scene.label:
            self.shrunk = (scene.label, pipeline.shrunk_scene(scene.scene, self.cfg.shrink))
        return self.shrunk[1]

    def timed(self, scene, view, needs, culling: str, tile) -> tuple:
        """(the map's arrays and the map, its build Timing) of ``view`` with layers ``needs``."""
        closed = self.closed(scene) if culling != "none" else None
        extents, casters = self.extents[scene.label], self.casters(scene)

        def build():
            """The map's arrays (evaluated by the clock) and the map."""
            smap = pipeline.build_map(casters, view, needs, culling, closed, tile, extents)
            return (*shadowmap.arrays(smap), smap)
        return timing.measure_kernel(build, self.cfg.timing_repeats)

    def alone(self, scene, view, map_plan) -> tuple:
        """(map, build Timing) of map plan ``map_plan`` built alone, with its peak bytes."""
        timing.reset_peak()
        out, build_time = self.timed(scene, view, set(map_plan.needs), map_plan.culling, map_plan.tile)
        smap = out[-1]
        smap.peak_bytes = timing.peak_bytes()
        return smap, build_time

    def stack(self, scene, views, stack_plans, light_type) -> list:
        """Each map of a stack built together and timed (dsm.experiment.stacks.Built)."""
        own = {frozenset(pipeline.needs_of([pipeline.preset_for_light(spec, light_type)]))
               for m in stack_plans for spec in m.specs}
        casters, culling = self.casters(scene), stack_plans[0].culling
        closed = self.closed(scene) if culling != "none" else None
        modes = (culling, pipeline.map_cull_modes(casters, views[0], culling, closed),
                 pipeline.map_cull_modes(casters, views[0]))
        return stacks.build(casters, views, stack_plans[0].needs, modes, own, self.extents[scene.label],
                            self.cfg.timing_repeats)
