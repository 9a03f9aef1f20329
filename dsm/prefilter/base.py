"""The contract of a pre-filtered map kind, and what every kind shares: depth normalization,
storage precision, the separable box blur and the per-receiver fetch.

Depth-compare schemes (:mod:`dsm.schemes.base`) give a signed margin per filter tap, and a
filter averages their binary tests. A pre-filtered map gives a *continuous V per receiver*
instead: its texels store moments of the depth (statistics a linear filter may average), and
its lookup turns the filtered moments at the receiver into a visibility in [0, 1]. A kind
module (:class:`MapKind`) has ``NAME``, ``SOURCE``, a frozen ``Params`` dataclass, ``count(params)``
(moments per texel), ``log_max(params)`` (an exponential moment's largest log, or None),
``moment_key(params)`` (the parameters the moments depend on: maps sharing
it share one build), ``moments(t, params)`` (numpy float64, one array per moment, from the
normalized depth ``t``) and ``visibility(b, t, prm)`` (Dr.Jit: the filtered moments ``b`` and
the receiver's normalized depth ``t`` -> V). A ``Params`` field whose metadata holds ``"tune": (space, lo, hi)``
is a lookup-time parameter (the moments do not depend on it) that dsm tune fits in that box
(``space``: ``log`` or ``linear``; dsm.tune.moments).

Depth is normalized to the view's range, ``t = (z - near) / (far - near)`` in [0, 1], the
linear depth engines write into a moment map; a texel whose ray hit nothing holds ``t = 1``.
The moments come from the ray-cast ``z1`` of each texel, or with ``[map] moment_samples = N``
from N x N rays at its sub-texel centres (:func:`supersampled_view`), their moments averaged per
texel (:func:`texel_means`, an MSAA resolve's mean) before storage. ``format`` is their storage precision: ``float32`` or ``float16`` (IEEE half,
rounded to nearest; a value beyond 65504 becomes +inf as a half render target stores it), or
``unorm16`` for a kind with an ``encode(t, params)`` / ``decode(q)`` pair, None in the others (MSM's
optimized quantization): the encoded moments, clamped to [0, 1], rounded to k / 65535 (half to even), and
decoded at lookup after the fetch, as a shader decodes what it filtered (:func:`restored`). The
moments (or encoded moments) are stored, blurred in float64, and the blurred values stored
again in the format, as a blur pass writes a render target of that format.

The blur is a separable box or Gaussian (``[map] blur_kernel``; sigma (W + 1) / 6, Filament's)
of odd width ``W`` texels (``W = 1``: the unfiltered fetch). It stays on its face: at a face edge the window is clamped to the face (edge texels repeat), so
cube maps are not blurred across their seams and a paraboloid face is blurred over its whole
square, rim included (the texels beyond the rim hold their rays' hits, or t = 1 where they
missed). The fetch is the nearest texel of the blurred map; a receiver beyond a directional
light's map reads the moments of t = 1 (no caster, as a depth tap reads the far bound).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any, Callable, Protocol, runtime_checkable

import drjit as dr
import mitsuba as mi
import numpy as np

FLOAT_FORMATS = ("float32", "float16")          # every kind: its moments as floats
ENCODED_FORMATS = ("unorm16",)                   # a kind with encode / decode: its encoded moments
MOMENT_FORMATS = FLOAT_FORMATS + ENCODED_FORMATS
UNORM16_STEPS = 2 ** 16 - 1
# the largest e-exponent each format holds: ln(FLT_MAX), ln(65504)
# (the logs taken in float64: np.log of a half is a half, 11.09375, whose exp overflows 65504)
LOG_MAX = {"float32": float(np.log(float(np.finfo(np.float32).max))),
           "float16": float(np.log(float(np.finfo(np.float16).max)))}


@runtime_checkable
class MapKind(Protocol):
    """A pre-filtered map kind module: its constants, ``Params``, moments and lookup."""
    NAME: str
    SOURCE: str
    Params: type
    # encode(t, params) -> list: the moments as ENCODED_FORMATS store them, in [0, 1] (numpy);
    # decode(q) -> list: their inverse at lookup. None (both): stored as floats only (FLOAT_FORMATS)
    encode: Callable | None
    decode: Callable | None

    def count(self, params: Any) -> int:
        """Moments stored per texel."""

    def log_max(self, params: Any) -> float | None:
        """The largest natural log of a stored moment (checked against LOG_MAX); None: no
        exponential moment that can overflow."""

    def moment_key(self, params: Any) -> tuple:
        """The parameters the stored moments depend on (equal keys: one build)."""

    def moments(self, t: np.ndarray, params: Any) -> list:
        """The moments of normalized depths ``t`` (numpy float64), one array each."""

    def visibility(self, b: list, t: Any, prm: Any) -> Any:
        """V in [0, 1] per receiver from filtered moments ``b`` and normalized depth ``t`` (Dr.Jit)."""


@dataclass
class MomentMap:
    """A built pre-filtered map: its view, the blurred stored moments (mi.Float each, texel order
    of the depth map) and the moments of t = 1 (read beyond a directional light's map)."""
    view: object
    b: list
    far_b: list
    fmt: str
    blur: int
    mips: tuple | None = None      # mipmaps.packed() of the levels after 0 ([map] mipmaps), None: none


def normalized_depth(z, view):
    """Depth ``z`` (world, Dr.Jit or numpy) as t = (z - near) / (far - near), the moment maps' depth."""
    if isinstance(z, np.ndarray):
        return np.clip((z.astype(np.float64) - view.near) / (view.far - view.near), 0.0, 1.0)
    near = dr.opaque(mi.Float, float(view.near))
    return (z - near) / dr.opaque(mi.Float, float(view.far - view.near))


def formats_of(kind) -> tuple:
    """The moment formats ``kind`` may be stored in: the float ones, and unorm16 if it encodes."""
    return MOMENT_FORMATS if kind.encode is not None else FLOAT_FORMATS


def stored(x: np.ndarray, fmt: str) -> np.ndarray:
    """``x`` as the format stores it, read back in float64."""
    if fmt == "unorm16":
        return np.round(np.clip(x, 0.0, 1.0) * UNORM16_STEPS) / UNORM16_STEPS
    if fmt == "float16":
        with np.errstate(over="ignore"):
            return x.astype(np.float16).astype(np.float64)
    return x.astype(np.float32).astype(np.float64)


def separable_blur(x: np.ndarray, width: int, faces: int, R: int, weights=None) -> np.ndarray:
    """A separable ``width`` x ``width`` window over texel values ``x`` (faces * R * R, float64),
    each face on its own, the window clamped at face edges (edge texels repeat): per axis, 0 +
    tap 0 + tap 1 + ... (each times its weight where ``weights`` is given, else the sum divided
    by ``width``). Summed tap by tap, not by a running sum: an exponential moment spans 30
    decades, and a running sum's difference would lose the small values to the large ones."""
    if width == 1:
        return x
    img = x.reshape(faces, R, R)
    for axis in (1, 2):
        img = _axis_taps(img, width, axis, weights)
    return img.reshape(-1)


def _axis_taps(img: np.ndarray, width: int, axis: int, weights) -> np.ndarray:
    """One axis (1: rows, 2: columns) of :func:`separable_blur`, tap by tap in place. Tap k reads
    the texel k - width // 2 away, clamped at the face's edge: the texels whose source is inside
    the face read one slice of ``img``, the clamped ones its edge row or column broadcast. No
    padded copy is made (its page faults were a third of a blur's time), and each output texel
    gets the same additions in the same order as a sum over the edge-padded image."""
    h, R = width // 2, img.shape[axis]
    out = np.empty_like(img)
    tmp = None if weights is None else np.empty_like(img)
    along = (lambda a, b: (slice(None), slice(a, b))) if axis == 1 else (lambda a, b: (slice(None), slice(None), slice(a, b)))
    for k in range(width):
        s = k - h                                   # this tap's shift along the axis
        lo = min(R, max(0, -s))                     # outputs lo..hi read a source inside the face
        hi = max(lo, min(R, R - s))
        for a, b, src in ((lo, hi, img[along(lo + s, hi + s)]), (0, lo, img[along(0, 1)]), (hi, R, img[along(R - 1, R)])):
            if b <= a:
                continue
            if weights is not None:
                src = np.multiply(weights[k], src, out=tmp[along(a, b)])
            if k == 0:
                np.add(0, src, out=out[along(a, b)])
            else:
                out[along(a, b)] += src
    return out if weights is not None else np.divide(out, width, out=out)


def box_blur(x: np.ndarray, width: int, faces: int, R: int) -> np.ndarray:
    """The separable ``width`` x ``width`` box mean (separable_blur)."""
    return separable_blur(x, width, faces, R)


def gaussian_weights(width: int) -> np.ndarray:
    """The ``width`` taps of a normalized Gaussian of sigma (width + 1) / 6, Filament's relation
    of a VSM blur's width to its sigma (filament/src/ShadowMapManager.cpp), cut at the window."""
    sigma = (width + 1) / 6.0
    k = np.arange(width) - width // 2
    w = np.exp(-k * k / (2.0 * sigma * sigma))
    return w / w.sum()


def gaussian_blur(x: np.ndarray, width: int, faces: int, R: int) -> np.ndarray:
    """The separable ``width`` x ``width`` Gaussian of gaussian_weights (separable_blur)."""
    return separable_blur(x, width, faces, R, gaussian_weights(width))


BLURS = {"box": box_blur, "gaussian": gaussian_blur}


def texel_values(kind, t: np.ndarray, params, fmt: str) -> list:
    """What a texel of normalized depth ``t`` holds before storage: the moments, or in an
    encoded format (ENCODED_FORMATS) the kind's encoded moments."""
    return kind.encode(t, params) if fmt in ENCODED_FORMATS else kind.moments(t, params)


def restored(kind, b: list, fmt: str) -> list:
    """The moments of fetched values ``b``: decoded in an encoded format, else ``b`` itself."""
    return kind.decode(b) if fmt in ENCODED_FORMATS else b


def supersampled_view(view, samples: int):
    """``view`` with ``samples`` x ``samples`` texels for each of its texels: the same frame, near,
    far and extent, its resolution times ``samples``, so texel (i, j) of ``view`` is texels
    (i N .. i N + N - 1, j N .. j N + N - 1) of the copy (every view maps a texel position through
    its resolution ``R`` alone: views.View.to_square)."""
    if samples == 1:
        return view
    fine = copy.copy(view)
    fine.resolution = view.resolution * samples
    fine.R = dr.opaque(mi.Float, float(fine.resolution))
    fine.R_u = dr.opaque(mi.UInt32, int(fine.resolution))
    return fine


def texel_means(x: np.ndarray, faces: int, R: int, samples: int) -> np.ndarray:
    """The mean of each texel's ``samples`` x ``samples`` values of a supersampled map (faces *
    (R samples)^2 values, face then row-major) as faces * R^2 values: what an MSAA resolve of the
    moments writes (a mean of moments is the moment of the union of the samples)."""
    if samples == 1:
        return x
    return x.reshape(faces, R, samples, R, samples).mean(axis=(2, 4)).reshape(-1)


def build(kind, params, z1_world: np.ndarray, view, fmt: str, blur: int, kernel: str = "box",
          samples: int = 1, mip: bool = False) -> MomentMap:
    """The moment map of ``kind`` from a depth map's z1 (world, texel order; ``samples`` > 1: of
    supersampled_view(view, samples)): moments (encoded in an encoded format), averaged over each
    texel's samples, stored, blurred (``kernel``: box or gaussian, ``blur`` texels wide), stored again;
    ``mip``: with the chain of 2 x 2 means of that (dsm.prefilter.mipmaps)."""
    t = normalized_depth(z1_world, view)
    b = [stored(BLURS[kernel](stored(texel_means(m, view.faces, view.resolution, samples), fmt), blur, view.faces,
                              view.resolution), fmt)
         for m in texel_values(kind, t, params, fmt)]
    far_b = [float(stored(m, fmt)[0]) for m in texel_values(kind, np.ones(1), params, fmt)]
    mips = None
    if mip and view.resolution > 1:
        from . import mipmaps
        mips = mipmaps.packed([mipmaps.chain(m, view.faces, view.resolution, lambda x: stored(x, fmt)) for m in b])
    return MomentMap(view, [mi.Float(m.astype(np.float32)) for m in b], far_b, fmt, blur, mips)


def fetch(mmap: MomentMap, rx):
    """The filtered moments at each receiver's nearest texel (the moments of t = 1 beyond the map)."""
    view = mmap.view
    R1 = mi.Int32(view.R_u) - 1
    i = mi.Int32(dr.floor(rx.u_map))
    j = mi.Int32(dr.floor(rx.v_map))
    out = (i < 0) | (j < 0) | (i > R1) | (j > R1)
    idx = (rx.face * view.R_u + mi.UInt32(dr.clip(j, 0, R1))) * view.R_u + mi.UInt32(dr.clip(i, 0, R1))
    if mmap.mips is not None:            # [map] mipmaps: the level of the receiver's footprint
        from . import mipmaps
        b = mipmaps.blend(mmap.mips, rx, [dr.gather(mi.Float, b, idx) for b in mmap.b])
        return [dr.select(out, dr.opaque(mi.Float, f), x) for x, f in zip(b, mmap.far_b)]
    return [dr.select(out, dr.opaque(mi.Float, f), dr.gather(mi.Float, b, idx)) for b, f in zip(mmap.b, mmap.far_b)]


def linstep(lo, hi, x):
    """(x - lo) / (hi - lo) clamped to [0, 1]: the light-bleeding reduction's ramp."""
    return dr.clip((x - lo) / (hi - lo), 0.0, 1.0)


def safe_div(num, den, use):
    """num / den where ``use``; elsewhere 0, with a gradient of 0 (a select's unused branch still
    back-propagates 0 * inf = NaN through an unguarded division)."""
    return dr.select(use, num / dr.select(use, den, 1.0), 0.0)


def chebyshev(mean, mean_sq, t, min_variance):
    """Chebyshev's one-sided upper bound on P(z >= t) from E[z], E[z^2] (Donnelly & Lauritzen
    2006): 1 where t <= E[z], else var / (var + (t - E[z])^2), var at least ``min_variance``.
    Differentiated (dsm grad, dsm tune), its derivative is that of the same bound written
    1 / (1 + (d / sigma)^2): var / (var + d^2)'s squares var + d^2, beyond float32 for EVSM's
    warped variance (up to e^80). The value is the quotient's in both cases, to the bit."""
    var = dr.maximum(mean_sq - mean * mean, min_variance)
    d = t - mean
    bound = var / (var + d * d)
    if dr.grad_enabled(mean, mean_sq, t, min_variance):
        has = var > 0
        r = safe_div(d, dr.sqrt(dr.select(has, var, 1.0)), has)
        stable = dr.select(has, 1.0 / (1.0 + r * r), 0.0)
        # the quotient's value (the detached difference adds an exact 0) with the stable form's derivative
        bound = dr.detach(bound) + (stable - dr.detach(stable))
    return dr.select(t <= mean, 1.0, bound)
