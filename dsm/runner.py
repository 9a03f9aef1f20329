"""The runner: config -> shared work -> cases -> results folder.

Shared work is done once: the G-buffer per scene/camera, the receivers and exact reference
per scene/light, one map per light/resolution with only the attributes the named schemes
need. Each case (scheme instance on a map) is a lookup, metrics, an error image and a row of
metrics.csv. A failing case or map is recorded in run.json and the others still run; rows
are written as they finish, so nothing done is lost.
"""
from __future__ import annotations

import sys
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from . import config as cfgmod
from . import env, formats, gbuffer, metrics, reference, report, scenes, schemes, shadowmap, timing
from . import plan as planmod
from . import lookup
from .lookup import Receiver, visibility
from .views import CubeView, OrthographicView, ParaboloidView, PerspectiveView


@dataclass
class LightSetup:
    """Receivers and exact visibility of one scene from one light."""
    label: str
    light: object                 # LightSpec
    pixels: np.ndarray            # pixel index of each receiver
    p: object                     # receiver positions (mi.Point3f), normals, shapes
    n: object
    shape: np.ndarray
    v_star: np.ndarray
    occluder_dist: np.ndarray
    exclusions: dict
    reference_ms: float
    si: object = None
    back_p: object = None         # hit pixels facing away from the light (attached shadow), inside its domain
    back_n: object = None

    def backfacing_inside(self, view):
        """(positions, normals) of the back-facing pixels inside ``view``, or (None, None)."""
        if self.back_p is None:
            return None, None
        keep = view.inside(self.back_p).numpy().astype(bool)
        if not keep.any():
            return None, None
        idx = mi.UInt32(np.flatnonzero(keep).astype(np.uint32))
        p, n = dr.gather(mi.Point3f, self.back_p, idx), dr.gather(mi.Vector3f, self.back_n, idx)
        dr.eval(p, n)
        return p, n

    def subset(self, keep: np.ndarray) -> "LightSetup":
        """The receivers ``keep`` selects; the others count as outside the view's domain."""
        if keep.all():
            return self
        ex = dict(self.exclusions)
        ex["n_excluded_outside"] += int((~keep).sum())
        if not keep.any():
            return LightSetup(self.label, self.light, self.pixels[keep], None, None, self.shape[keep],
                              self.v_star[keep], self.occluder_dist[keep], ex, self.reference_ms)
        idx = mi.UInt32(np.flatnonzero(keep).astype(np.uint32))
        p, n = dr.gather(mi.Point3f, self.p, idx), dr.gather(mi.Vector3f, self.n, idx)
        dr.eval(p, n)
        return LightSetup(self.label, self.light, self.pixels[keep], p, n, self.shape[keep], self.v_star[keep],
                          self.occluder_dist[keep], ex, self.reference_ms)


@dataclass
class Results:
    """What a run produced: the rows of metrics.csv, run.json's content and the images."""
    out: Path
    rows: list
    run: dict
    images: dict = field(default_factory=dict)   # case id -> class image (H, W) uint8

    def where(self, **kw) -> "Results":
        rows = [r for r in self.rows if all(r.get(k) == v for k, v in kw.items())]
        return Results(self.out, rows, self.run, {r["case"]: self.images.get(r["case"]) for r in rows})

    def column(self, name) -> np.ndarray:
        return np.array([r[name] for r in self.rows])

    def rgb(self, case) -> np.ndarray:
        """The case's error image as (H, W, 3) uint8 in the report's colours."""
        if isinstance(case, dict):
            case = case["case"]
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


VIEW_FACES = planmod.VIEW_FACES
views_for = planmod.views_for


def make_view(light, R, receivers_world, bbox, kind=None):
    if light.type == "directional":
        return OrthographicView(light.direction, receivers_world, bbox, R)
    if light.type == "spot":
        axis = light.direction if light.direction is not None else np.subtract(light.target, light.position)
        return PerspectiveView(light.position, axis, light.cutoff, bbox, R)
    if light.type == "point":
        axis = light.direction if light.direction is not None else (0.0, 0.0, -1.0)
        if kind in ("paraboloid", "dual_paraboloid"):
            return ParaboloidView(light.position, axis, bbox, R, dual=kind == "dual_paraboloid")
        if kind == "cube":
            return CubeView(light.position, bbox, R)
        raise ValueError(f"unknown point-light view {kind!r} (valid: paraboloid, dual_paraboloid, cube)")
    raise ValueError(f"light type {light.type!r} has no view")


