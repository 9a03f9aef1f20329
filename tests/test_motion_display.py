"""Motion GIFs of display renders (dsm.experiment.motion_display): each frame the frame's camera pose
and light rendered at a whole multiple of the camera's resolution, its classes tinted over the N.L
render, drawn after the measurement (no count changes)."""
import math

import numpy as np
import pytest
from PIL import Image

from conftest import base_config


def _rotate(v, axis, deg):
    """Rodrigues' rotation in float64 (the test's own)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    t = math.radians(deg)
    return v * math.cos(t) + np.cross(a, v) * math.sin(t) + a * (a @ v) * (1 - math.cos(t))


def _block_classes(panel, k, colours):
    """Each k x k block's class: the class whose tint (shade x (0.15 + 0.85 colour), the page's
    multiply at 0.85) fits the block's pixels best, each pixel's shade its own least-squares scale."""
    tint = 0.15 + 0.85 * colours.astype(float) / 255                          # (classes, 3)
    h, w = panel.shape[0] // k, panel.shape[1] // k
    px = panel[:h * k, :w * k].astype(float).reshape(h, k, w, k, 3).transpose(0, 2, 1, 3, 4).reshape(h, w, k * k, 3)
    scale = np.einsum("hwpc,nc->hwpn", px, tint) / (tint * tint).sum(1)          # per pixel and class
    resid = ((px[..., None, :] - scale[..., None] * tint) ** 2).sum(-1).sum(2)   # (h, w, classes)
    return resid.argmin(-1)


def _frames_csv(out):
    import csv
    with open(out / "frames.csv", newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.slow
def test_motion_gif_frames_give_the_frames_class_counts_and_change_no_count(run_dict):
    """Camera dolly and sun turning over 3 frames; the camera 64 x 48, so k = 7 (48 x 7 >= 320)."""
    from dsm.experiment import motion_display as md
    from dsm.truth import metrics
    cfg = lambda images: base_config(camera={"resolution": [64, 48]}, scene=[{"builtin": "plane_box"}],
                                     map={"resolution": 96}, scheme=[{"name": "constant", "bias": ["1 texel"]}],
                                     report={"images": images},
                                     motion=[{"frames": 3, "camera": "dolly", "offset": [0.0, 0.6, 0.0], "light": "turn",
                                              "light_axis": [0.0, 0.0, 1.0], "light_angle": 25.0, "points": 400}])
    res, bare = run_dict(cfg("all"), "all", report=True), run_dict(cfg("none"), "none", report=True)
    untimed = lambda out: [{k: v for k, v in r.items() if not k.endswith("_ms")} for r in _frames_csv(out)]
    assert untimed(res.out) == untimed(bare.out)          # drawn apart (frames.csv's build times aside)
    gif = Image.open(next((res.out / "images").glob("*/0001_frames.gif")))
    k, w, h = 7, 64 * 7, 48 * 7
    assert gif.n_frames == 3 and gif.size == (3 * w + 2 * md.GAP_PX, md.HEADER_PX + h)
    from dsm.report.html import gif_kind
    assert gif_kind(next((res.out / "images").glob("*/0001_frames.gif"))) == "display"
    base = {metrics.OUTSIDE: 0, metrics.LIT: 1, metrics.SHADOW: 2, metrics.ACNE: 3, metrics.ACNE_RESOLUTION: 3,
            metrics.PETERPAN: 4, metrics.PETERPAN_RESOLUTION: 4, metrics.LEAK: 4}
    total = np.zeros(5, int)
    for t, row in enumerate(_frames_csv(res.out)):
        gif.seek(t)
        rgb = np.asarray(gif.convert("RGB"))
        found = _block_classes(rgb[md.HEADER_PX:, :w], k, metrics.CLASS_COLORS)
        n = np.bincount(np.vectorize(base.get)(found).ravel(), minlength=5)
        total += n
        assert int(row["n_receivers"]) == n[1:].sum() > 500
        # frames.csv's rates to its six digits
        assert float(row["acne_rate"]) == pytest.approx(n[3] / (n[1] + n[3]), rel=1e-5)
        assert float(row["peterpan_rate"]) == pytest.approx(n[4] / (n[2] + n[4]), rel=1e-5)
        assert float(row["error_rate"]) == pytest.approx((n[3] + n[4]) / n[1:].sum(), rel=1e-5)
        assert n[2] > 0 and n[3] + n[4] > 0                          # a shadow and errors on the frame
    r = res.rows[0]                                                  # the case's counts, summed over its frames
    assert (r["n_gt_lit"], r["n_gt_shadowed"], r["n_acne"], r["n_peterpan"]) == \
        (total[1] + total[3], total[2] + total[4], total[3], total[4])
    # the exact and the mapped panel agree wherever the camera measured no receiver (exact shown there)
    exact, mapped = rgb[md.HEADER_PX:, w + md.GAP_PX:2 * w + md.GAP_PX], rgb[md.HEADER_PX:, 2 * (w + md.GAP_PX):]
    outside = np.kron(found == metrics.OUTSIDE, np.ones((k, k), bool))
    assert (exact[outside] == mapped[outside]).all() and (exact[~outside] != mapped[~outside]).any()


def test_display_render_n_dot_l_of_a_plane_is_the_float64_cosine():
    """A frame's display render of the plane under a turned sun: N.L at each receiver pixel is
    0.12 + 0.88 cos, cos from the mesh's vertices and the turned direction in float64 numpy."""
    from dsm import pipeline
    from dsm.core.types import LightSpec
    from dsm.experiment import motion_display as md
    from dsm.scenes.camera import Camera
    data = pipeline.load_scene(pipeline.scene_spec({"builtin": "plane"}), (40, 32))
    v = np.array(data.scene.shapes()[0].vertex_positions_buffer(), np.float64).reshape(-1, 3)
    normal = np.cross(v[1] - v[0], v[2] - v[0])
    normal /= np.linalg.norm(normal)
    base = Camera.from_sensor(data.sensor)
    k = md.display_scale(40, 32)
    d0 = np.array([0.3, -0.5, -1.0])
    for turn, shift in ((0.0, 0.0), (35.0, 0.4)):
        d = _rotate(d0, [0.0, 0.0, 1.0], turn)
        light = LightSpec("directional", direction=tuple(d))
        pose = (base.origin + [shift, 0, 0], base.origin + base.forward + [shift, 0, 0], base.up)
        fd = md.frame_display(data, base, k, pose, light, "0:directional", 7)
        assert fd.nl.shape == (32 * k, 40 * k) and fd.receiver.sum() > 20000
        cos = abs(normal @ (-d / np.linalg.norm(d)))                  # the camera sees the lit side
        assert np.abs(fd.nl[fd.receiver] - (0.12 + 0.88 * cos)).max() < 2e-6
        assert 0.2 < cos < 0.99
        mid = tuple(np.argwhere(fd.receiver)[len(np.argwhere(fd.receiver)) // 2])
        assert fd.exact[mid] == pytest.approx(0.12 + 0.88 * cos, abs=2e-6)    # nothing shadows a lone plane


def test_a_motion_gif_of_class_images_is_captioned_as_one(run_dict):
    """[report] images = "errors": the GIF is the frames' class images (the camera's size, class colours only)
    and report.html's viewer captions it so (it called them display renders); the display GIF of
    test_motion_gif_frames_give_the_frames_class_counts_and_change_no_count reads as "display"."""
    from dsm.report.html import gif_kind
    from dsm.truth import metrics
    cfg = base_config(camera={"resolution": [32, 24]}, scene=[{"builtin": "plane_box"}], map={"resolution": 64},
                      scheme=[{"name": "constant", "bias": ["1 texel"]}], report={"images": "errors"},
                      motion=[{"frames": 2, "light": "move", "light_offset": [0.0, 1.0, 0.0], "points": 200}])
    res = run_dict(cfg, "errors", report=True)
    path = next((res.out / "images").glob("*/0001_frames.gif"))
    gif = Image.open(path)
    assert gif.size == (32, 24)            # one pixel per camera pixel (identical frames may merge)
    colours = {tuple(c) for c in np.asarray(gif.convert("RGB")).reshape(-1, 3)}
    assert colours <= {tuple(int(x) for x in c) for c in metrics.CLASS_COLORS}
    assert gif_kind(path) == "classes"
    page = (res.out / "report.html").read_text()
    assert page.count('data-gifkind="classes"') == 1 and 'data-gifkind="display"' not in page
