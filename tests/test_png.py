"""dsm/report/png.py against Pillow's decoder (a second implementation of the format)."""
import io

import numpy as np
import pytest
from PIL import Image

from dsm.report import png

RNG = np.random.default_rng(3)


@pytest.mark.parametrize("shape,mode", [((7, 5), "L"), ((6, 9, 3), "RGB"), ((4, 11, 4), "RGBA"), ((1, 1), "L")])
def test_pillow_decodes_every_pixel(shape, mode):
    px = RNG.integers(0, 256, shape).astype(np.uint8)
    with Image.open(io.BytesIO(png.encode(px, dpi=72))) as im:
        assert im.mode == mode and im.size == (shape[1], shape[0])
        assert np.array_equal(np.asarray(im), px)
        assert im.info["dpi"] == pytest.approx((72, 72), abs=0.01)


def test_an_indexed_image_decodes_to_its_palette_colours(tmp_path):
    colours = RNG.integers(0, 256, (6, 3)).astype(np.uint8)
    idx = RNG.integers(0, 6, (13, 8)).astype(np.uint8)
    png.write(tmp_path / "p.png", idx, colours)
    with Image.open(tmp_path / "p.png") as im:
        assert im.mode == "P" and np.array_equal(np.asarray(im), idx)
        assert np.array_equal(np.asarray(im.convert("RGB")), colours[idx])
    assert [p.name for p in tmp_path.iterdir()] == ["p.png"]        # no temporary file left


@pytest.mark.parametrize("px,palette", [(np.zeros((2, 2), np.float32), None), (np.zeros((2, 2, 2), np.uint8), None),
                                        (np.full((2, 2), 3, np.uint8), np.zeros((3, 3), np.uint8)),
                                        (np.zeros((2, 2, 3), np.uint8), np.zeros((3, 3), np.uint8))])
def test_what_it_cannot_store_is_refused(px, palette):
    with pytest.raises(ValueError, match="expected"):
        png.encode(px, palette)
