"""One technique of dsm grad: a depth filter or a pre-filtered map kind, its blur and its edge treatment."""
from __future__ import annotations

from dataclasses import dataclass

from .. import prefilter

# every pre-filtered kind of the kit's registry (their blur widths sweep; the depth filters have none)
MOMENT_TECHNIQUES = prefilter.NAMES


@dataclass(frozen=True)
class Technique:
    """One technique instance: its name, blur width in texels (moment maps; 1 elsewhere) and
    whether its map is antialiased (Worchel & Alexa 2023's edge treatment, dsm.grad.antialias)."""
    name: str
    blur: int = 1
    antialias: bool = False

    @property
    def label(self) -> str:
        """The instance as the table names it, e.g. ``vsm blur 3 aa``."""
        out = self.name + (f" blur {self.blur}" if self.name in MOMENT_TECHNIQUES else "")
        return out + (" aa" if self.antialias else "")
