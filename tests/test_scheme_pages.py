"""One page per scheme (issue 75): every registered scheme has a committed error image and rates, and
they are fresh: docs/_ext/scheme_pages.py's CONFIG run again gives the same class images, pixel for
pixel, and the same rates (a change that moves a scheme's errors must remake them:
``python docs/_ext/scheme_pages.py``)."""
import json
import math
import sys

import numpy as np
from PIL import Image

from conftest import ROOT

sys.path.insert(0, str(ROOT / "docs" / "_ext"))
import scheme_pages            # noqa: E402  (docs/_ext is the site's tooling, not a package)


def test_every_scheme_has_an_image_and_rates_and_a_page_that_shows_them():
    from dsm import schemes
    rates = json.loads(scheme_pages.RATES.read_text())
    assert sorted(rates) == sorted(s.NAME for s in schemes.ALL)
    for s in schemes.ALL:
        assert (scheme_pages.IMAGES / f"{s.NAME}.png").is_file(), s.NAME
        page = scheme_pages.scheme_page(s, rates)
        assert page.startswith(f"# {s.NAME}\n") and f"../../scheme_images/{s.NAME}.png" in page
        # the formula and the parameters: the module's docstring whole, each Params field by name
        assert " ".join(s.__doc__.split("\n", 1)[1].split()) in " ".join(page.split())
        for f in s.Params.__dataclass_fields__:
            assert f"| `{f}` |" in page, (s.NAME, f)


def test_the_committed_images_and_rates_are_fresh(tmp_path):
    fresh = scheme_pages.make_images(tmp_path / "images", out=tmp_path / "run")
    committed = json.loads(scheme_pages.RATES.read_text())
    assert sorted(fresh) == sorted(committed)
    for name, r in fresh.items():
        c = committed[name]
        assert (r["view"], r["params"]) == (c["view"], c["params"]), name
        for col in scheme_pages.RATE_COLUMNS:
            assert r[col] == c[col] or (math.isnan(r[col]) and math.isnan(c[col])), (name, col, r[col], c[col])
        new = np.asarray(Image.open(tmp_path / "images" / f"{name}.png"))
        old = np.asarray(Image.open(scheme_pages.IMAGES / f"{name}.png"))
        assert new.shape == old.shape and (new == old).all(), name
