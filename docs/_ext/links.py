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
    ids = {p.resolve(): set(ID.findall(p.read_text(errors="replace"))) for p in pages}
    bad = []
    for page in pages:
        for href in REF.findall(page.read_text(errors="replace")):
            if not _resolves(page.resolve(), href, ids):
                bad.append((str(page.relative_to(html_root)), href))
    return bad


def _resolves(page: Path, href: str, ids: dict) -> bool:
    """Whether one link of ``page`` leads to a file of the site (and an id on it, for a fragment)."""
    u = urlsplit(href)
    if u.scheme or href.startswith("//"):
        return True                     # outside the site: not checked offline
    target = page if not u.path else (page.parent / unquote(u.path)).resolve()
    if target.is_dir():
        target = target / "index.html"
    if not target.is_file():
        return False
    return not u.fragment or target.suffix != ".html" or u.fragment in ids.get(target, set())
