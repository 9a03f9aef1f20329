"""What of the kit's registries dsm grad differentiates, and why not the rest.

Every light type (:data:`dsm.lights.TYPES`), pre-filtered map kind (:data:`dsm.prefilter.REGISTRY`)
and filter (:data:`dsm.core.types.FILTERS`) is either differentiated (dsm grad reads it from the
kit's ``[[light]]`` and ``[map]``, :mod:`dsm.grad.kit_tables`) or
listed here with its reason; tests/test_grad.py fails on one that is neither, so a light added by
docs/howto/add_a_light.md, a new map kind or a new filter cannot go without a word.
"""
from __future__ import annotations

# kit light type -> GradSpec.light that differentiates it
LIGHTS = {"spot": "point", "directional": "directional", "area": "area"}
# kit light type -> why dsm grad has no gradient for it
LIGHTS_WITHOUT = {
    "point": "its cube and paraboloid views are not differentiated (a receiver's face is a step in its "
             "direction); dsm grad's point light is the kit's spot straight down, one perspective map",
    "scene": "its emitters are the scene file's: dsm grad builds its own scene, with no file's light to move",
}
# filters of the depth map that dsm grad differentiates (its techniques beside the map kinds)
FILTERS = ("nearest", "pcf_bilinear", "pcss")
# kit filter -> why dsm grad has no gradient for it
FILTERS_WITHOUT = {
    "pcf_jitter4x4": "its taps are nearest texels at jittered offsets: a step in the receiver's map position, "
                     "a gradient of zero as nearest's",
    "pcf_wide": "its K x K taps are nearest texels: a step in the receiver's map position, a gradient of zero "
                "as nearest's",
    "smrt": "its rays' samples are nearest texels along each ray (dsm.maps.smrt): a step in the samples' map "
            "positions, a gradient of zero as nearest's",
}
