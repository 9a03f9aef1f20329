"""SMRT's settings (dsm.maps.smrt): rays per receiver, samples per ray, the rule where the map has
no data, and the engines' presets with each value's source. Plain Python: the config reader checks a
filter label with it before anything loads Mitsuba."""
from __future__ import annotations

import re
from dataclasses import dataclass

from ..core.suggest import did_you_mean

RULES = ("hold", "eevee", "plain")
MAX_RAYS = 1024
MAX_SAMPLES = 256


@dataclass(frozen=True)
class Settings:
    """An SMRT configuration: rays per receiver, samples per ray, the rule where the map has no data."""
    rays: int
    samples: int
    rule: str

    @property
    def taps(self) -> int:
        """Map reads per lookup: rays x samples."""
        return self.rays * self.samples


# the engines' defaults, each value's source named (docs/smrt.md)
PRESETS = {
    # r.Shadow.Virtual.SMRT.RayCountLocal = 7, SamplesPerRayLocal = 8: Unreal Engine 5.4's console
    # variable reference (indxzero.github.io/ue544cvarwiki, the variables' defaults in 5.4's source)
    "ue5_local": Settings(7, 8, "hold"),
    # r.Shadow.Virtual.SMRT.RayCountDirectional = 7, SamplesPerRayDirectional = 8 (the same reference)
    "ue5_directional": Settings(7, 8, "hold"),
    # Render Properties > Shadows > Rays = 1, Steps = 6 (Blender manual, EEVEE's shadow settings;
    # SceneEEVEE.shadow_ray_count, shadow_step_count defaults in Blender's DNA_scene_types.h): one frame
    "eevee": Settings(1, 6, "eevee"),
    # EEVEE draws a new ray per anti-aliasing sample and accumulates them: Sampling > Viewport 16 and
    # Render 64 samples (SceneEEVEE.taa_samples, taa_render_samples defaults, the same header)
    "eevee_viewport": Settings(16, 6, "eevee"),
    "eevee_render": Settings(64, 6, "eevee"),
}
DEFAULT_PRESET = "ue5_local"
_CUSTOM = re.compile(r"^(\d+)x(\d+)(?::(\w+))?$")


def is_smrt(filt: str) -> bool:
    """Whether a filter label names SMRT (``smrt`` or ``smrt:...``)."""
    return filt == "smrt" or filt.startswith("smrt:")


def settings(filt: str) -> Settings:
    """The Settings of ``smrt``, ``smrt:<preset>`` or ``smrt:RxS[:rule]``; ValueError naming the choices."""
    arg = filt.split(":", 1)[1] if ":" in filt else DEFAULT_PRESET
    if arg in PRESETS:
        return PRESETS[arg]
    m = _CUSTOM.match(arg)
    if m is None:
        raise ValueError(f"{filt!r}: {did_you_mean(arg, PRESETS)}smrt takes a preset ({', '.join(PRESETS)}) "
                         f"or RxS[:rule] (R rays, S samples per ray, rule one of {', '.join(RULES)})")
    rays, samples, rule = int(m.group(1)), int(m.group(2)), m.group(3) or "hold"
    if not (1 <= rays <= MAX_RAYS and 1 <= samples <= MAX_SAMPLES and rule in RULES):
        raise ValueError(f"{filt!r}: {did_you_mean(rule, RULES) if rule not in RULES else ''}rays 1 to {MAX_RAYS}, "
                         f"samples 1 to {MAX_SAMPLES}, rule one of {', '.join(RULES)}")
    return Settings(rays, samples, rule)
