"""The counting rules of a case's costs: bytes per texel at a stored width, taps per lookup.

The rules alone, below the plan (dsm.config.plan says what a map's cases will cost before any work)
and the case (dsm.case.cost counts them on the map as built); dsm.case.cost says what each counts.
"""
from __future__ import annotations

from . import lookup as map_lookup, smrt_presets as smrt

# bytes per stored depth: a 24-bit depth occupies a 32-bit word on GPUs (D24_UNORM_S8_UINT, X8_D24)
FORMAT_BYTES = {"float32": 4, "float16": 2, "unorm16": 2, "unorm24": 4, "ndc24": 4}
SLOPE_BYTES = 4                 # the slope layer: float32 in every format
PAGE_ENTRY_BYTES = 4            # a virtual map's page table: one uint32 physical page per virtual page
FIXED_TAPS = {"nearest": 1, "pcf_bilinear": 4, "pcf_jitter4x4": 16}


def layer_bytes(layers, fmt: str) -> int:
    """Bytes per texel of the depth ``layers`` (``z1``, ``z2``, ``slope``; ``shape`` never) stored in ``fmt``."""
    width = FORMAT_BYTES[fmt]
    return sum(width if k in ("z1", "z2") else SLOPE_BYTES if k == "slope" else 0 for k in layers)


def moment_bytes(moments: int, fmt: str, mipmaps: bool) -> float:
    """Bytes per texel of a pre-filtered map: ``moments`` at ``fmt``'s width, x 4/3 with a mip chain."""
    return moments * FORMAT_BYTES[fmt] * (4 / 3 if mipmaps else 1)


def filter_taps(filt: str) -> int | None:
    """Taps per lookup of a depth filter whose count is fixed (None: pcss, counted as it runs; smrt:
    rays x samples, every sample a tap)."""
    if filt in FIXED_TAPS:
        return FIXED_TAPS[filt]
    if filt == "pcf_wide" or filt.startswith("pcf_wide:"):
        k = int(filt.split(":", 1)[1]) if ":" in filt else map_lookup.PCF_WIDE_DEFAULT
        return k * k
    if filt == "pcss":
        return None
    if smrt.is_smrt(filt):
        return smrt.settings(filt).taps
    raise ValueError(f"unknown filter {filt!r}")


def pcss_taps(found_fraction: float) -> float:
    """PCSS's taps per lookup when ``found_fraction`` of the receivers find a blocker (the rest stop after the search)."""
    return map_lookup.PCSS_SEARCH ** 2 + map_lookup.PCSS_FILTER ** 2 * found_fraction
