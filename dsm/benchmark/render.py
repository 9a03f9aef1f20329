"""Each case's shadowed render and the exact render it is judged against, for FLIP.

dsm.run writes a case's shaded image (dsm.report.tables.shade: Lambert under the light with the
map's V, ambient elsewhere) to its shadow PNG but keeps only its class image in memory, and no
render under the exact V*. So the benchmark re-traces each scene's G-buffer and light set-ups
through dsm.pipeline (the same stages, config and seed as the run) and shades both with the
kit's own ``shade``: under the case's V (read back from its class image: lit where the class is
lit or peter-panned) and under V*. A case's receivers are the light's less those outside its
map's view (the runner's ``LightSetup.subset``; measured: one spot receiver of plane_box at 1e5):
the class image marks them (class 0: not a receiver), so the set-up is cut to them as the run's
was. The class image's V* is checked against the re-traced V*: a mismatch is an error, not a
silently wrong render.
"""
from __future__ import annotations

import numpy as np

from .. import pipeline
from ..report.tables import shade
from ..truth import metrics


def light_setups(config, variant: str | None = None) -> dict:
    """(scene label, light label) -> (G-buffer, LightSetup) of a case config, as its run labels them."""
    cfg = pipeline.prepare(config, variant)
    out = {}
    for spec in cfg.scenes:
        sd = pipeline.load_checked_scene(spec, cfg.camera_resolution, cfg.camera)
        gb = pipeline.gbuffer(sd)
        for i, light in enumerate(sd.lights_for(cfg.lights)):
            label = f"{i}:{light.type}"          # dsm.config.plan.scene_lights' labels
            out[(sd.label, label)] = (gb, pipeline.light_setup(sd, gb, light, label, 0, cfg.seed))
    return out


def visibilities(classes: np.ndarray, pixels: np.ndarray) -> tuple:
    """(V, V*) per receiver as 0/1 floats from a case's class image and its receivers' pixel indices."""
    c = metrics.base_class(np.asarray(classes).reshape(-1)[pixels])
    return (np.isin(c, (metrics.LIT, metrics.PETERPAN)).astype(float),
            np.isin(c, (metrics.LIT, metrics.ACNE)).astype(float))


def shaded(gb, setup, v: np.ndarray) -> np.ndarray:
    """The kit's shaded render (H, W) in [0, 1] of one light set-up under visibility ``v``."""
    return shade((gb.height, gb.width), gb, setup, v, pipeline.is_positional(setup.light))


def case_renders(setups: dict, row: dict, classes: np.ndarray) -> tuple:
    """(shadowed render under the case's V, exact render under V*) of one metrics row."""
    gb, setup = setups[(row["scene"], row["light"])]
    in_view = np.asarray(classes).reshape(-1)[setup.pixels] != metrics.OUTSIDE
    setup = setup.subset(in_view)               # the case's receivers: those inside its map's view
    v, v_star = visibilities(classes, setup.pixels)
    if not np.array_equal(v_star.astype(bool), np.asarray(setup.v_star, bool)):
        raise RuntimeError(f"dsm benchmark: case {row['case']}: the re-traced exact visibility differs from the "
                           "run's: its renders would not be the run's")
    return shaded(gb, setup, v), shaded(gb, setup, setup.v_star.astype(float))
