"""What the report's figures are drawn on: matplotlib's Agg canvas with two shortcuts.

A text is rendered as one bitmap of its whole string (FreeType lays it out in C) and kept, so a
label drawn again (the rate tick labels, legends and axis labels recur in every figure of a run)
costs one blit: matplotlib 3.11's Agg renderer draws each glyph as a Python step (a transform
matrix built in numpy, one FreeType render, one blit), a quarter of a figure's drawing time. The
string's bitmap is what its earlier versions drew, at the same size and font, placed on whole
pixels. Mathtext (``$...$``) and TeX are drawn by matplotlib as before.

A panel's tick labels are one artist (``tick_labels``), laid out as matplotlib lays out a Text and
drawn from those bitmaps: a Text per label was the larger part of a figure's text time.

While ``reusing()`` (the report's drawing, jobs.run_jobs), figures of one layout are drawn on
one Figure (``pooled``), cleared of the last figure's artists (``clear``), not built anew:
building a panel's Axes was a fifth of a figure's cost. A figure drawn so equals, pixel for
pixel, the same figure drawn on a new Figure (tests/test_report_canvas.py).
"""
from __future__ import annotations

import contextlib
import warnings
import functools
import math

import numpy as np

from . import glyph_cache

MAX_CACHED = 20000        # strings kept per process (a bitmap of a label is a few hundred bytes)


def _renderer_class():
    """RendererAgg with cached string bitmaps and metrics (made on first use: matplotlib is
    imported only when a figure is drawn)."""
    from matplotlib.backends.backend_agg import RendererAgg, get_hinting_flag

    bitmaps, metrics = {}, {}

    def bitmap(font, antialiased: bool) -> tuple:
        """The string ``font`` holds (set_text) drawn: (image, x offset, y offset, descent) in pixels."""
        font.draw_glyphs_to_bitmap(antialiased=antialiased)
        xo, yo = font.get_bitmap_offset()
        return np.array(font.get_image(), dtype=np.uint8), xo / 64.0, yo / 64.0, font.get_descent() / 64.0

    class CachedTextRenderer(RendererAgg):
        """RendererAgg drawing each plain text as one cached bitmap of the whole string."""

        def _get_font_height_metrics(self, prop):
            # matplotlib's Text asks a renderer that has this (text.Text._get_layout) for a font's line
            # metrics, which it otherwise looks up for every text; the figure's dpi is the renderer's
            return glyph_cache.font_height_metrics(prop, self.dpi)

        def get_text_width_height_descent(self, s, prop, ismath):
            """Width, height and descent of ``s`` in pixels (cached per string, font and dpi)."""
            if ismath:
                return super().get_text_width_height_descent(s, prop, ismath)
            flags = get_hinting_flag()
            key = (s, hash(prop), self.dpi, flags)
            got = metrics.get(key)
            if got is None:
                font = self._prepare_font(prop)
                font.set_text(s, 0.0, flags=flags)       # FreeType's layout: about 70 us a character
                w, h = font.get_width_height()
                got = glyph_cache.bounded_put(metrics, key, (w / 64.0, h / 64.0, font.get_descent() / 64.0), MAX_CACHED)
                # a string measured is drawn next (antialiased, as every text here): its bitmap from
                # this layout, not from a second one
                if key + (True,) not in bitmaps:
                    glyph_cache.bounded_put(bitmaps, key + (True,), bitmap(font, True), MAX_CACHED)
            return got

        def draw_text(self, gc, x, y, s, prop, angle, ismath=False, mtext=None):
            """``s`` at (x, y) (pixels, y down: the text's baseline start), rotated by ``angle`` degrees."""
            if ismath:
                return super().draw_text(gc, x, y, s, prop, angle, ismath, mtext)
            # hash(prop): family, style, weight, size, file: a snapshot (a FontProperties is mutable)
            flags = get_hinting_flag()
            key = (s, hash(prop), self.dpi, flags, bool(gc.get_antialiased()))
            got = bitmaps.get(key)
            if got is None:
                font = self._prepare_font(prop)
                font.set_text(s, 0.0, flags=flags)
                got = glyph_cache.bounded_put(bitmaps, key, bitmap(font, key[-1]), MAX_CACHED)
            image, xo, yo, descent = got
            if not image.size:
                return
            # the bitmap's lower left corner: the descent turns with the text (as matplotlib placed a
            # whole string's bitmap before it drew glyph by glyph)
            xd, yd = descent * math.sin(math.radians(angle)), descent * math.cos(math.radians(angle))
            self._renderer.draw_text_image(image, round(x + xo + xd), round(y + yo + yd) + 1, angle, gc)

    return CachedTextRenderer


def tick_labels(xy, texts, transform, ha: str, va: str, size: float):
    """Tick labels ``texts`` (``size`` points) at points ``xy`` of ``transform`` as one artist."""
    return _tick_label_class()(xy, texts, transform, ha, va, size)


