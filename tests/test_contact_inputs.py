"""Contact shadows (dsm/contact) on the inputs that once misled: under an area light its lit and umbra
regions, a range contact length beside a voxel grid refused."""

import pytest

from conftest import cli_run as _cli, one_line as _one_line, base_config, toml_text
from dsm.config import read as config, plan


def test_contact_columns_under_an_area_light_use_its_lit_and_umbra_regions():
    """Receivers by V* = 1, 1 (lit), 0, 0 (umbra), 0.5, 0.5 (penumbra, in neither count, as the core
    metrics): the march darkens receivers 0, 2, 4, 5. By hand: false shadow 1 (receiver 0; the
    penumbra's receiver 4 was counted too), recovered 1 (receiver 2), nothing missed; after it
    acne 1 of 2 lit, peter-panning 0 of 2 umbra, error 1 of 6, mean |V - V*| (1 + .5 + .5) / 6."""
    import numpy as np
    from dsm.contact import march as contact
    v_frac = np.array([1.0, 1.0, 0.0, 0.0, 0.5, 0.5])
    v = np.array([1.0, 1.0, 1.0, 0.0, 1.0, 0.0])
    occ = np.array([True, False, True, False, True, True])
    m = contact.case_metrics(v, v_frac >= 0.5, occ, v_frac)     # as the runner passes them
    assert (m["n_contact_false"], m["n_contact_recovered"], m["n_contact_missed"]) == (1, 1, 0)
    assert m["contact_acne_rate"] == 0.5 and m["contact_peterpan_rate"] == 0.0
    assert m["contact_error_rate"] == pytest.approx(1 / 6) and m["contact_mean_abs_error"] == pytest.approx(2 / 6)


@pytest.mark.slow
def test_an_area_light_runs_contact_error_rate_is_the_documented_sum(run_dict):
    """design.md: contact_error_rate = (n_acne + n_contact_false + n_peterpan - n_contact_recovered)
    / n_receivers. Under an area light recovered (46) exceeded n_peterpan (0) and the sum failed."""
    res = run_dict(base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [48, 48]},
                               light=[{"type": "area", "shape": "rectangle", "position": [0.6, -0.4, 3.0],
                                       "size": 0.5, "max_samples": 512}],
                               map={"resolution": 64}, contact={"length": "4 texel"},
                               scheme=[{"name": "constant", "bias": "1 texel"}]))
    (r,) = res.rows
    assert r["n_penumbra"] > 0 and r["n_contact_false"] > 0
    assert r["n_contact_recovered"] <= r["n_peterpan"] and r["n_contact_missed"] <= r["n_peterpan"]
    assert r["contact_error_rate"] == pytest.approx(
        (r["n_acne"] + r["n_contact_false"] + r["n_peterpan"] - r["n_contact_recovered"]) / r["n_receivers"])


def test_a_range_contact_length_beside_a_vsv_grid_is_a_config_error(tmp_path, capsys):
    """A VSV view's near and far are 0 and 1 (its depth is a fraction of the alpha range), so a
    contact length of "0.5 range" marched 0.5 world units there, not half a depth range."""
    point = {"type": "point", "position": [0.6, -0.8, 2.2]}
    cfg = base_config(scene=[{"builtin": "plane_box"}], light=[point], map={"resolution": 32, "view": ["cube", "vsv"]},
                      scheme=[{"name": "constant"}, {"name": "vsv"}], contact={"length": "0.5 range"})
    path = tmp_path / "c.toml"
    path.write_text(toml_text(cfg))
    rc, err = _cli(capsys, "plan", path)
    assert rc == 2
    _one_line(err, str(path), "contact.length", "vsv", "texel")
    cfg["map"]["view"] = ["cube"]
    cfg["scheme"] = [{"name": "constant"}]
    assert plan.make(config.parse(cfg, "<test>")).cases == 1          # a depth map's range is defined
