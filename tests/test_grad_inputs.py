"""dsm grad's inputs and undefined answers (dsm/grad): what it would ignore or measure in another scene is
refused; a relative error against a zero truth is undefined, not a number."""

import pytest

from conftest import cli_lines, one_line


GRAD = '[gradient]\nscene = "plate"\nlight = "{light}"\nmap_resolution = 32\nimage_resolution = 32\nparams = ["{param}"]\n{extra}'


@pytest.mark.parametrize("light, param, extra, key, words", [
    ("point", "occluder_z", "light_angle = 30\n", "gradient.light_angle", ['only with light = "directional"', "'point'"]),
    ("point", "occluder_z", "reference_step = {occluder_z = 10}\n", "gradient.reference_step.occluder_z",
     ["10 moves the occluder under the ground", "valid: 0 < step < 0.5"]),
    ("point", "occluder_z", "fd_step = {occluder_z = 1.6}\n", "gradient.fd_step.occluder_z",
     ["the occluder under the ground", "valid: 0 < step < 0.5"]),
    ("point", "light_height", "reference_step = {light_height = 1.5}\n", "gradient.reference_step.light_height",
     ["the light under the occluder's top", "valid: 0 < step < 1.5"]),
    ("point", "occluder_z", "inverse_starts = [1e30]\n", "gradient.inverse_starts",
     ["1e+30 moves occluder_z out of the scene", "|offset| < 0.5"]),
    ("directional", "light_angle", "inverse_starts = [-0.5, 75]\n", "gradient.inverse_starts",
     ["75 moves light_angle out of the scene", "|offset| < 70 degree"]),
    ("point", "occluder_x", "reference_step = {occluder_x = 10}\n", "gradient.reference_step.occluder_x",
     ["10 moves the occluder out of the image", "valid: 0 < step < 1"]),
])
def test_grad_refuses_what_it_would_ignore_or_measure_in_another_scene(light, param, extra, key, words, tmp_path,
                                                                       capsys):
    cfg = tmp_path / "g.toml"
    cfg.write_text(GRAD.format(light=light, param=param, extra=extra))
    rc, err = cli_lines(capsys, "grad", cfg, "--compare", "--out", tmp_path / "o")
    assert rc == 2
    one_line(err, str(cfg), key, *words)
    assert not (tmp_path / "o").exists()


def test_a_relative_error_is_undefined_where_the_truth_is_zero_within_its_error():
    from dsm.grad.check import relative_within
    assert relative_within(0.0507, 0.00095, 0.0025) is None       # was 5237.5 %
    assert relative_within(0.0, 0.0, 0.0) is None
    assert relative_within(1.1, 1.0, 0.01) == pytest.approx(0.1)


def test_projective_rows_that_measured_nothing_do_not_agree(tmp_path):
    from types import SimpleNamespace
    from dsm.grad import findings, tables
    blind = SimpleNamespace(value=0.0, error=0.0)
    p = SimpleNamespace(integrator="direct_projective", param="occluder_z", spp=4, grads=[0.0, 0.0], mean=0.0,
                        spread=0.0, primal_mismatch=0.0, ms=1.0)
    assert tables.agrees(p, blind) is None and tables.verdict(p, blind) == "measured nothing"
    tables.write_rows(tmp_path / "projective.csv", tables.PROJECTIVE_COLUMNS, [tables.projective_values(p, blind, None)])
    import csv
    (row,) = csv.DictReader(open(tmp_path / "projective.csv"))
    assert row["agrees"] == "" and row["rel_error"] == ""
    words = findings.projective_words([row])
    assert "agreed with the truth in 0 of 1" in words and "measured nothing" in words


def test_the_words_say_why_no_technique_is_closest_where_the_truth_is_zero_within_its_error():
    from dsm.grad import findings
    rows = [{"technique": t, "param": "occluder_x", "ad": ad, "reference": "0.00095", "reference_error": "0.0025",
             "rel_error": "", "sign": "", "cosine": ""} for t, ad in (("nearest", "0.05"), ("pcss", "0.01"))]
    text = findings.compare_words(rows)
    assert "undefined" in text and "the truth is 0 within its own error" in text and "nearest (" not in text
