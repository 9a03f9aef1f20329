"""Every scheme meets the written contract, and its signed margin says what its source says."""
from types import SimpleNamespace

import numpy as np
import pytest

N = 4000


def _data(rng):
    z1 = rng.uniform(1.0, 5.0, N)
    return dict(z1=z1, z2=z1 + rng.uniform(0.0, 0.5, N), d=z1 + rng.normal(0.0, 0.05, N),
                plane=z1 + rng.normal(0.0, 0.05, N), slope=rng.uniform(0.0, 0.05, N),
                cos=rng.uniform(0.05, 1.0, N), scale=7.0)


# the tests as the sources and README state them, in float64: (params, lit)
EXPECTED = {
    "none": ({}, lambda x, p: x["d"] <= x["z1"]),
    "constant": ({"bias": 0.02}, lambda x, p: x["d"] <= x["z1"] + p["bias"]),
    "slope_scaled": ({"bias": 0.001, "slope": 3.0, "clamp": 0.05},
                     lambda x, p: x["d"] <= x["z1"] + np.minimum(p["clamp"], p["bias"] + p["slope"] * x["slope"])),
    "normal_angle": ({"bias": 0.01, "max": 0.08},
                     lambda x, p: x["d"] <= x["z1"] + np.minimum(p["max"], p["bias"] * np.sqrt(1 - x["cos"] ** 2)
                                                                / x["cos"])),
    "normal_offset": ({"offset": 0.0, "bias": 0.02}, lambda x, p: x["d"] <= x["z1"] + p["bias"]),
    # combined: normal offset (0 here: the shift is the normal_offset scheme's), then
    # z1 + depth_bias + min(slope_clamp, slope_scale * m); the clamp bounds the slope term only
    "combined": ({"normal_offset": 0.0, "depth_bias": 0.01, "slope_scale": 2.0, "slope_clamp": 0.04},
                 lambda x, p: x["d"] <= x["z1"] + p["depth_bias"] + np.minimum(p["slope_clamp"],
                                                                             p["slope_scale"] * x["slope"])),
    "receiver_plane": ({"bias": 0.01}, lambda x, p: x["plane"] <= x["z1"] + p["bias"]),
    "adaptive": ({"K": 0.003}, lambda x, p: x["plane"] <= x["z1"] + p["K"] * x["scale"]),
    # per tap; the tap here is the receiver's own texel, 1 texel of 1 world unit: the clamp (8) is far
    "adaptive_tap": ({"K": 0.003, "max_slope": 8.0}, lambda x, p: x["plane"] <= x["z1"] + p["K"] * x["scale"]),
    "midpoint": ({}, lambda x, p: x["d"] <= 0.5 * (x["z1"] + x["z2"])),
    "dual": ({"z_offset": 0.1}, lambda x, p: x["d"] <= x["z1"] + np.minimum(0.5 * (x["z2"] - x["z1"]), p["z_offset"])),
    "second_depth": ({"bias": 0.01}, lambda x, p: x["d"] <= x["z1"] + p["bias"]),
    # distance_normal: its offset moves the lookup point (tests/test_distance_normal.py); then z1 + bias
    "distance_normal": ({"normal_bias": 0.5, "min_offset": 0.0, "bias": 0.02}, lambda x, p: x["d"] <= x["z1"] + p["bias"]),
}