def light_setup(sd, gb, light, label, repeats: int = 0) -> LightSetup:
    """Receivers of one light (hit pixels facing it, inside its domain) and their exact visibility."""
    p_all, n_all = gb.p, gb.n
    probe = make_view(light, 1, np.zeros((1, 3)), sd.bbox, "cube")   # a point light lights every direction
    to_light = probe.to_light(p_all)
    facing = (dr.dot(n_all, to_light) > 0).numpy().astype(bool)
    inside = probe.inside(p_all).numpy().astype(bool) if light.type != "directional" else np.ones_like(facing)
    hit = gb.hit
    mask = hit & facing & inside
    pixels = np.flatnonzero(mask).astype(np.uint32)
    exclusions = {"n_pixels": int(mask.size), "n_excluded_nohit": int((~hit).sum()),
                  "n_excluded_backfacing": int((hit & ~facing).sum()),
                  "n_excluded_outside": int((hit & facing & ~inside).sum())}
    back = np.flatnonzero(hit & ~facing & inside).astype(np.uint32)
    back_p = back_n = None
    if len(back):
        bidx = mi.UInt32(back)
        back_p, back_n = dr.gather(mi.Point3f, gb.p, bidx), dr.gather(mi.Vector3f, gb.n, bidx)
        dr.eval(back_p, back_n)
    if len(pixels) == 0:      # nothing faces this light: an empty case, no zero-sized kernels
        empty = np.zeros(0)
        return LightSetup(label, light, pixels, None, None, empty.astype(np.uint32), empty.astype(bool),
                          empty, exclusions, 0.0, None, back_p, back_n)
    idx = mi.UInt32(pixels)
    si = dr.gather(mi.SurfaceInteraction3f, gb.si, idx)
    p = dr.gather(mi.Point3f, gb.p, idx)
    n = dr.gather(mi.Vector3f, gb.n, idx)
    magnitude = reference.scene_magnitude(sd.bbox)
    (vis, dist), t = timing.measure(lambda: reference.visibility(sd.scene, si, light, magnitude), repeats)
    dr.eval(p, n)
    return LightSetup(label, light, pixels, p, n, gb.shape.numpy()[pixels], vis.numpy().astype(bool),
                      dist.numpy(), exclusions, t.ms, si, back_p, back_n)


def closed_flags(sd) -> list:
    """Per-shape closedness of a scene (detected, or set by the config), computed once."""
    if sd.closed is None:
        from .closedness import shape_closedness
        over = dict(sd.closed_override)
        sd.closed, sd.closed_reason = [], []
        for name, shape in zip(sd.shape_names, sd.scene.shapes()):
            closed, why = shape_closedness(shape)
            if closed and "wound inward" in why:
                # its solid is everything outside it: a light outside (a spot above a room) would
                # see through its back faces, so culling leaves it whole, as an open surface
                closed, why = False, why + "; culling treats it as open"
            if name in over:
                closed, why = over[name], f"set by the config (detected: {why})"
            sd.closed.append(closed)
            sd.closed_reason.append(why)
    return sd.closed


