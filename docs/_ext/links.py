"""The site's internal links, checked offline: every href and src of every built page that names no
scheme (http:, mailto:) must be a file of the site, and its #fragment an id on that page."""
import re
from pathlib import Path
from urllib.parse import unquote, urlsplit

REF = re.compile(r'\b(?:href|src)="([^"]+)"')
ID = re.compile(r'\bid="([^"]+)"')


def broken_links(html_root: Path) -> list:
    """[(page, href)] of internal links under ``html_root`` that lead nowhere (empty: all resolve)."""
    html_root = Path(html_root)
    pages = sorted(html_root.rglob("*.html"))
    texts = {p: p.read_text(errors="replace") for p in pages}
    ids = {p.resolve(): set(ID.findall(text)) for p, text in texts.items()}
    # every page repeats the sidebar's links: a path is looked up on disk once per folder it is read from
    targets = {}
    bad = []
    for page, text in texts.items():
        here = page.resolve()
        for href in REF.findall(text):
            if not _resolves(here, href, ids, targets):
                bad.append((str(page.relative_to(html_root)), href))
    return bad


def _resolves(page: Path, href: str, ids: dict, targets: dict) -> bool:
    """Whether one link of ``page`` leads to a file of the site (and an id on it, for a fragment);
    ``targets`` caches each (folder, path)'s file."""
    u = urlsplit(href)
    if u.scheme or href.startswith("//"):
        return True                     # outside the site: not checked offline
    key = (page.parent, u.path) if u.path else (page, "")
    if key not in targets:
        targets[key] = _target(page, u.path)
    target = targets[key]
    if target is None:
        return False
    return not u.fragment or target.suffix != ".html" or u.fragment in ids.get(target, set())


def _target(page: Path, path: str):
    """The file a link's path names from ``page`` (the page itself for an empty path), or None."""
    target = page if not path else (page.parent / unquote(path)).resolve()
    if target.is_dir():
        target = target / "index.html"
    return target if target.is_file() else None
