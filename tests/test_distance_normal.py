"""Distance-scaled normal bias (UE5 virtual shadow maps' r.Shadow.Virtual.NormalBias, approximated)."""

import math

import numpy as np
import pytest

import dsm.pipeline as pl
from dsm.maps import lookup
from dsm import schemes
from dsm.maps.receiver import Receiver
from dsm.core.types import LightSpec

CAM_O, CAM_T = np.array([5.0, -7.0, 6.0]), np.array([0.0, 0.0, 0.3])     # plane_box's camera, fov 40


@pytest.fixture(scope="module")
def box():
    sd = pl.load_scene(pl.scene_spec({"builtin": "plane_box"}), (96, 96))
    gb = pl.gbuffer(sd)
    setup = pl.light_setup(sd, gb, LightSpec("directional", direction=(-0.4, -0.3, -1.0)), "sun")
    view = pl.make_view(setup.light, 256, pl.points_np(setup.p), sd.bbox)
    smap = pl.store(pl.build_map(sd.scene, view, ()), "float32")
    return sd, setup, smap, pl.receivers(view, setup, sd.diagonal)


def expected_offset(p, normal_bias, min_offset):
    """max(min_offset, normal_bias / 1000 * view depth * tan(20 deg)), the camera from the built-in's pose."""
    f = (CAM_T - CAM_O) / np.linalg.norm(CAM_T - CAM_O)
    return np.maximum(min_offset, normal_bias / 1000 * ((p - CAM_O) @ f) * math.tan(math.radians(20.0)))


@pytest.mark.parametrize("normal_bias, min_offset", [(0.5, 0.0), (40.0, 0.0), (40.0, 0.12)])
def test_offset_grows_with_the_view_depth(box, normal_bias, min_offset):
    sd, setup, smap, rx = box
    spec = pl.scheme_spec({"name": "distance_normal", "normal_bias": normal_bias, "min_offset": min_offset})
    mod = schemes.get("distance_normal")
    moved = mod.shift(rx, lookup.resolve(spec.params, rx))
    p, n = pl.points_np(rx.p_world), pl.points_np(rx.n_world)
    want = n * expected_offset(p, normal_bias, min_offset)[:, None]
    got = pl.points_np(moved.p_world) - p
    assert np.abs(got - want).max() < 2e-6 + 1e-4 * np.abs(want).max()
    if min_offset:                                   # the floor binds near the camera, the scaling far away
        off = expected_offset(p, normal_bias, min_offset)
        assert (off == min_offset).any() and (off > min_offset).any()


def test_a_floor_alone_is_normal_offset(box):
    sd, setup, smap, rx = box
    a = pl.visibility(pl.scheme_spec({"name": "distance_normal", "normal_bias": 0.0, "min_offset": 0.05}), rx, smap)
    b = pl.visibility(pl.scheme_spec({"name": "normal_offset", "offset": 0.05}), rx, smap)
    assert np.array_equal(a[0].numpy(), b[0].numpy())


def test_more_normal_bias_less_acne(box):
    sd, setup, smap, rx = box
    acne = []
    for nb in (0.0, 5.0, 50.0):
        v = pl.visibility(pl.scheme_spec({"name": "distance_normal", "normal_bias": nb}), rx, smap)[0].numpy()
        acne.append(int((setup.v_star & (v < 0.5)).sum()))
    assert acne[0] > 100 and acne[0] > acne[1] > acne[2]


def test_without_a_camera_it_says_so(box):
    sd, setup, smap, rx = box
    bare = Receiver.make(rx.view, rx.p_world, rx.n_world, sd.diagonal)
    with pytest.raises(ValueError, match="camera"):
        pl.visibility(pl.scheme_spec({"name": "distance_normal"}), bare, smap)


def test_lookup_is_the_numpy_margin_at_the_moved_point(box):
    """V against numpy float64: p' = p + n offset, its texel in the orthographic map (origin, axes,
    extent), lit where z1 + bias - depth(p') >= 0; receivers at a tie or a texel border left out."""
    sd, setup, smap, rx = box
    nb, bias = 4.0, 0.002
    v = pl.visibility(pl.scheme_spec({"name": "distance_normal", "normal_bias": nb, "bias": bias}), rx, smap)[0].numpy()
    p, n = pl.points_np(rx.p_world), pl.points_np(rx.n_world)
    view = smap.view
    q = p + n * expected_offset(p, nb, 0.0)[:, None] - view.origin_np
    ex, ey, ez = view.axes_np
    R = view.resolution
    u, w = (q @ ex) * R / view.extent, (q @ ey) * R / view.extent
    inside = (u >= 0) & (u < R) & (w >= 0) & (w < R)
    idx = np.clip(np.floor(w), 0, R - 1).astype(int) * R + np.clip(np.floor(u), 0, R - 1).astype(int)
    z1 = np.where(inside, np.asarray(smap.z1.numpy(), np.float64)[idx], view.far)
    margin = z1 + bias - q @ ez
    border = lambda a: np.abs(a - np.round(a)) < 1e-3
    clear = (np.abs(margin) > 1e-4) & ~border(u) & ~border(w)
    assert clear.mean() > 0.95 and (margin[clear] < 0).any() and (margin[clear] >= 0).any()
    assert np.array_equal(v[clear] >= 0.5, margin[clear] >= 0)