@functools.lru_cache(maxsize=1)
def _tick_label_class():
    """TickLabels (made on first use, as the renderer: matplotlib is imported only when a figure is drawn)."""
    from matplotlib.artist import Artist
    from matplotlib.font_manager import FontProperties

    class TickLabels(Artist):
        """Single-line labels at points of one transform, laid out as matplotlib lays out a Text (its
        box aligned by ``ha`` and ``va``, a line at least as tall as "lp") and drawn straight from the
        renderer: a Text per tick label is laid out and drawn as an artist of its own, the larger
        part of a figure's text time."""

        def __init__(self, xy, texts, transform, ha, va, size):
            super().__init__()
            self.xy, self.texts, self.ha, self.va = np.asarray(xy, float).reshape(-1, 2), list(texts), ha, va
            self.prop = FontProperties(size=size)
            self.set_transform(transform)
            self.set_clip_on(False)

        def draw(self, renderer):
            """Each label at its point, black, antialiased."""
            if not self.get_visible() or not self.texts:
                return
            gc = renderer.new_gc()
            gc.set_foreground((0.0, 0.0, 0.0, 1.0), isRGBA=True)
            gc.set_antialiased(True)
            _, lp_h, lp_d = renderer.get_text_width_height_descent("lp", self.prop, ismath=False)
            height = renderer.get_canvas_width_height()[1]
            for (x, y), s in zip(self.get_transform().transform(self.xy), self.texts):
                w, h, d = renderer.get_text_width_height_descent(s, self.prop, ismath=False)
                h, d = max(h, lp_h), max(d, lp_d)
                x += {"left": 0.0, "center": -w / 2, "right": -w}[self.ha]
                y += {"baseline": 0.0, "bottom": d, "center": d - h / 2, "top": d - h}[self.va]
                renderer.draw_text(gc, x, height - y if renderer.flipy() else y, s, self.prop, 0.0)
            gc.restore()
            self.stale = False

    return TickLabels


@functools.lru_cache(maxsize=1)
def _canvas_class():
    """FigureCanvasAgg drawing with CachedTextRenderer (made once, on first use)."""
    return glyph_cache.agg_canvas_class(_renderer_class())


def canvas(fig):
    """An Agg canvas for ``fig`` (set as its canvas: savefig draws on it) whose renderer caches
    text bitmaps; a figure drawn again (a pooled one) keeps its canvas, so its renderer and the
    text metrics matplotlib keeps per renderer."""
    cls = _canvas_class()
    return fig.canvas if type(fig.canvas) is cls else cls(fig)


# ------------------------------------------------------------------ one Figure per layout

# while reusing(): layout key -> (Figure, axes) this process drew before; None: every figure new
_POOL = {"figures": None}


@contextlib.contextmanager
def reusing():
    """Within it, figures of one layout (pooled()'s key) are drawn on one Figure, cleared of the
    last figure's artists: building a panel's Axes is a fifth of a figure's drawing time, and a
    run's figures have a few layouts. Outside it, each figure is new (a caller may keep it)."""
    before = _POOL["figures"]
    _POOL["figures"] = {} if before is None else before
    try:
        with warnings.catch_warnings():
            # a pooled panel keeps the last figure's (log) scale while the next one's data, which may
            # hold no positive value, is plotted; figures.set_scale then sets the scale it wants, so
            # matplotlib's warning about the scale it is leaving says nothing about the figure
            warnings.filterwarnings("ignore", message="Data has no positive values", category=UserWarning)
            yield
    finally:
        _POOL["figures"] = before


def pooled(key, make, scales: bool = True):
    """(Figure, axes) for layout ``key``: the pooled one, cleared (see reusing(); ``scales``
    False: its axes keep their scales, for a caller that sets every one), else ``make()``'s."""
    pool = _POOL["figures"]
    if pool is None:
        return make()
    if key in pool:
        fig, axes = pool[key]
        clear(fig, axes, scales)
        return fig, axes
    pool[key] = make()
    return pool[key]


def clear(fig, axes, scales: bool = True):
    """Take every artist a drawing added off ``fig`` and its ``axes`` (an array of Axes), and put
    their limits, labels, colour cycle and (``scales``) scales back as a new figure's (the
    suptitle is kept: drawing sets its text)."""
    import matplotlib
    from matplotlib.transforms import Bbox
    for ax in np.ravel(axes):
        for a in [*ax.lines, *ax.collections, *ax.texts, *ax.artists, *ax.patches, *ax.images, *ax.tables]:
            a.remove()
        ax.set_title("")
        ax.set_xlabel("")
        ax.set_ylabel("")
        ax.set_prop_cycle(None)
        if scales and ax.get_xscale() != "linear":
            ax.set_xscale("linear")
        if scales and ax.get_yscale() != "linear":
            ax.set_yscale("linear")
        ax.set_autoscalex_on(True)
        ax.set_autoscaley_on(True)
        ax.dataLim = Bbox.null()          # a panel left empty must not keep the last figure's extent
        ax.ignore_existing_data_limits = True
        ax.xaxis.labelpad = ax.yaxis.labelpad = matplotlib.rcParams["axes.labelpad"]
        ax.__dict__.pop("legend_texts", None)
        ax.__dict__.pop("legend_entries", None)
    keep = getattr(fig, "_suptitle", None)
    for a in [*fig.texts, *fig.artists, *fig.lines, *fig.patches, *fig.images]:
        if a is not keep:
            a.remove()
