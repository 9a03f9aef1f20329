"""The pages' templates (dsm.report.templates): markup in a name is text on the page, a variable a page
does not give is an error, every script and style is inside the page, and a page's first screen takes
a block of its own."""
from html.parser import HTMLParser
from pathlib import Path

import jinja2
import pytest

ODD = '<i>x"&\'</i>'            # a contender (and a scene) whose name is markup and quotes


class Page(HTMLParser):
    """A page's ranking links (href, text), the texts of its h1 and p.answer, its external references."""

    def __init__(self):
        super().__init__()
        self.links, self.h1, self.answers, self.external, self._in = [], [], [], [], None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "a" and a.get("href", "").startswith("contenders/"):
            self._in = ("link", a["href"])
            self.links.append([a["href"], ""])
        elif tag == "h1":
            self._in = ("h1",)
            self.h1.append("")
        elif tag == "p" and a.get("class") == "answer":
            self._in = ("answer",)
            self.answers.append("")
        if (tag == "script" and "src" in a) or tag == "link":
            self.external.append((tag, a))

    def handle_data(self, data):
        if self._in and self._in[0] == "link":
            self.links[-1][1] += data
        elif self._in:
            {"h1": self.h1, "answer": self.answers}[self._in[0]][-1] += data

    def handle_endtag(self, tag):
        if tag in ("a", "h1", "p"):
            self._in = None


def _record(scene, contender, rate):
    return {"scene": scene, "unit": "m", "offset": "0", "light": "spot", "contender": contender, "n_receivers": 1000,
            "n_gt_shadowed": 500, "n_acne": int(rate * 1000), "n_peterpan": 0, "acne_rate": rate, "peterpan_rate": 0.0,
            "error_rate": rate, "texel_size": 0.01, "build_ms": 1.0, "lookup_ms": 1.0, "params": ""}


@pytest.fixture(scope="module")
def board(tmp_path_factory):
    """A hand-made result whose contender and scene names are markup, written as its pages."""
    from dsm.benchmark import page
    out = tmp_path_factory.mktemp("board")
    cases = [_record(s, c, r) for s in ("a", ODD) for c, r in (("bevy", 0.1), (ODD, 0.3))]
    cases += [{"scene": s, "unit": "m", "offset": "0", "light": "spot", "contender": "oracle", "n_receivers": 1000,
               "world_objective": 0.05, "texel_objective": 0.05, "per_texel_objective": 0.0} for s in ("a", ODD)]
    doc = {"suite": "dsm-bench-5", "suite_sha256": "0" * 64, "size": "test", "dsm_version": "0", "variant": "x",
           "versions": {"dsm_git_commit": "c"}, "machine": {"cpu": "cpu", "cores": 1}, "cases": cases}
    page.write_page(doc, out)
    return out


def _parse(path: Path) -> Page:
    p = Page()
    p.feed(path.read_text(encoding="utf-8"))
    return p


def test_a_name_that_is_markup_is_shown_as_its_text(board):
    """The ranking links each contender by its own name, read back from the page as text (the markup
    escaped, not interpreted), and so does the cases table, a link per record; its page's heading names it
    the same way."""
    from dsm.benchmark import contenders
    got = _parse(board / "leaderboard.html")
    ranked = [link for link in got.links if "#" not in link[0]]        # the cases table links a card (#c<i>)
    assert sorted(ranked) == sorted([[contenders.page_path(c), c] for c in ("bevy", ODD)])
    assert got.answers[0] == (f"Ranking (mean error rate over every scene, unit and light, at the origin): "
                              f"1. bevy (0.1000), 2. {ODD} (0.3000).")
    text = (board / "leaderboard.html").read_text()
    assert sorted(name for href, name in got.links if "#" in href) == sorted(["bevy", ODD] * 2)
    assert ODD not in text and "<i>" not in text
    assert _parse(board / contenders.page_path(ODD)).h1 == [f"{ODD}: its 2 cases"]


def test_every_script_and_style_is_inside_the_page(board):
    """No page refers to a script or a style sheet outside itself; each holds the text of the static
    files it uses, as the templates' folder has them."""
    from dsm.benchmark import contenders
    folder = Path(__file__).resolve().parents[1] / "dsm" / "report" / "templates"
    read = lambda name: (folder / name).read_text(encoding="utf-8")
    pages = {board / "leaderboard.html": ("report.css", "sort.js", "filters.js"),
             board / contenders.page_path("bevy"): ("report.css", "order.js")}
    for path, static in pages.items():
        text = path.read_text(encoding="utf-8")
        assert _parse(path).external == [], path
        for name in static:
            assert read(name).strip() in text, (path.name, name)
    assert "function sortBy" in read("sort.js") and "function orderBy" in read("order.js")


def test_a_variable_the_page_does_not_give_is_an_error():
    """StrictUndefined: a template that names a variable the caller left out raises, naming it, rather
    than printing nothing."""
    from dsm.report import templates
    with pytest.raises(jinja2.UndefinedError, match="counts"):
        templates.render("report.html", title="t")
    with pytest.raises(jinja2.UndefinedError, match="summary"):
        templates.render("summary.html")


def test_a_value_is_escaped_in_a_partial_template_too():
    """summary.html rendered alone (report.html's summary section) escapes its words as the pages do."""
    from dsm.report import templates
    got = templates.render("summary.html", summary={"note": "a </p> & co", "table": templates.Table([], [])})
    assert "<p class=note>a &lt;/p&gt; &amp; co</p>" in got


def test_the_first_screen_takes_a_block_before_the_answers():
    """A template that extends leaderboard.html and fills first_screen puts its words first, before the
    page's own answers (super()): where a new answer goes. report.html has the block too."""
    from dsm.benchmark import page
    from dsm.report import templates
    env = templates.environment()
    child = env.from_string('{% extends "leaderboard.html" %}{% block first_screen %}'
                            '<p class=answer>new</p>{{ super() }}{% endblock %}')
    cases = [_record("a", c, r) for c, r in (("bevy", 0.1), ("three", 0.3))]
    cases.append({"scene": "a", "unit": "m", "offset": "0", "light": "spot", "contender": "oracle",
                  "n_receivers": 1000, "world_objective": 0.05, "texel_objective": 0.05, "per_texel_objective": 0.0})
    doc = {"suite": "dsm-bench-5", "suite_sha256": "0" * 64, "size": "test", "dsm_version": "0", "variant": "x",
           "versions": {"dsm_git_commit": "c"}, "machine": {"cpu": "cpu", "cores": 1}, "cases": cases}
    got = Page()
    got.feed(child.render(**page.context(doc)))
    assert got.answers[:2] == ["new", "Ranking (mean error rate over every scene, unit and light, at the origin): "
                                      "1. bevy (0.1000), 2. three (0.3000)."]
    assert "first_screen" in env.get_template("report.html").blocks
