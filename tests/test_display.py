"""Display renders (dsm.experiment.display): each scene and light shaded at a whole multiple of the
camera's resolution (at least 320 px a side), written after the measurement, changing no count."""
import csv

import numpy as np
from PIL import Image

from conftest import base_config


def _counts(out):
    with open(out / "metrics.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    # identities, counts and rates (times, the JIT's compiled kernels and memory peaks depend on what the
    # process ran before)
    return [{k: v for k, v in r.items() if k in ("case", "scene", "light", "scheme", "params") or k.startswith("n_")
             or k.endswith("_rate")} for r in rows]


def test_display_renders_show_the_exact_shadow_at_their_own_resolution_and_change_no_count(tmp_path):
    import dsm
    from dsm.experiment import display
    from dsm.report.figures import display_paths
    from dsm.truth import metrics
    cfg = lambda images: base_config(experiment={"name": "display"}, camera={"resolution": [40, 32]},
                                     scene=[{"builtin": "plane_box"}], map={"resolution": [64]},
                                     scheme=[{"name": "constant", "bias": ["1 texel"]}], report={"images": images})
    res = dsm.run(cfg("all"), out=tmp_path / "all")
    bare = dsm.run(cfg("none"), out=tmp_path / "none")
    assert _counts(res.out) == _counts(bare.out)                    # the renders change no count
    row = res.rows[0]
    assert not any((bare.out / p).exists() for p in display_paths(row))
    nl, exact = (np.asarray(Image.open(res.out / p), float) / 255 for p in display_paths(row))
    k = display.display_scale(40, 32)
    assert k == 10 and nl.shape == exact.shape == (320, 400)       # 32 x 10 >= 320 rows, 40 x 10 columns
    assert (exact <= nl + 1e-9).all()                               # a shadow only takes light away
    # the exact shadow where the camera's class image says V* = 0 (its pixels repeated k x k): the
    # display render's pixels inside a camera pixel's block mostly agree with that pixel's V*
    classes = np.asarray(res.images[row["case"]])
    base = metrics.base_class(classes)
    v_star = np.isin(base, (metrics.LIT, metrics.ACNE))
    receiver = base != metrics.OUTSIDE
    up = lambda a: np.kron(a, np.ones((k, k), bool))
    lit = exact > 0.13                                            # ambient alone is 0.12
    inside = up(receiver) & (nl > 0.13)                           # receivers the light reaches (N.L > 0)
    agree = (lit == up(v_star))[inside].mean()
    assert 0.9 < agree <= 1.0 and (~up(v_star) & inside).any()    # a shadow is on the display render
