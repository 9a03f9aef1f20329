"""Sphinx extension of dsm's documentation: writes the generated pages before Sphinx looks for
sources, and shows docs/design.md (kept whole on disk, where other pages link to it) as the index of
its topics, which are generated from it one page per ``## `` heading."""
import re
from pathlib import Path

from generate import design_pages, write_all

DOCS = Path(__file__).resolve().parents[1]


def generate(app, config):
    """config-inited: every generated page written under docs/_generated/."""
    write_all(DOCS)


def design_index(app, docname, source):
    """source-read: design.md becomes the index of its generated topic pages, keeping every heading
    (## to ####) it has, each with a link to the topic page holding it, so a link to
    design.md#some-heading still lands on that heading."""
    if docname != "design":
        return
    text = (DOCS / "design.md").read_text()
    title = text.split("\n", 1)[0].lstrip("# ").strip() or "Design"
    pages = design_pages(text)
    lines = [f"# {title}", "", "The design, one page per topic (generated from `docs/design.md` at build time).",
             "", "```{toctree}", ":maxdepth: 1", ""] + [f"_generated/design/{slug}" for slug, _ in pages] + ["```", ""]
    for slug, page in pages[1:]:
        prose = re.sub(r"(?ms)^```.*?^```", "", page)       # a '#' line inside a code block is no heading
        for heading in re.findall(r"(?m)^#{1,3} .+$", prose):
            level = heading.index(" ") + 1          # the topic page's headings are one level up
            lines += ["#" * level + heading[level - 1:], "", f"In [{page.split(chr(10), 1)[0][2:]}]"
                      f"(_generated/design/{slug}.md).", ""]
    source[0] = "\n".join(lines)


TOPICS = "TOPICS"          # the index's placeholder line for the topics' toctree entries


def topics(index_text: str) -> list:
    """The topic pages: every docs/*.md but the index and those the index's other lists name."""
    named = set(re.findall(r"(?m)^([\w/.-]+)$", index_text.split("```{toctree}", 1)[-1]))
    return sorted(p.stem for p in DOCS.glob("*.md") if p.stem != "index" and p.stem not in named)


def index_topics(app, docname, source):
    """source-read: the index's TOPICS line becomes the topic pages, one a line."""
    if docname == "index":
        source[0] = source[0].replace(f"\n{TOPICS}\n", "\n" + "\n".join(topics(source[0])) + "\n", 1)


SNOWBALL_STEM = []        # Sphinx's own English stem, kept here once memoize_stems has replaced it


def memoize_stems():
    """The search index's English stemmer asked once per distinct word: Sphinx stems every word of every
    page (about 40,000 words, a few thousand distinct, each through the pure-Python Snowball stemmer); a
    word's stem is a function of the word alone, so the index is the same."""
    from sphinx.search.en import SearchEnglish
    if SNOWBALL_STEM:
        return
    SNOWBALL_STEM.append(SearchEnglish.stem)
    stems = {}

    def stem(self, word: str) -> str:
        if word not in stems:
            stems[word] = SNOWBALL_STEM[0](self, word)
        return stems[word]

    SearchEnglish.stem = stem


def setup(app):
    """Register the hooks."""
    memoize_stems()
    app.connect("config-inited", generate)
    app.connect("source-read", design_index)
    app.connect("source-read", index_topics)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