def test_every_registered_scheme_is_checked_here():
    from dsm.schemes import REGISTRY
    assert sorted(s.NAME for s in REGISTRY) == sorted(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_margin_sign_is_the_sources_test(variant, name):
    import drjit as dr
    import mitsuba as mi
    from dsm.schemes import base, get
    scheme = get(name)
    assert isinstance(scheme, base.Scheme)
    rng = np.random.default_rng(sum(map(ord, name)))
    x = _data(rng)
    f = lambda a: mi.Float(np.asarray(a, np.float32))
    n = mi.Vector3f(f(np.sqrt(1 - x["cos"] ** 2)), 0.0, f(x["cos"]))
    plane = f(x["plane"])
    rx = SimpleNamespace(depth=f(x["d"]), n_world=n, to_light=mi.Vector3f(0, 0, 1), scene_scale=mi.Float(x["scale"]),
                         p_world=dr.zeros(mi.Point3f, N), u_map=mi.Float(0.5), v_map=mi.Float(0.5),
                         texel_world=mi.Float(1.0))
    tap = SimpleNamespace(z1=f(x["z1"]), z2=f(x["z2"]), slope=f(x["slope"]), cu_map=mi.Float(0.5),
                          cv_map=mi.Float(0.5), receiver_plane_depth=lambda r: plane)
    params, expected = EXPECTED[name]
    prm = SimpleNamespace(**{k: mi.Float(v) for k, v in params.items()})
    margin = scheme.margin(rx, tap, prm).numpy()
    # x rounded to float32 as the kit sees it, then the source's test in float64
    x32 = {k: (np.asarray(v, np.float32).astype(np.float64) if isinstance(v, np.ndarray) else v) for k, v in x.items()}
    want = expected(x32, params)
    clear = np.abs(margin) > 1e-5                    # away from ties, where float32 rounding decides
    assert clear.mean() > 0.95 and want[clear].any() and (~want[clear]).any()
    np.testing.assert_array_equal(margin[clear] >= 0, want[clear])
    if name not in ("normal_offset", "combined", "distance_normal"):
        assert scheme.shift(rx, prm) is rx           # the default shift does nothing


# the contract fields every module declares, as the sources state them: the VSV lookups read the
# voxel grid alone, distance_normal the receivers' camera (UE5's distance-scaled normal bias)
VSV_LOOKUPS = {"vsv", "vsv_epsilon", "vsv_adaptive"}
CAMERA_READERS = {"distance_normal"}


def test_every_scheme_declares_views_camera_and_needs():
    from dsm.schemes import ALL
    assert VSV_LOOKUPS <= {m.NAME for m in ALL}
    for m in ALL:
        assert m.VIEWS == (("vsv",) if m.NAME in VSV_LOOKUPS else None), m.NAME
        assert m.READS_CAMERA is (m.NAME in CAMERA_READERS), m.NAME
        got = m.needs(m.Params())
        assert isinstance(got, frozenset) and got <= m.NEEDS, m.NAME


def test_combined_needs_the_slope_layer_only_with_its_slope_term():
    from dsm.schemes import combined
    assert combined.needs(combined.Params()) == frozenset()
    assert combined.needs(combined.Params(slope_scale=2.0)) == frozenset({"slope"})


def test_a_module_without_a_contract_field_is_not_a_scheme():
    from dsm.schemes import base, constant
    fields = {k: v for k, v in vars(constant).items() if not k.startswith("__")}
    assert isinstance(SimpleNamespace(**fields), base.Scheme)
    for name in ("READS_CAMERA", "VIEWS", "needs"):
        assert not isinstance(SimpleNamespace(**{k: v for k, v in fields.items() if k != name}), base.Scheme), name


def test_every_map_kind_declares_log_max_and_its_encoding():
    from dsm import prefilter
    from dsm.prefilter import base
    exponential = {"esm", "evsm"}          # an exp(c t) moment, which a format can overflow
    encoded = {"msm"}                      # Peters & Klein's optimized 16-bit quantization
    for m in prefilter.REGISTRY:
        top = m.log_max(m.Params())
        assert (type(top) is float) if m.NAME in exponential else top is None, m.NAME
        assert (m.encode is not None and m.decode is not None) is (m.NAME in encoded), m.NAME
        assert ("unorm16" in base.formats_of(m)) is (m.NAME in encoded), m.NAME
    fields = {k: v for k, v in vars(prefilter.vsm).items() if not k.startswith("__") and k != "log_max"}
    assert not isinstance(SimpleNamespace(**fields), base.MapKind)


def test_views_declare_what_their_readers_read():
    """The view fields read across the kit have a default on View and their kinds' own values."""
    from dsm.maps.cascades import CascadeView
    from dsm.maps.views import OrthographicView, View
    from dsm.maps.vsv import EpipolarView
    assert (View.depth_oracles, View.cascaded, View.blend, View.light_size, View.exclude) == (True, False, 0.0, 0.0, ())
    assert CascadeView.cascaded and not OrthographicView.cascaded
    assert not EpipolarView.depth_oracles
