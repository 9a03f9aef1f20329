"""matplotlib's own Agg text drawing, pixel for pixel, with its work kept across figures.

The report's section figures (dsm/report/sections/: soft, hybrid, motion, cascades, cache) are
plain matplotlib figures: their tick labels, bar labels and legends are drawn by RendererAgg,
which lays a string out (FreeType through ``FT2Font._layout``), then renders and blits each glyph
at its sub-pixel place, and parses a ``$...$`` tick label (a symlog axis's) with pyparsing. A
renderer is made per figure and matplotlib's caches (text metrics, parsed mathtext) live in it, so
every figure did all of that again: most of such a figure's drawing time.

``canvas(fig)`` gives a figure a canvas whose renderer keeps that work in process-wide caches:

- a string's layout (its glyphs and their offsets) and its width, height and descent, keyed by the
  string, the font properties, the rcParams that choose the font and its hinting, and the dpi;
- a rendered glyph, keyed by its font, size, dpi, index, rotation, hinting, antialiasing and the
  sub-pixel part (1/64 pixel, FreeType's unit) of where it lands: FreeType rasterizes an outline
  moved by whole pixels into the same bitmap moved by those pixels, so the cached bitmap is blitted
  at the whole-pixel part;
- one mathtext parser for every renderer (matplotlib's keeps its parses per parser).

The glyph loop follows matplotlib 3.11's ``RendererAgg._draw_text_glyphs_and_boxes`` and the line
metrics its ``text.Text._get_layout``, with their results kept. Those parts derive from matplotlib,
Copyright (c) 2012- Matplotlib Development Team; All Rights Reserved, used under the Matplotlib
License Agreement (PSF-based, https://matplotlib.org/stable/project/license.html), whose notice this keeps.
The layouts and glyphs are cached where matplotlib draws a text glyph by glyph (3.11 on); with an
earlier matplotlib, the metrics and the parses only.

What is drawn is what RendererAgg draws (tests/test_report_glyph_cache.py compares the figures'
pixels with matplotlib's own canvas). Unlike dsm/report/canvas.py's whole-string bitmaps, which
place a string on whole pixels, nothing moves.
"""
from __future__ import annotations

import functools
import math

import numpy as np

MAX_CACHED = 50000        # entries per cache (a glyph's bitmap is a few hundred bytes)
# the rcParams that choose a FontProperties' font files (font_manager.findfont keys on the same)
FONT_RC = ("font.family", "font.style", "font.variant", "font.weight", "font.stretch", "font.size",
           "font.serif", "font.sans-serif", "font.cursive", "font.fantasy", "font.monospace",
           "text.hinting", "text.hinting_factor", "text.kerning_factor")


def _frozen(v):
    return tuple(v) if isinstance(v, list) else v


def font_key(prop, dpi) -> tuple:
    """What decides a FontProperties' font files, size in pixels and hinting (its hash: family, style,
    weight, size, file...; the rcParams that resolve a generic family; the dpi)."""
    import matplotlib as mpl
    return (hash(prop), dpi) + tuple(_frozen(dict.get(mpl.rcParams, k)) for k in FONT_RC)


# the font tables matplotlib's Text reads a line's least ascent, descent and gap from, in its order
HEIGHT_TABLES = (("OS/2", "sTypoLineGap", "sTypoAscender", "sTypoDescender"), ("hhea", "lineGap", "ascent", "descent"))
_HEIGHTS = {}


def font_height_metrics(prop, dpi) -> tuple:
    """(least ascent, least descent, line gap) in pixels of ``prop``'s font at ``dpi``, as matplotlib's
    Text computes them from the font's tables (text.Text._get_layout) before laying out a line, once
    per font (it looked the font and its tables up for every text it laid out); (None, None, None)
    where the font has neither table (Text then measures "lp")."""
    key = font_key(prop, dpi)
    got = _HEIGHTS.get(key)
    if got is None:
        from matplotlib.font_manager import fontManager, get_font
        font = get_font(fontManager._find_fonts_by_props(prop))
        got = (None, None, None)
        for table_name, gap_key, ascent_key, descent_key in HEIGHT_TABLES:
            table = font.get_sfnt_table(table_name)
            if table is None:
                continue
            scale = 1 / font.get_sfnt_table("head")["unitsPerEm"] * prop.get_size_in_points() * dpi / 72
            got = (table[ascent_key] * scale, -table[descent_key] * scale, table[gap_key] * scale)
            break
        _put(_HEIGHTS, key, got)
    return got


def _put(cache: dict, key, value):
    if len(cache) > MAX_CACHED:
        cache.clear()
    cache[key] = value
    return value


