"""Sphinx extension of dsm's documentation: writes the generated pages before Sphinx looks for
sources, and shows docs/design.md (kept whole on disk, where other pages link to it) as the index of
its topics, which are generated from it one page per ``## `` heading."""
from pathlib import Path

from generate import design_pages, write_all

DOCS = Path(__file__).resolve().parents[1]


def generate(app, config):
    """config-inited: every generated page written under docs/_generated/."""
    write_all(DOCS)


def design_index(app, docname, source):
    """source-read: design.md becomes its title and the toctree of its generated topic pages."""
    if docname != "design":
        return
    text = (DOCS / "design.md").read_text()
    title = text.split("\n", 1)[0].lstrip("# ").strip() or "Design"
    slugs = [slug for slug, _ in design_pages(text)]
    source[0] = (f"# {title}\n\nThe design, one page per topic (generated from `docs/design.md` at build "
                 "time).\n\n```{toctree}\n:maxdepth: 1\n\n"
                 + "\n".join(f"_generated/design/{s}" for s in slugs) + "\n```\n")


def setup(app):
    """Register the two hooks."""
    app.connect("config-inited", generate)
    app.connect("source-read", design_index)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
