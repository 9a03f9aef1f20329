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


def test_write_leaves_only_the_file(tmp_path):
    px = RNG.integers(0, 256, (13, 8, 3)).astype(np.uint8)
    png.write(tmp_path / "p.png", px)
    with Image.open(tmp_path / "p.png") as im:
        assert np.array_equal(np.asarray(im), px)
    assert [p.name for p in tmp_path.iterdir()] == ["p.png"]        # no temporary file left


@pytest.mark.parametrize("px", [np.zeros((2, 2), np.float32), np.zeros((2, 2, 2), np.uint8),
                                np.zeros((0, 3), np.uint8), np.zeros((3, 0, 3), np.uint8)])
def test_what_it_cannot_store_is_refused(px):
    with pytest.raises(ValueError, match="expected"):
        png.encode(px)


def test_a_figure_is_written_at_its_dpi_and_keeps_its_own(tmp_path):
    """figures._save draws at figures.DPI and writes the canvas's pixels; the figure returned to a
    caller keeps its dpi, as savefig leaves it."""
    from dsm.report import figures
    fig = figures.draw_lines(tmp_path / "f.png", "t", [("c", "x", {"a": [(1, 0.1, 0.2), (2, 0.2, 0.1)]}, {})])
    dpi = fig.dpi
    with Image.open(tmp_path / "f.png") as im:
        w, h = fig.get_size_inches()
        assert im.mode == "RGB" and im.size == (int(w * figures.DPI), int(h * figures.DPI))   # Agg's canvas: whole pixels, cut
        assert np.asarray(im)[0, 0].tolist() == [255, 255, 255]       # a white background (the figure is opaque)
    assert dpi != figures.DPI and fig.dpi == dpi


@pytest.mark.parametrize("shape,colours", [((9, 7), 8), ((1, 1), 1), ((5, 13), 256)])
def test_pillow_decodes_an_indexed_image_s_indices_and_palette(shape, colours):
    """Colour type 3: Pillow reads back every index and the palette's colours, and the RGB it shows."""
    idx = RNG.integers(0, colours, shape).astype(np.uint8)
    pal = RNG.integers(0, 256, (colours, 3)).astype(np.uint8)
    with Image.open(io.BytesIO(png.encode_indexed(idx, pal))) as im:
        assert im.mode == "P" and im.size == (shape[1], shape[0])
        assert np.array_equal(np.asarray(im), idx)
        assert np.array_equal(np.asarray(im.getpalette()[:3 * colours], np.uint8).reshape(-1, 3), pal)
        assert np.array_equal(np.asarray(im.convert("RGB")), pal[idx])


@pytest.mark.parametrize("idx,pal", [(np.full((2, 2), 3, np.uint8), np.zeros((3, 3), np.uint8)),
                                     (np.zeros((2, 2), np.int32), np.zeros((3, 3), np.uint8)),
                                     (np.zeros((2, 2), np.uint8), np.zeros((257, 3), np.uint8)),
                                     (np.zeros((0, 2), np.uint8), np.zeros((3, 3), np.uint8))])
def test_an_indexed_image_a_reader_would_refuse_is_refused(idx, pal):
    with pytest.raises(ValueError):
        png.encode_indexed(idx, pal)
