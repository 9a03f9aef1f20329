"""A spot or point light's virtual map (dsm.maps.virtual_punctual) writes each case's level image, as the
directional map does: every receiver pixel coloured by its level, so the image's colour counts are the
case's level histogram in metrics.csv (counted by dsm.truth.virtual, not from the image)."""

import csv

import numpy as np
import pytest
from PIL import Image

from conftest import base_config


@pytest.mark.parametrize("light", [{"type": "spot", "position": [1.5, -1.0, 3.0], "target": [0.0, 0.0, 0.0],
                                    "cutoff": 40.0},
                                   {"type": "point", "position": [0.6, -0.4, 2.0]}])
def test_punctual_level_image_counts_are_the_level_histogram(tmp_path, light):
    import dsm
    from dsm.report.sections.virtual import LEVEL_COLORS
    cfg = base_config(camera={"resolution": [160, 160]}, scene=[{"builtin": "l_shape"}], light=[light],
                      map={**({"view": "cube"} if light["type"] == "point" else {}),
                           "virtual": {"preset": "eevee_punctual"}},
                      scheme=[{"name": "constant", "bias": "1 texel"}])
    dsm.run(cfg, out=tmp_path / "run", report=False)
    (row,) = csv.DictReader(open(tmp_path / "run" / "metrics.csv"))
    want = {int(k): int(v) for k, v in (p.split(":") for p in row["vsm_level_histogram"].split())}
    assert len(want) >= 2 and sum(want.values()) == int(row["n_receivers"])
    (path,) = (tmp_path / "run" / "images").glob("*/*_level.png")
    img = np.asarray(Image.open(path).convert("RGB")).reshape(-1, 3)
    got = {lvl: int(np.all(img == LEVEL_COLORS[lvl % len(LEVEL_COLORS)], axis=1).sum()) for lvl in want}
    assert got == want
    assert int(np.any(img != 0, axis=1).sum()) == int(row["n_receivers"])
