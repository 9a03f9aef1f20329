"""The section figures' renderer (dsm/report/glyph_cache.py) against matplotlib's own: a figure with
rotated, mathtext, multi-line and legend texts drawn on it equals, pixel for pixel, the same figure on
matplotlib's FigureCanvasAgg, drawn cold and again from the caches at other sub-pixel places; the
font's line metrics are the ones matplotlib's Text reads from the font's tables; a table's rows
(dsm.report.templates.table_rows) are the bytes the row and cell macros wrote."""
import numpy as np
import pytest


def _figure(dx: float = 0.0):
    """A figure with what the section figures draw: bar labels turned 90 degrees, a symlog axis (mathtext
    tick labels), a title, a suptitle, a two-line text and a legend; ``dx`` moves the texts by a fraction
    of a pixel."""
    from matplotlib.figure import Figure
    fig = Figure(figsize=(5.1, 3.3))
    ax = fig.subplots()
    ax.bar(range(4), [1e-3, 0.2, 0.0, 0.5], color=["C0", "C1", "C2", "C3"], label="bars")
    ax.plot([0, 3], [1e-4, 0.9], ".-", label="pcf texel k=1.5 (normal offset 0.3)")
    ax.set_yscale("symlog", linthresh=1e-4)
    ax.set_xticks(range(4), ["slope_scaled nearest", "constant pcf3", "receiver_plane pcf5", "none"],
                  rotation=90, fontsize=6)
    ax.set_title(f"MAE umbra, shifted {dx:g}", fontsize=8)
    ax.text(0.3 + dx / 500, 0.5, "two lines:\npeter-panning rate", transform=ax.transAxes, fontsize=7)
    ax.legend(fontsize=6, loc="upper left")
    fig.suptitle("area, light rect: |V - V*| by region", fontsize=8)
    fig.subplots_adjust(bottom=0.42 + dx / 1000, top=0.86, left=0.12, right=0.97)
    return fig


def _pixels(fig, canvas_class) -> np.ndarray:
    cv = canvas_class(fig)
    fig.set_dpi(80)
    cv.draw()
    return np.asarray(cv.buffer_rgba()).copy()


@pytest.mark.parametrize("dx", [0.0, 0.37, 0.5])
def test_a_section_figure_is_matplotlib_s_pixel_for_pixel(dx):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from dsm.report import glyph_cache
    want = _pixels(_figure(dx), FigureCanvasAgg)
    assert (want[..., :3] < 128).any()                       # something was drawn
    for _ in range(2):                                       # cold, then from the caches
        assert np.array_equal(_pixels(_figure(dx), glyph_cache.canvas), want)


def test_the_line_metrics_are_those_matplotlib_reads_from_the_font():
    """(least ascent, least descent, gap) as text.Text computes them: the font's OS/2 table, scaled."""
    from matplotlib.font_manager import FontProperties, fontManager, get_font

    from dsm.report import glyph_cache
    for size, dpi in ((7.2, 120), (6, 80), (9, 72)):
        prop = FontProperties(size=size)
        font = get_font(fontManager._find_fonts_by_props(prop))
        os2 = font.get_sfnt_table("OS/2")
        scale = size * dpi / 72 / font.get_sfnt_table("head")["unitsPerEm"]
        want = (os2["sTypoAscender"] * scale, -os2["sTypoDescender"] * scale, os2["sTypoLineGap"] * scale)
        assert glyph_cache.font_height_metrics(prop, dpi) == pytest.approx(want, rel=1e-12)


def test_a_text_s_extent_is_matplotlib_s():
    """A multi-line text's box on the kit's renderers (line metrics from the cache) is matplotlib's."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from dsm.report import canvas, glyph_cache
    for make_canvas in (glyph_cache.canvas, canvas.canvas):
        fig = Figure(figsize=(3, 2), dpi=120)
        t = fig.text(0.1, 0.2, "one\ntwo lines, gj\nthree", fontsize=7.2, linespacing=1.6)
        want = t.get_window_extent(FigureCanvasAgg(fig).get_renderer()).bounds
        assert t.get_window_extent(make_canvas(fig).get_renderer()).bounds == want


# the row and cell macros of macros.html before table_rows replaced them (the reference)
OLD_MACROS = '''{% macro cell(c) -%}
<td{% if c.num %} class=n{% endif %}{% if c.value is not none %} data-v="{{ c.value }}"{% endif %}
{%- if c.title is not none %} title="{{ c.title }}"{% endif %}>
{%- if c.href is not none %}<a href="{{ c.href }}">{{ c.text }}</a>{% else %}{{ c.text }}{% endif %}</td>
{%- endmacro %}

{% macro row(r) -%}
<tr{% if r.id %} id={{ r.id }}{% endif %}{% if r.cls %} class={{ r.cls }}{% endif %}
{%- for k, v in r.data.items() %} data-{{ k }}="{{ v }}"{% endfor %}>
{%- for c in r.cells %}{{ cell(c) }}{% endfor %}</tr>
{%- endmacro %}
<tbody>
{% for r in rows %}
{{ row(r) }}
{% endfor %}
</tbody>'''


def test_a_table_s_rows_are_the_macros_bytes():
    import jinja2
    from markupsafe import Markup

    from dsm.report.templates import Cell, Row, Table, environment
    rows = [Row([Cell("a<b & \"c\"", "x'y"), Cell(3, 3, num=True), Cell(0.1, 0.1, num=True, title="t<1>"),
                 Cell(Markup("<i>ok</i>"), None, href="p?a=1&b=2"), Cell(None), Cell("", "")],
                {"scene": "plane<box>", "case": 7, "err": "", "label": 'q"uote'}, "case-7", "odd"),
            Row([Cell("-", "", num=True), Cell(1.5e-07, repr(1.5e-07), num=True)]),
            Row([], {}, "", None)]
    env = jinja2.Environment(autoescape=True, undefined=jinja2.StrictUndefined, trim_blocks=True,
                             lstrip_blocks=True)
    want = env.from_string(OLD_MACROS).render(rows=rows)
    page = environment().from_string('{% import "macros.html" as m %}{{ m.table(t) }}').render(
        t=Table([("a", "text"), ("b", None)], rows))
    assert want in page
    assert page.count("<tr") == 1 + len(rows)
