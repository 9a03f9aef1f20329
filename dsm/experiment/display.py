"""Display renders: each scene and light of a run shaded at a resolution of its own, apart from the
measuring camera, so report.html can show a case's class image over the scene's shapes and the
exact shading beside the shadow-mapped one.

The measuring camera is often small (160 px a side by default): its class image, blown up, shows
flat areas of one colour, and a lit box top merges into the lit ground. A display render is the
same camera pose at a whole multiple of its resolution (at least DISPLAY_MIN pixels a side, so each
camera pixel is k x k display pixels and the class image upscaled nearest-neighbour lines up with
it), shaded with the kit's own Lambert term (dsm.report.tables.shade): once with every receiver lit
(N.L, the shapes) and once under the exact visibility V*. They are drawn after every timed
measurement, in the report's time, with their own G-buffer and light set-ups (nothing the
measurement counts is touched), one pair per scene and light: images/<scene>_<light>/display_*.png.
Area lights are left out (their V* is a jittered estimate per receiver, costly at this size), and
so are runs whose ``[report] images`` is not "all".
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .. import lights, pipeline
from ..report import png
from ..report.figures import display_paths, shade_image
from ..report.tables import receiver_cosines, shade

DISPLAY_MIN = 320          # pixels on a display render's shorter side, at least


def display_scale(width: int, height: int) -> int:
    """The whole factor k that takes a camera of width x height to at least DISPLAY_MIN a side."""
    return max(1, math.ceil(DISPLAY_MIN / min(width, height)))


def write_renders(out: Path, cfg, pairs: set) -> list:
    """The display renders of every (scene, light) label pair in ``pairs`` into ``out``/images;
    returns notes on what was left out (area lights, a scene that did not load again)."""
    notes = []
    for spec in cfg.scenes:
        try:
            sd = pipeline.load_scene(spec, cfg.camera_resolution, cfg.camera)
        except Exception as e:        # the measurement ran; a display render is never worth failing it
            notes.append(f"display render of scene {spec.label}: {type(e).__name__}: {e}")
            continue
        wanted = [(i, light) for i, light in enumerate(sd.lights_for(cfg.lights))
                  if (sd.label, f"{i}:{light.type}") in pairs]
        if not wanted:
            continue
        w, h = (int(x) for x in sd.sensor.film().size())
        k = display_scale(w, h)
        gb = pipeline.gbuffer(sd, w * k, h * k)
        for i, light in wanted:
            label = f"{i}:{light.type}"            # dsm.config.plan.scene_lights' labels
            if lights.is_soft(light):
                notes.append(f"display render of {sd.label} light {label}: an area light (left out)")
                continue
            _write_pair(Path(out), sd.label, label, gb, pipeline.light_setup(sd, gb, light, label, 0, cfg.seed))
    return notes


def _write_pair(out: Path, scene: str, label: str, gb, setup):
    """One scene and light's N.L and exact renders as 8-bit grey PNGs."""
    positional = pipeline.is_positional(setup.light)
    cos = receiver_cosines(setup, positional) if setup.n is not None else None     # once for both renders
    nl, exact = (shade((gb.height, gb.width), gb, setup, v, positional, cos)
                 for v in (np.ones(len(setup.pixels)), np.asarray(setup.v_star, float)))
    for name, img in zip(display_paths({"scene": scene, "light": label}), (nl, exact)):
        path = out / name
        path.parent.mkdir(parents=True, exist_ok=True)
        png.write(path, shade_image(img))
