"""dsm tune's cases: every scene, light and camera's receivers in the light's shared map."""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import pipeline as pl
from ..core.types import DEFAULT_CAMERA


# ---------------------------------------------------------------- cases: receivers of every view

@dataclass
class Case:
    """One scene, light and camera: receivers seen in the light's shared map."""
    scene: str
    light: str
    camera: str
    role: str
    group: int                 # index of the (scene, light) map
    setup: object              # LightSetup (receivers inside the view)
    rx: object                 # Receiver in the stored map's view
    v_star: np.ndarray
    v_star_dr: object          # mi.Bool
    th: object                 # pipeline.Thresholds (nearest texel, no shift)

    @property
    def n(self) -> int:
        """The number of receivers in this case."""
        return int(self.v_star.size)


@dataclass
class Group:
    """One scene and light: its map per culling (one layer set each), shared by all cameras."""
    scene: str
    light: str
    view: object
    maps: dict                 # culling -> stored map
    n_texels: int
    diagonal: float
    scene_data: object = None  # SceneData (dsm.scenes.data): what light samples are traced in
    light_spec: object = None  # LightSpec: the light that labels them


def _cameras(tc, sd):
    """(name, role, sensor) of every camera: the [[tune.camera]] poses, placed like the config's
    lights (scaled by the scene's scale, then moved by its translation); none: the scene's own."""
    from ..scenes.load import look_at_sensor
    W, H = tc.config.camera_resolution or DEFAULT_CAMERA
    if not tc.spec.cameras:
        return [("scene", "train", sd.sensor)]
    out = []
    s, t = sd.scale, np.asarray(sd.offset, float)
    for c in tc.spec.cameras:
        d = look_at_sensor(np.multiply(c.position, s) + t, np.multiply(c.target, s) + t, c.up, c.fov, W, H)
        out.append((c.name, c.role, mi.load_dict(d)))
    return out


def prepare_cases(tc, progress=None):
    """Load every scene, light and camera; fit each light's map to the union of its cameras'
    receivers; build it for every culling the tuned schemes ask for. (groups, cases, notes)"""
    cfg = tc.config
    fmt = cfg.map.format[0]
    R = cfg.map.resolutions_for(1)[0]
    kind = cfg.map.view[0]
    needs = {}
    for s in tc.schemes:     # every layer a scheme may read: a tuned term may start at 0 (combined's slope_scale)
        needs.setdefault(pl.culling_of(s.params), set()).update(pl.scheme_module(s.name).NEEDS)
    needs.setdefault("none", set())
    groups, cases, notes = [], [], []
    for spec in cfg.scenes:
        if spec.missing:            # an absent optional file: the others are tuned, the note says which
            notes.append(f"{spec.label}: {spec.missing}")
            continue
        sd = pl.load_checked_scene(spec, cfg.camera_resolution, getattr(cfg, "camera", None))   # [camera] pose, if any
        lights = sd.lights_for(cfg.lights)
        closed = pl.closedness(sd)[0] if any(c != "none" for c in needs) else None
        extents = pl.spawn_extents(sd.scene)
        cams = [(name, role, pl.gbuffer(sd, sensor=sensor)) for name, role, sensor in _cameras(tc, sd)]
        for li, light in enumerate(lights):
            label = light.label or light.type
            setups = [(name, role, pl.light_setup(sd, gb, light, label)) for name, role, gb in cams]
            pts = [pl.points_np(s.p) for _, _, s in setups if s.p is not None]
            pts = np.concatenate(pts) if pts else np.zeros((0, 3))
            view = pl.make_view(light, R, pts, sd.bbox, kind)
            maps = {c: pl.store(pl.build_map(sd.scene, view, sorted(nd), c, closed, extents=extents), fmt)
                    for c, nd in needs.items()}
            g = len(groups)
            groups.append(Group(sd.label, label, view, maps, view.n_texels, sd.diagonal, sd, light))
            for name, role, s in setups:
                if s.p is not None:
                    s = s.subset(view.inside(s.p).numpy().astype(bool))
                if s.p is None or len(s.pixels) == 0:
                    notes.append(f"{sd.label} / {label} / {name}: no receiver (left out)")
                    continue
                smap = maps["none"]
                rx = pl.receivers(smap.view, s, sd.diagonal)
                dr.eval(rx.depth, rx.u_map, rx.v_map, rx.face, rx.texel_world, rx.to_light)
                th = pl.thresholds(rx, smap)
                cases.append(Case(sd.label, label, name, role, g, s, rx, s.v_star.copy(), mi.Bool(s.v_star), th))
                if not s.v_star.any():
                    notes.append(f"{sd.label} / {label} / {name}: every receiver is in shadow (it sees shadowed "
                                 "surfaces only: a wall or floor out of the light, or a closed mesh from inside)")
            if progress:
                progress(f"{sd.label} / {label}")
    return groups, cases, notes


# ---------------------------------------------------------------- oracles of pooled cases

def pooled_thresholds(cases, groups):
    """The cases' thresholds as one set, texel ids made unique per map (group)."""
    off = np.cumsum([0] + [g.n_texels for g in groups])
    th = [c.th for c in cases]
    cat = lambda k: np.concatenate([getattr(t, k) for t in th])
    texel = np.concatenate([c.th.texel + off[c.group] for c in cases])
    return pl.Thresholds(cat("tau"), cat("kappa"), texel, cat("z1"), cat("depth"), cat("texel_world")), \
        np.concatenate([c.v_star for c in cases])