@functools.lru_cache(maxsize=1)
def _renderer_class():
    """RendererAgg with its text work cached across renderers (made on first use: matplotlib is
    imported only when a figure is drawn). The glyphs are cached where matplotlib draws a text glyph
    by glyph (3.11 on); before, its strings' metrics and its mathtext parses only."""
    from matplotlib.backends.backend_agg import RendererAgg
    from matplotlib.ft2font import FT2Font

    sizes, shared = {}, {}

    class MetricsCacheRenderer(RendererAgg):
        """RendererAgg whose text metrics and mathtext parses are shared by every renderer of this process."""

        def __init__(self, width, height, dpi):
            super().__init__(width, height, dpi)
            # the first renderer's parser (its output type is the one this matplotlib's RendererAgg uses)
            self.mathtext_parser = shared.setdefault("parser", self.mathtext_parser)

        def _get_font_height_metrics(self, prop):
            # matplotlib's Text asks a renderer that has this (text.Text._get_layout, 3.11 on); the figure's
            # dpi is the renderer's (the canvas's get_renderer makes one per figure dpi)
            return font_height_metrics(prop, self.dpi)

        def get_text_width_height_descent(self, s, prop, ismath):
            """Width, height and descent of ``s`` in pixels, as RendererAgg measures them."""
            if ismath:
                return super().get_text_width_height_descent(s, prop, ismath)
            key = (s,) + font_key(prop, self.dpi)
            got = sizes.get(key)
            return got if got is not None else _put(sizes, key, super().get_text_width_height_descent(s, prop, ismath))

    if not (hasattr(RendererAgg, "_draw_text_glyphs_and_boxes") and hasattr(FT2Font, "_layout")):
        return MetricsCacheRenderer
    from matplotlib.backends.backend_agg import get_hinting_flag
    from matplotlib.ft2font import RenderMode
    layouts, glyphs = {}, {}

    class GlyphCacheRenderer(MetricsCacheRenderer):
        """MetricsCacheRenderer whose string layouts and glyph bitmaps are shared too."""

        def draw_text(self, gc, x, y, s, prop, angle, ismath=False, mtext=None):
            """``s`` at (x, y) (pixels, y down), rotated by ``angle`` degrees, as RendererAgg draws it."""
            if ismath:
                return self.draw_mathtext(gc, x, y, s, prop, angle)
            features = mtext.get_fontfeatures() if mtext is not None else None
            language = mtext.get_language() if mtext is not None else None
            key = (s, _frozen(features), _frozen(language)) + font_key(prop, self.dpi)
            items = layouts.get(key)
            if items is None:
                font = self._prepare_font(prop)
                items = _put(layouts, key, [(i.ft_object, i.glyph_index, i.x, i.y) for i in font._layout(
                    s, flags=get_hinting_flag(), features=features, language=language)])
            size = prop.get_size_in_points()
            self._draw_text_glyphs_and_boxes(gc, x, y, angle, ((f, size, g, 0, 1, dx, dy) for f, g, dx, dy in items), [])

        def _draw_text_glyphs_and_boxes(self, gc, x, y, angle, glyph_list, boxes):
            # RendererAgg's, each glyph's bitmap rendered once per sub-pixel place
            cos, sin = math.cos(math.radians(angle)), math.sin(math.radians(angle))
            flags = get_hinting_flag()
            antialiased = bool(gc.get_antialiased())
            height = self.height
            for font, size, index, slant, extend, dx, dy in glyph_list:      # dy is upwards
                x64 = round(0x40 * (x + dx * cos - dy * sin))
                y64 = round(0x40 * (height - y + dx * sin + dy * cos))        # FreeType's y is upwards
                key = (id(font), size, self.dpi, index, cos, sin, slant, extend, x64 & 63, y64 & 63, flags,
                       antialiased)
                got = glyphs.get(key)
                if got is None or got[0] is not font:
                    font.set_size(size, self.dpi)
                    matrix = (0x10000 * np.array([[cos, -sin], [sin, cos]])
                              @ [[extend, extend * slant], [0, 1]]).round().astype(int)
                    font._set_transform(matrix, [x64 & 63, y64 & 63])
                    bitmap = font._render_glyph(index, flags, RenderMode.NORMAL if antialiased else RenderMode.MONO)
                    buffer = bitmap.buffer
                    if not antialiased:
                        buffer *= 0xff
                    got = _put(glyphs, key, (font, buffer, bitmap.left, bitmap.top))
                _, buffer, left, top = got
                # draw_text_image's y is downwards and the bitmap's bottom side
                self._renderer.draw_text_image(buffer, left + (x64 >> 6), int(height) - (top + (y64 >> 6))
                                               + buffer.shape[0], 0, gc)
            if boxes:
                super()._draw_text_glyphs_and_boxes(gc, x, y, angle, (), boxes)

    return GlyphCacheRenderer


@functools.lru_cache(maxsize=1)
def _canvas_class():
    """FigureCanvasAgg drawing with _renderer_class()'s renderer (made once, on first use)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    renderer_class = _renderer_class()

    class GlyphCacheCanvas(FigureCanvasAgg):
        """FigureCanvasAgg with the cached-text renderer."""

        def get_renderer(self):
            """The renderer for the figure's current size and dpi (kept while they stay)."""
            w, h = self.get_width_height(physical=True)
            key = w, h, self.figure.dpi
            if self._lastKey != key:
                self.renderer = renderer_class(w, h, self.figure.dpi)
                self._lastKey = key
            return self.renderer

    return GlyphCacheCanvas


def canvas(fig):
    """Set ``fig``'s canvas to an Agg canvas whose renderer keeps its text work across figures (savefig
    draws on it); returns it."""
    return _canvas_class()(fig)
