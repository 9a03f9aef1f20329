"""Parameter labels a reader can read: ``name=value [unit]`` words with floats to their meaningful
digits and a depth-range bias that is a power of two named as one (``2^-24 range``), beside the
exact text the run wrote (metrics.csv's ``params``, which stays the case's identity).

This is the one label function of the kit's console, table.md and report: a bias reads the same
(``2^-24 range``) in each. ``2^k`` is a number a config reads (``bias = "2^-24 range"``), so a power of
two pastes back exactly. Where there is no hover (the console, table.md) ``exact=True`` keeps every
other number as the run wrote it (``%g``, six digits: the text a config reads back to the same
instance); the report's four digits keep the exact text a hover (HTML ``title``) or a column away.
"""
from __future__ import annotations

import math
import re

DIGITS = 4                # significant digits a parameter is shown to
# a power of two at or below this is named as one: 2^-10 and smaller are depth-buffer steps
# (2^-16, 2^-24 of the range), whose decimal text carries no meaning to a reader
POWER_MAX = 2.0 ** -10
# the relative difference %g's six digits can leave between a written power of two and the power
POWER_TOLERANCE = 5e-6
DEPTH_BITS = {16: "one step of a 16-bit depth buffer", 24: "one step of a 24-bit depth buffer",
              23: "float32's epsilon at 1 (2^-23)"}
WORD = re.compile(r"(?P<name>[A-Za-z_][\w]*)=(?P<value>[^\s=]+)(?: (?P<unit>texel|range|world))?")


def number_text(value: float, digits: int = DIGITS) -> str:
    """A float to ``digits`` significant digits without a trailing zero (1.2142857142857142 -> '1.214')."""
    if not math.isfinite(value):
        return str(value)
    if value == 0:
        return "0"
    text = f"{value:.{digits}g}"
    if "e" in text:
        mant, exp = text.split("e")
        return f"{mant}e{int(exp)}"
    return text


def power_of_two(value: float) -> int | None:
    """k when ``value`` is 2^k (to %g's six digits) and at most POWER_MAX, else None."""
    if not (0 < value <= POWER_MAX * (1 + POWER_TOLERANCE)):
        return None
    k = round(math.log2(value))
    return k if abs(value / 2.0 ** k - 1) <= POWER_TOLERANCE else None


def value_text(raw: str, unit: str | None, exact: bool = False) -> tuple:
    """(shown text, note or '') of one parameter's value as written and its unit (``exact``: a
    number that is no named power of two as written)."""
    try:
        value = float(raw)
    except ValueError:
        return raw + (f" {unit}" if unit else ""), ""
    k = power_of_two(value) if unit == "range" else None
    if k is not None:
        return f"2^{k} range", DEPTH_BITS.get(-k, "")
    return (raw if exact else number_text(value)) + (f" {unit}" if unit else ""), ""


def params_label(params: str, exact: bool = False) -> str:
    """``params`` (or any text of ``name=value [unit]`` words: an instance, a console line) as shown to
    a reader ('bias=5.96046e-08 range' -> 'bias=2^-24 range'); ``exact``: other numbers as written."""
    def one(m):
        shown, _ = value_text(m.group("value"), m.group("unit"), exact)
        return f"{m.group('name')}={shown}"
    return WORD.sub(one, params or "")


def params_notes(params: str) -> list:
    """What the shown label's named powers of two are ('2^-24 range: one step of a 24-bit depth buffer')."""
    out = []
    for m in WORD.finditer(params or ""):
        shown, note = value_text(m.group("value"), m.group("unit"))
        if note:
            out.append(f"{shown}: {note}")
    return out


def params_title(params: str) -> str:
    """The hover text of a shown label: the exact parameters as the run wrote them, and the notes."""
    notes = params_notes(params)
    return f"exact: {params}" + ("; " + "; ".join(notes) if notes else "") if params else ""
