"""PNG files of the report's images and figures, written without row filters.

Pillow's PNG encoder tries every row filter on every row and keeps the best; on the report's
images (flat colours, a few antialiased edges) that choice is about three quarters of its time
and buys nothing: zlib alone at level 1 gives files of the same size (a figure: 30.9 against
31.1 KB) in a third of the time (2.6 against 8.9 ms). Pillow offers no way to turn the search
off, so the few lines of the format (PNG specification, 2nd edition, sections 5 and 11) are here.
Any PNG reader decodes them (tests/test_png.py decodes them with Pillow): RGB, RGBA or grey, as
before; and indexed (a palette of up to 256 colours, one byte an index per pixel: the benchmark's
per-case class images and FLIP maps, whose indices are their values).
"""
from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

from .io import atomic

SIGNATURE = b"\x89PNG\r\n\x1a\n"
COLOUR_TYPE = {1: 0, 3: 2, 4: 6}       # channels -> grey, RGB, RGBA (PNG colour types)
LEVEL = 1                               # zlib's fastest level: the report's images are flat colours


def _chunk(tag: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))


def encode(pixels: np.ndarray, dpi: float | None = None) -> bytes:
    """An 8-bit PNG of ``pixels``: (H, W) grey, (H, W, 3) RGB or (H, W, 4) RGBA uint8; ``dpi`` is
    stored as the pixel density."""
    px = np.asarray(pixels)
    if (px.dtype != np.uint8 or px.ndim not in (2, 3) or (px.ndim == 3 and px.shape[2] not in COLOUR_TYPE)
            or 0 in px.shape[:2]):          # the format has no empty image (IHDR: width and height >= 1)
        raise ValueError(f"expected (H, W), (H, W, 3) or (H, W, 4) uint8 pixels, H and W >= 1, got {px.dtype} "
                         f"{px.shape}")
    h, w = px.shape[:2]
    channels = 1 if px.ndim == 2 else px.shape[2]
    rows = np.empty((h, w * channels + 1), np.uint8)        # each row: filter type 0 (none), its bytes
    rows[:, 0] = 0
    # copied in place, so a strided view (an RGBA canvas's RGB) needs no copy of its own; a channel at a
    # time (numpy copies a run of pixels per call, not 3 bytes: a seventh of the time for a figure)
    dest = rows[:, 1:].reshape(h, w, channels)
    for c in range(channels):
        dest[..., c] = px if px.ndim == 2 else px[..., c]
    out = [SIGNATURE, _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, COLOUR_TYPE[channels], 0, 0, 0))]
    if dpi:
        per_metre = int(round(dpi / 0.0254))
        out.append(_chunk(b"pHYs", struct.pack(">IIB", per_metre, per_metre, 1)))
    # zlib reads the array's buffer: no bytes copy of the image (a fifth of a figure's encoding time)
    out += [_chunk(b"IDAT", zlib.compress(rows.data, LEVEL)), _chunk(b"IEND", b"")]
    return b"".join(out)


def encode_indexed(indices: np.ndarray, palette: np.ndarray) -> bytes:
    """An indexed PNG (colour type 3): ``indices`` (H, W) uint8 into ``palette`` (N <= 256, 3) uint8 RGB."""
    idx, pal = np.asarray(indices), np.asarray(palette)
    if idx.dtype != np.uint8 or idx.ndim != 2 or 0 in idx.shape:
        raise ValueError(f"expected (H, W) uint8 indices, H and W >= 1, got {idx.dtype} {idx.shape}")
    if pal.dtype != np.uint8 or pal.ndim != 2 or pal.shape[1] != 3 or not 1 <= len(pal) <= 256:
        raise ValueError(f"expected an (N, 3) uint8 palette, 1 <= N <= 256, got {pal.dtype} {pal.shape}")
    if int(idx.max()) >= len(pal):      # a reader would refuse the file: say it here
        raise ValueError(f"index {int(idx.max())} outside the palette's {len(pal)} colours")
    h, w = idx.shape
    rows = np.zeros((h, w + 1), np.uint8)
    rows[:, 1:] = idx
    return b"".join([SIGNATURE, _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 3, 0, 0, 0)),
                     _chunk(b"PLTE", np.ascontiguousarray(pal).tobytes()),
                     _chunk(b"IDAT", zlib.compress(rows.data, zlib.Z_BEST_COMPRESSION)), _chunk(b"IEND", b"")])


def write_bytes(path: Path, data: bytes):
    """A PNG's bytes into ``path`` atomically (a reader never sees half a file)."""
    with atomic(path) as tmp:
        Path(tmp).write_bytes(data)


def write(path: Path, pixels: np.ndarray, dpi: float | None = None):
    """encode()'s PNG into ``path`` atomically (a reader never sees half a file)."""
    write_bytes(path, encode(pixels, dpi))
