"""matplotlib's own Agg text drawing, with the text's measurements kept across figures.

The report's section figures (dsm/report/sections/: soft, hybrid, motion, cascades, cache) are
plain matplotlib figures: their tick labels, bar labels and legends are measured and drawn by
RendererAgg, which lays each string out with FreeType and parses a ``$...$`` tick label (a symlog
axis's) with pyparsing. A renderer is made per figure and matplotlib's caches (text metrics, parsed
mathtext) live in it, so every figure measured and parsed all of its text again.

``canvas(fig)`` gives a figure a canvas whose renderer remembers, for the whole process, what
matplotlib answered:

- a string's width, height and descent, keyed by the string, the font properties, the rcParams
  that choose the font and its hinting, and the dpi;
- a font's line metrics (least ascent, descent, line gap), read from its tables as matplotlib 3.11's
  ``text.Text._get_layout`` reads them (that function derives from matplotlib, Copyright (c) 2012-
  Matplotlib Development Team; All Rights Reserved, used under the Matplotlib License Agreement,
  PSF-based, https://matplotlib.org/stable/project/license.html, whose notice this keeps);
- one mathtext parser for every renderer (matplotlib's keeps its parses per parser).

The glyphs themselves are drawn by RendererAgg (tests/test_report_glyph_cache.py compares the
figures' pixels with matplotlib's own canvas).
"""
from __future__ import annotations

import functools


MAX_CACHED = 50000        # entries per cache (a string's size or a font's metrics: a few numbers each)
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
        bounded_put(_HEIGHTS, key, got)
    return got


def bounded_put(cache: dict, key, value, limit: int = MAX_CACHED):
    """``cache[key] = value``, the cache emptied first once it holds more than ``limit`` entries; ``value``."""
    if len(cache) > limit:
        cache.clear()
    cache[key] = value
    return value


@functools.lru_cache(maxsize=1)
def _renderer_class():
    """RendererAgg with its text measurements and mathtext parses kept across renderers (made on first
    use: matplotlib is imported only when a figure is drawn)."""
    from matplotlib.backends.backend_agg import RendererAgg

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
            if got is None:
                got = bounded_put(sizes, key, super().get_text_width_height_descent(s, prop, ismath))
            return got

    # the glyphs themselves are drawn by RendererAgg: a process-wide cache of layouts and glyph bitmaps
    # (drawn at each glyph's sub-pixel place) once failed a report in the full suite with FreeType's
    # "invalid outline" on a font object matplotlib's own renderers share, not reproduced alone; the
    # metrics and the mathtext parses, which only remember what matplotlib answered, are kept
    return MetricsCacheRenderer


def agg_canvas_class(renderer_class):
    """A FigureCanvasAgg class whose figures are drawn by ``renderer_class`` (a RendererAgg), one renderer
    kept per figure while its size and dpi stay."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    class RendererCanvas(FigureCanvasAgg):
        """FigureCanvasAgg drawing with the given renderer class."""

        def get_renderer(self):
            """The renderer for the figure's current size and dpi (kept while they stay)."""
            w, h = self.get_width_height(physical=True)
            key = w, h, self.figure.dpi
            if self._lastKey != key:
                self.renderer = renderer_class(w, h, self.figure.dpi)
                self._lastKey = key
            return self.renderer

    return RendererCanvas


@functools.lru_cache(maxsize=1)
def _canvas_class():
    """The section figures' canvas class: _renderer_class()'s renderer (made once, on first use)."""
    return agg_canvas_class(_renderer_class())


def canvas(fig):
    """Set ``fig``'s canvas to an Agg canvas whose renderer keeps its text work across figures (savefig
    draws on it); returns it."""
    return _canvas_class()(fig)