class Runner:
    def __init__(self, config: cfgmod.Config, out: Path, variant: str | None = None, progress: bool = True,
                 keep_images: bool = True):
        self.cfg = config
        self.out = Path(out)
        self.variant = env.use_variant(variant or config.variant)
        self.progress = progress
        self.keep_images = keep_images
        self.plan = planmod.make(config)
        self.rays = {"gbuffer": 0, "reference": 0, "map_texel": 0, "map_continue": 0}
        self.maps = []
        self.scene_info = []
        self.gbuffer_ms = {}
        self.status = []
        self.rows = []
        self.images = {}
        self.case_no = 0
        self.quantized = 0            # quantized map copies made (stored formats other than float32)
        self.versions = report.versions()
        self.state = "running"

    # ------------------------------------------------------------ top level
    def run(self) -> Results:
        """Run every case. run.json is rewritten (atomically) after each case with the run's state:
        ``running``, then ``complete``, or ``interrupted`` after Ctrl-C (re-raised once the
        folder says what it holds); a killed run leaves ``running`` and every finished case."""
        timing.enable_history()
        self.out.mkdir(parents=True, exist_ok=True)
        (self.out / "images").mkdir(exist_ok=True)
        self.csv = report.CsvWriter(self.out / "metrics.csv")
        self.state = "running"
        self._write_run_json()
        bar = report.progress(total=self.plan.cases, enabled=self.progress)
        try:
            self._run_scenes(bar)
        except KeyboardInterrupt:
            self.state = "interrupted"
            raise
        else:
            self.state = "complete"
        finally:
            bar.close()
            self._write_run_json()
            report.write_table(self.out / "table.md", self.rows, self.cfg, self.status)
            if self.state == "complete":
                report.write_plots(self.out / "plots", self.rows)
                report.write_pareto(self.out / "plots", self.rows)
        return Results(self.out, self.rows, self._run_json(), self.images)

    def _run_scenes(self, bar):
        for spec in self.cfg.scenes:
            if spec.missing:
                self.status.append({"what": f"scene {spec.label}", "status": "skipped", "error": spec.missing})
                continue
            try:
                sd = scenes.load(spec, self.cfg.camera_resolution)
            except Exception as e:
                self._fail(f"scene {spec.label}", e)
                continue
            self._run_scene(sd, bar)
            self._write_run_json()

    def _fail(self, what, exc):
        error = f"{type(exc).__name__}: {exc}"
        self.status.append({"what": what, "status": "failed", "error": error,
                            "traceback": traceback.format_exc(limit=6)})
        print(f"dsm: failed: {what}: {error}", file=sys.stderr)     # seen where the user looks, not only in run.json

    # ------------------------------------------------------------ per scene
    def _run_scene(self, sd, bar):
        W, H = (int(x) for x in sd.sensor.film().size())
        gb, t = timing.measure(lambda: _gbuffer_arrays(sd, W, H), 0)
        gb = gb[-1]
        gb.ms = t.ms
        self.gbuffer_ms[sd.label] = t.ms
        if sd.notes:
            self.status.append({"what": f"scene {sd.label}", "status": "note", "error": "; ".join(sd.notes)})
        self.rays["gbuffer"] += W * H
        lights = sd.lights_for(self.cfg.lights)
        if not lights:
            self._fail(f"scene {sd.label}", ValueError(
                "the scene has no usable point/spot/directional emitter and the config names no [[light]]"))
            return
        for li, light in enumerate(lights):
            label = f"{li}:{light.type}"
            try:
                setup = self._light_setup(sd, gb, light, label)
            except Exception as e:
                self._fail(f"scene {sd.label} light {label}", e)
                continue
            for kind in views_for(light.type, self.cfg.map.view):
                for R in self.cfg.map.resolutions_for(VIEW_FACES[kind]):
                    self._run_map(sd, gb, setup, kind, R, bar)

    def _light_setup(self, sd, gb, light, label) -> LightSetup:
        setup = light_setup(sd, gb, light, label, self.cfg.timing_repeats)
        self.rays["reference"] += len(setup.pixels)
        return setup

    # ------------------------------------------------------------ per map
    def _run_map(self, sd, gb, setup, kind, R, bar):
        specs = self.cfg.schemes
        per_case = len(self.cfg.map.filter) * len(self.cfg.map.format)
        try:
            view = make_view(setup.light, R, _points_np(setup.p) if setup.p is not None else np.zeros((0, 3)),
                             sd.bbox, kind)
            rx = seam = None
            if setup.p is not None:
                setup = setup.subset(view.inside(setup.p).numpy().astype(bool))   # a single paraboloid: its hemisphere
            bp, bn = setup.backfacing_inside(view)
            if setup.p is not None and len(setup.pixels):
                rx = Receiver.make(view, setup.p, setup.n, sd.diagonal)
                seam = view.seam_distance(rx.u, rx.v, rx.face)
                dr.eval(rx.d, rx.u, rx.v, rx.face, rx.texel_world, rx.to_light, seam)
                seam = seam.numpy()
        except Exception as e:
            self._fail(f"scene {sd.label} light {setup.label} view {kind} map {R}", e)
            bar.update(len(specs) * per_case)
            return
        # one map per culling choice, with the union of what its schemes need
        groups = {}
        for spec in specs:
            groups.setdefault(schemes.culling_of(spec.params), []).append(spec)
        first_t = None
        for culling, group in groups.items():
            try:
                modes = None
                if culling != "none":
                    modes = shadowmap.cull_modes_for(culling, self._closed(sd))
                needs = schemes.needs_of(group)
                mplan = self.plan.map_for(sd.label, setup.label, view.kind, R, culling)
                tile = mplan.tile if mplan else 0
                timing.reset_peak()
                smap, bt = timing.measure(lambda: _map_arrays(sd.scene, view, needs, culling, modes, tile),
                                          self.cfg.timing_repeats)
                peak = timing.peak_bytes()
                smap = smap[-1]
                smap.peak_bytes = peak
                self.maps.append({"scene": sd.label, "light": setup.label, "view": view.kind, "resolution": R,
                                  "culling": culling, "layers": ["z1", "shape"] + [k for k in shadowmap.LAYERS
                                                                                   if getattr(smap, k) is not None],
                                  "tiles": smap.tiles, "rays": dict(smap.rays), "rehits": smap.rehits,
                                  "build_peak_bytes": peak,
                                  "build_peak_bytes_est": mplan.peak_bytes if mplan else None,
                                  "formats": [f for f in self.cfg.map.format if f != "float32"]})
                for k, v in smap.rays.items():
                    self.rays[k] = self.rays.get(k, 0) + v
                if smap.unfinished:
                    self.status.append({"what": f"map {sd.label} {setup.label} R={R} culling={culling}",
                                        "status": "warning", "error": f"{smap.unfinished} texels still searching "
                                        f"after {shadowmap.MAX_STEPS} surfaces"})
            except Exception as e:
                self._fail(f"scene {sd.label} light {setup.label} map {R} culling {culling}", e)
                bar.update(len(group) * per_case)
                continue
            try:
                stored = {fmt: formats.store(smap, fmt) for fmt in self.cfg.map.format}
                self.quantized += sum(1 for fmt in self.cfg.map.format if fmt != "float32")
            except Exception as e:
                self._fail(f"scene {sd.label} light {setup.label} map {R} culling {culling}: stored formats", e)
                bar.update(len(group) * per_case)
                continue
            # receivers in the depth function each stored format compares in (formats.stored_view)
            rxs = {fmt: rx if rx is None or stored[fmt].view is view else
                   Receiver.make(stored[fmt].view, setup.p, setup.n, sd.diagonal) for fmt in stored}
            back = {fmt: Receiver.make(stored[fmt].view, bp, bn, sd.diagonal) for fmt in stored} if bp is not None else {}
            build_times = {frozenset(needs): bt}
            if first_t is None:
                # the first layer alone, so a case's extra layers show as build_ms - build_first_ms
                first_t = bt if culling == "none" and not needs else timing.measure(
                    lambda: _map_arrays(sd.scene, view, set(), "none", None, tile), self.cfg.timing_repeats)[1]
            for spec in group:
                own = frozenset(schemes.get(spec.name).NEEDS)
                if own not in build_times:
                    # time the build of exactly what this scheme needs (the data comes from the shared map)
                    _, build_times[own] = timing.measure(
                        lambda: _map_arrays(sd.scene, view, own, culling, modes, tile), self.cfg.timing_repeats)
                bt = build_times[own]
                for filt in self.cfg.map.filter:
                    for fmt in self.cfg.map.format:
                        self._run_case(sd, gb, setup, view, stored[fmt], (bt, first_t), rxs[fmt], seam, spec, filt,
                                       fmt, back.get(fmt))
                        bar.update(1)

    def _closed(self, sd):
        if sd.closed is None:
            closed_flags(sd)
            self.scene_info.append({"scene": sd.label, "shapes": [
                {"name": n, "closed": c, "why": w} for n, c, w in zip(sd.shape_names, sd.closed, sd.closed_reason)]})
        return sd.closed

    def _run_case(self, sd, gb, setup, view, smap, build, rx, seam, spec, filt, fmt, rx_back=None):
        bt, first_t = build
        self.case_no += 1
        case = f"{self.case_no:04d}"
        meta = {"case": case, "scene": sd.label, "light": setup.label, "view": view.kind, "scheme": spec.name,
                "culling": smap.culling,
                "preset": spec.preset or "", "params": spec.label, "resolution": view.resolution,
                "total_texels": view.n_texels,
                "filter": filt, "format": fmt}
        try:
            module = schemes.get(spec.name)
            if rx is None:
                v_np, tap_np, lt = np.zeros(0), np.zeros(0, np.uint32), timing.Timing(0.0, 0.0, 0.0, 0, 0)
                fallbacks = 0
            else:
                (v, tap_shape), lt = timing.measure(lambda: visibility(module, spec.params, rx, smap, filt, self.cfg.seed),
                                                    self.cfg.timing_repeats)
                v_np, tap_np = v.numpy(), tap_shape.numpy()
                fallbacks = lookup.plane_fallbacks(module, spec.params, rx, smap)
            m = metrics.compute(v_np, setup.v_star, setup.shape, tap_np, setup.occluder_dist, seam,
                                view.kind not in ("orthographic", "perspective"))
            # seed 000's self-unshadowing: pixels in attached shadow (facing away) that the map calls lit
            v_back = visibility(module, spec.params, rx_back, smap, filt, self.cfg.seed)[0].numpy() \
                if rx_back is not None else np.zeros(0)
            m["n_backfacing"] = int(v_back.size)
            m["backface_lit_rate"] = float((v_back >= 0.5).mean()) if v_back.size else metrics.UNDEFINED
            texel = float(np.median(rx.texel_world.numpy())) if rx is not None else metrics.UNDEFINED
            sweep_key, sweep_value = report.sweep_of(spec, self.cfg.schemes)
            row = {**meta, **setup.exclusions, **m, "texel_size": texel,
                   "n_plane_fallback": fallbacks if getattr(module, "USES_PLANE", False) else metrics.UNDEFINED,
                   "build_ms": bt.ms, "build_first_ms": first_t.ms, "build_compile_ms": bt.compile_ms, "build_peak_mb": smap.peak_bytes / 2 ** 20,
                   "lookup_ms": lt.ms, "lookup_compile_ms": lt.compile_ms, "lookup_kernels_compiled": lt.cache_misses,
                   "reference_ms": setup.reference_ms, "sweep_key": sweep_key, "sweep_value": sweep_value}
            classes = np.zeros(gb.width * gb.height, np.uint8)
            classes[setup.pixels] = metrics.classify(v_np, setup.v_star)
            classes = classes.reshape(gb.height, gb.width)
            report.write_case_images(self.out / "images", case, classes, gb, setup, v_np)
            if self.keep_images:
                self.images[case] = classes
            self.rows.append(row)
            self.csv.write(row)
            # a case without receivers says nothing about the scheme: it is reported as empty
            self.status.append({"what": f"case {case}", **{k: meta[k] for k in ("scene", "light", "view", "scheme",
                                                                                 "params", "resolution")},
                                "status": "ok" if m["n_receivers"] else "empty"})
            self._write_run_json()
        except Exception as e:
            self._fail(f"case {case} ({sd.label}, {setup.label}, {spec.name} {spec.label}, R={view.resolution})", e)

    # ------------------------------------------------------------ run.json
    def _run_json(self):
        info = report.run_info(self.cfg, self.variant, self.rays, self.status, self.versions, dr.thread_count())
        info["state"] = self.state
        info["scenes"] = self.scene_info
        info["gbuffer_ms"] = self.gbuffer_ms     # one cold pass per scene (compile included)
        info["plan"] = self.plan.as_dict()
        info["maps"] = self.maps
        info["quantized_copies"] = self.quantized
        return info

    def _write_run_json(self):
        # after every case (compact), indented once the run has ended
        report.write_json(self.out / "run.json", self._run_json(), None if self.state == "running" else 1)


def _points_np(p) -> np.ndarray:
    return np.stack([np.asarray(c, np.float64) for c in (p.x.numpy(), p.y.numpy(), p.z.numpy())], axis=1)


def _gbuffer_arrays(sd, W, H):
    gb = gbuffer.cast(sd.scene, sd.sensor, W, H)
    return (gb.p, gb.n, gb.shape, gb)


def _map_arrays(scene, view, needs, culling="none", modes=None, tile=None):
    smap = shadowmap.build(scene, view, needs, culling, modes, tile)
    return (*shadowmap.arrays(smap), smap)


def run(config, out=None, variant=None, progress=False) -> Results:
    """Run an experiment (a Config, a dict or a path to a TOML file) and return its Results."""
    config = cfgmod.coerce(config)           # a one-line TypeError or ConfigError for anything else
    cfgmod.check_runnable(config)            # NothingToRun: every scene an absent optional file
    env.use_variant(variant or config.variant)
    scenes.check(config)                     # unreadable scenes, before any work
    planmod.check_memory(planmod.make(config), config.source)
    if out is None:
        import tempfile
        out = Path(tempfile.mkdtemp(prefix=f"dsm-{config.name}-"))
    return Runner(config, Path(out), variant, progress).run()
