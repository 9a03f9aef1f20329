"""Sphinx configuration of dsm's documentation site (scripts/docs builds it into docs/_build/html)."""
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path[:0] = [str(DOCS / "_ext"), str(DOCS.parent)]      # the extension, and this checkout's dsm

project = "dsm"
author = "the dsm developers"
copyright = "the dsm developers"
extensions = ["myst_nb", "sphinx.ext.autodoc", "dsm_site"]
autodoc_member_order = "bysource"
autodoc_typehints = "description"     # the signature short; the types beside each parameter
html_theme = "furo"
html_title = "dsm"
exclude_patterns = ["_build", "_ext", "gallery/*.md", "papers/runs"]   # gallery/: fragments scripts/gallery.py writes; papers/runs: the papers page's data
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 4
smartquotes = False                  # --force stays two hyphens, "k texel" keeps its quotes
nb_execution_mode = "off"            # notebooks are shown with their stored outputs, never run again
suppress_warnings = ["myst.header"]   # pages written before the site may start at ## or skip a level
html_static_path = ["_static"]
html_css_files = ["dsm.css"]        # docs/_static/dsm.css: the scheme pages' class images shown sharp
