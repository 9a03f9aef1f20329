"""The Agg canvas the report's figures are drawn on: matplotlib's, but a text is rendered as one
bitmap of its whole string (FreeType lays it out in C) and kept, so a label drawn again (the same
rate tick labels, legends and axis labels recur in every figure of a run) costs one blit.

matplotlib 3.11's Agg renderer draws each glyph of a text as a Python step (a transform matrix
built in numpy, one FreeType render, one blit), about a quarter of a figure's drawing time;
the string's bitmap is what matplotlib up to 3.9 drew, at the same size and font, placed on
whole pixels. Mathtext (``$...$``) and TeX are drawn by matplotlib as before.
"""
from __future__ import annotations

import functools
import math

import numpy as np

MAX_CACHED = 20000        # strings kept per process (a bitmap of a label is a few hundred bytes)


def _renderer_class():
    """RendererAgg with cached string bitmaps and metrics (made on first use: matplotlib is
    imported only when a figure is drawn)."""
    from matplotlib.backends.backend_agg import RendererAgg, get_hinting_flag

    bitmaps, metrics = {}, {}

    class CachedTextRenderer(RendererAgg):
        """RendererAgg drawing each plain text as one cached bitmap of the whole string."""

        def get_text_width_height_descent(self, s, prop, ismath):
            """Width, height and descent of ``s`` in pixels (cached per string, font and dpi)."""
            if ismath:
                return super().get_text_width_height_descent(s, prop, ismath)
            key = (s, hash(prop), self.dpi)
            got = metrics.get(key)
            if got is None:
                font = self._prepare_font(prop)
                font.set_text(s, 0.0, flags=get_hinting_flag())
                w, h = font.get_width_height()
                got = (w / 64.0, h / 64.0, font.get_descent() / 64.0)
                if len(metrics) > MAX_CACHED:
                    metrics.clear()
                metrics[key] = got
            return got

        def draw_text(self, gc, x, y, s, prop, angle, ismath=False, mtext=None):
            """``s`` at (x, y) (pixels, y down: the text's baseline start), rotated by ``angle`` degrees."""
            if ismath:
                return super().draw_text(gc, x, y, s, prop, angle, ismath, mtext)
            key = (s, hash(prop), self.dpi, bool(gc.get_antialiased()))
            got = bitmaps.get(key)
            if got is None:
                font = self._prepare_font(prop)
                font.set_text(s, 0.0, flags=get_hinting_flag())
                font.draw_glyphs_to_bitmap(antialiased=key[3])
                xo, yo = font.get_bitmap_offset()
                got = (np.array(font.get_image(), dtype=np.uint8), xo / 64.0, yo / 64.0, font.get_descent() / 64.0)
                if len(bitmaps) > MAX_CACHED:
                    bitmaps.clear()
                bitmaps[key] = got
            image, xo, yo, descent = got
            if not image.size:
                return
            # the bitmap's lower left corner: the descent turns with the text (matplotlib 3.9's placement)
            xd, yd = descent * math.sin(math.radians(angle)), descent * math.cos(math.radians(angle))
            self._renderer.draw_text_image(image, round(x + xo + xd), round(y + yo + yd) + 1, angle, gc)

    return CachedTextRenderer


@functools.lru_cache(maxsize=1)
def _canvas_class():
    """FigureCanvasAgg with the cached-text renderer (made once, on first use)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    renderer_class = _renderer_class()

    class CachedTextCanvas(FigureCanvasAgg):
        """FigureCanvasAgg drawing with CachedTextRenderer."""

        def get_renderer(self):
            """The renderer for the figure's current size and dpi (kept while they stay)."""
            w, h = self.get_width_height(physical=True)
            key = w, h, self.figure.dpi
            if self._lastKey != key:
                self.renderer = renderer_class(w, h, self.figure.dpi)
                self._lastKey = key
            return self.renderer

    return CachedTextCanvas


def canvas(fig):
    """An Agg canvas for ``fig`` (set as its canvas: savefig draws on it) whose renderer caches text bitmaps."""
    return _canvas_class()(fig)
