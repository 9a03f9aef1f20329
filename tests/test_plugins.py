"""The Mitsuba integrator plugins dsm_error and dsm_shadow: the runner's code, through mi.render."""
import numpy as np
import pytest

from conftest import ROOT

POINT_XML = ROOT / "tests" / "data" / "point_scene.xml"
SPOT_XML = ROOT / "tests" / "data" / "spot_scene.xml"


def _classes(img):
    from dsm.plugins.integrators import CLASS_LINEAR
    a = np.asarray(img)[..., :3]
    d = ((a[..., None, :] - CLASS_LINEAR[None, None]) ** 2).sum(-1)
    assert d.min(-1).max() < 1e-10                        # every pixel is exactly one class colour
    return np.argmin(d, -1).astype(np.uint8)


@pytest.mark.parametrize("xml,scheme,view", [(POINT_XML, {"scheme": "constant", "bias": "1 texel"}, "cube"),
                                             (POINT_XML, {"scheme": "none"}, "dual_paraboloid"),
                                             (SPOT_XML, {"scheme": "slope_scaled"}, "cube"),
                                             (SPOT_XML, {"scheme": "normal_offset", "offset": "1.5 texel"}, "cube")])
def test_dsm_error_matches_the_runner_pixel_for_pixel(run_dict, xml, scheme, view):
    import mitsuba as mi
    scene = mi.load_file(str(xml))
    props = {"type": "dsm_error", "resolution": 256, "view": view, **scheme}
    img = mi.render(scene, integrator=mi.load_dict(props))
    got = _classes(img)
    W = int(scene.sensors()[0].film().size()[0])
    table = {k: v for k, v in scheme.items() if k != "scheme"}
    res = run_dict({"scene": [{"file": str(xml)}], "camera": {"resolution": [W, W]},
                    "map": {"resolution": 256, "view": view},
                    "scheme": [{"name": scheme["scheme"], **table}], "timing": {"repeats": 1}})
    assert len(res) == 1
    want = res.images[res.rows[0]["case"]]
    assert got.shape == want.shape
    np.testing.assert_array_equal(got, want)
    r = res.rows[0]
    assert (got == 3).sum() == r["n_acne"] and (got == 4).sum() == r["n_peterpan"]


def _box_filtered(tmp_path):
    """The point-light scene with a box pixel filter: each pixel holds only its own samples."""
    import mitsuba as mi
    path = tmp_path / "box.xml"
    path.write_text(POINT_XML.read_text().replace('<film type="hdrfilm">',
                                                  '<film type="hdrfilm">\n            <rfilter type="box"/>'))
    return mi.load_file(str(path))


def test_dsm_shadow_with_no_bias_matches_mitsubas_direct_where_the_map_agrees(tmp_path):
    """Same seed, same camera rays: where the map's visibility equals the exact one, dsm_shadow's
    radiance is Mitsuba's direct integrator's (one delta light: no Monte Carlo noise in either),
    while without bias the map disagrees with V* on about half the lit receivers (acne)."""
    import mitsuba as mi
    scene = _box_filtered(tmp_path)
    ours = np.asarray(mi.render(scene, integrator=mi.load_dict(
        {"type": "dsm_shadow", "scheme": "none", "resolution": 2048, "view": "cube", "aovs": True}), spp=1, seed=3))
    direct = np.asarray(mi.render(scene, integrator=mi.load_dict({"type": "direct"}), spp=1, seed=3))
    v, vstar = ours[..., 3], ours[..., 4]
    agree = np.abs(v - vstar) < 1e-6
    lit = vstar > 0.999
    assert (agree & lit).sum() > 2000 and (~agree & lit).sum() > 2000   # acne without bias, agreement elsewhere
    diff = np.abs(ours[..., :3] - direct[..., :3]).max(-1)
    scale = np.abs(direct[..., :3]).max()
    ok = diff[agree] <= 1e-3 * scale
    assert ok.mean() > 0.995, ok.mean()           # a few pixels: Mitsuba's own spawn offset differs


def test_dsm_shadow_with_adaptive_bias_matches_direct_almost_everywhere(variant):
    import mitsuba as mi
    scene = mi.load_file(str(POINT_XML))
    ours = np.asarray(mi.render(scene, integrator=mi.load_dict(
        {"type": "dsm_shadow", "scheme": "adaptive", "resolution": 1024}), spp=4, seed=1))
    direct = np.asarray(mi.render(scene, integrator=mi.load_dict({"type": "direct"}), spp=4, seed=1))
    diff = np.abs(ours - direct).max(-1)
    assert (diff <= 1e-3 * np.abs(direct).max()).mean() > 0.98


def test_xml_scene_with_a_dsm_integrator_renders_through_load_file(tmp_path):
    import mitsuba as mi
    text = POINT_XML.read_text().replace(
        '<scene version="3.0.0">',
        '<scene version="3.0.0">\n    <integrator type="dsm_error">\n        <string name="scheme" value="constant"/>\n'
        '        <string name="bias" value="2 texel"/>\n        <integer name="resolution" value="256"/>\n'
        '        <string name="view" value="dual_paraboloid"/>\n    </integrator>')
    path = tmp_path / "with_integrator.xml"
    path.write_text(text)
    scene = mi.load_file(str(path))
    assert "DsmError" in str(scene.integrator())
    got = _classes(mi.render(scene))
    assert (got == 1).sum() > 1000 and (got == 2).sum() > 20   # lit and shadowed receivers are there


def test_bad_plugin_properties_name_the_property_and_the_choices(variant):
    import mitsuba as mi
    from dsm import ConfigError
    with pytest.raises(Exception, match="view.*cube"):
        mi.load_dict({"type": "dsm_error", "view": "sphere"})
    with pytest.raises(Exception, match="name.*adaptive"):
        mi.load_dict({"type": "dsm_shadow", "scheme": "magic"})
    with pytest.raises(Exception, match="bias"):
        mi.load_dict({"type": "dsm_shadow", "scheme": "constant", "bias": "2 parsecs"})
    assert issubclass(ConfigError, Exception)
