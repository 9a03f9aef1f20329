"""The contract every scheme module meets (:class:`Scheme`), and the shift that does nothing.

A scheme is a module: ``NAME``, ``SOURCE``, ``NEEDS`` (map layers beyond z1 and shape ids),
``USES_PLANE`` (whether it reads the receiver plane, whose fallbacks are counted),
``VIEWS`` (the view kinds it reads, or None), ``READS_CAMERA``, ``needs(params) -> frozenset``,
a frozen ``Params`` dataclass, ``margin(rx, tap, params) -> Float`` and ``shift(rx, params)
-> Receiver``. The margin is signed, in the view's depth units: the receiver is lit by a tap
when it is >= 0 (``lit``). Filters apply it per tap; tuning by gradient relaxes it.

This is the contract of the depth map (``[map] kind = "depth"``): *a signed margin per filter
tap*, V the filter's weighted share of taps with margin >= 0. Pre-filtered maps (``vsm``,
``esm``, ``evsm``, ``msm``) meet the sibling contract :class:`dsm.prefilter.base.MapKind`: *a
continuous V per receiver* from filtered moments, with no taps and no margin. Both are
measured alike: lit means V >= 0.5, and mean_abs_error is the mean |V - V*|.
"""
from __future__ import annotations

from typing import Any, Protocol, runtime_checkable


@runtime_checkable
class Scheme(Protocol):
    """The contract of a scheme module: its constants, ``Params``, ``margin`` and ``shift``."""
    NAME: str
    SOURCE: str
    NEEDS: frozenset
    USES_PLANE: bool        # compares the receiver plane's depth at the texel centre (lookup.plane_fallbacks)
    # the view kinds it reads (a VSV lookup: ("vsv",)); None: every view but the exclusive ones
    VIEWS: tuple | None
    # reads the camera that sees each receiver (Receiver.camera), which dsm tune's light samples lack
    READS_CAMERA: bool
    Params: type

    def needs(self, params: Any) -> frozenset:
        """The map layers an instance reads (beyond z1 and shape ids): a subset of ``NEEDS``."""

    def margin(self, rx: Any, tap: Any, params: Any) -> Any:
        """Signed margin per receiver (Dr.Jit Float): lit where >= 0."""

    def shift(self, rx: Any, params: Any) -> Any:
        """The receiver to look up (normal offset moves it; the others return it as it is)."""


def no_shift(rx, params):
    """The lookup point is the receiver itself."""
    return rx


def fixed_needs(layers: frozenset):
    """A ``needs`` for a scheme whose every instance reads the same ``layers`` (its ``NEEDS``)."""
    def needs(params) -> frozenset:
        """The map layers this instance reads: the scheme's ``NEEDS``, whatever its parameters."""
        return layers
    return needs
