"""Parameter labels a reader can read (dsm.core.labels): floats to four significant digits, a
depth-range bias that is a power of two named as one, the exact text kept for the hover."""
import math

from dsm.core import labels


def test_a_24_bit_depth_step_reads_as_a_power_of_two():
    # metrics.csv writes 2^-24 with %g's six digits: 5.96046e-08
    written = f"{2.0 ** -24:g}"
    assert written == "5.96046e-08"
    params = f"bias={written} range slope=3.0 clamp=0.0078125 range"
    assert labels.params_label(params) == "bias=2^-24 range slope=3 clamp=0.007812 range"
    assert labels.params_notes(params) == ["2^-24 range: one step of a 24-bit depth buffer"]
    assert labels.params_title(params).startswith(f"exact: {params}")


def test_floats_to_their_meaningful_digits_and_other_words_untouched():
    assert labels.params_label("bias=1.2142857142857142 texel") == "bias=1.214 texel"
    assert labels.params_label("normal_offset=0.848528 texel depth_bias=0.08 slope_clamp=inf") == \
        "normal_offset=0.8485 texel depth_bias=0.08 slope_clamp=inf"
    assert labels.params_label("z_offset=4 texel culling=back_closed") == "z_offset=4 texel culling=back_closed"
    assert labels.params_label("") == "" and labels.params_title("") == ""
    # a world length is never named a power of two, nor a range value that is not one (to %g's digits)
    assert labels.params_label(f"bias={2.0 ** -24:g}") == "bias=5.96e-8"
    assert labels.params_label(f"bias={1.01 * 2.0 ** -24:g} range") == "bias=6.02e-8 range"
    assert labels.params_label(f"bias={2.0 ** -16:g} range") == "bias=2^-16 range"
    assert labels.params_label("bias=0.5 range") == "bias=0.5 range"        # above 2^-10: plain digits


def test_number_text_keeps_four_significant_digits():
    for v in (1.2142857142857142, 123456.0, 0.000123456, 3.0, -2.5e-9):
        shown = labels.number_text(v)
        assert math.isclose(float(shown), float(f"{v:.4g}"), rel_tol=0) and "e+" not in shown


def _row(scene, scheme, params, acne):
    """A nearest-filter case of light 0:directional at R = 64 with 100 receivers and ``acne`` acne."""
    from dsm.core import record
    r = {c: ("" if c in record.TEXT_COLUMNS else 0.0) for c in record.NAMES}
    r.update(case=f"{scene}-{scheme}", scene=scene, light="0:directional", view="orthographic", resolution=64,
             scheme=scheme, params=params, preset="", filter="nearest", format="float32", n_receivers=100,
             n_acne=acne, n_peterpan=0, acne_rate=acne / 100, peterpan_rate=0.0, error_rate=acne / 100)
    return r


SLOPE = f"bias={2.0 ** -24:g} range slope=3.0 clamp=0.0078125 range"
ROWS = [_row("plane", "slope_scaled", SLOPE, 1), _row("plane_box", "slope_scaled", SLOPE, 2),
        _row("plane", "constant", "bias=0.05", 5), _row("plane_box", "constant", "bias=0.05", 6)]


def test_the_console_and_table_md_name_a_bias_as_the_report_does_and_say_what_they_pool():
    from dsm.report import summary
    shown = "slope_scaled bias=2^-24 range slope=3.0 clamp=0.0078125 range"     # other numbers as written
    lines = summary.terminal_answer(ROWS)
    # pooled over both scenes: (1 + 2) acne of 200 receivers
    assert f"best for light 0:directional over 2 scenes at R = 64: {shown} (0.015)" in lines
    assert not any("5.96046e-08" in line for line in lines)
    table = summary.best_md(ROWS)
    assert table[2] == f"| plane | 0:directional | {shown} (0.01) |"
    assert summary.pooled_scenes(ROWS[:1], "0:directional") == "in plane"


def test_a_label_pastes_back_into_a_config_as_the_same_instance():
    from dsm.core.types import Length
    from dsm.experiment.results import label_key
    assert Length.parse("2^-24 range") == Length(2.0 ** -24, "range")
    assert labels.params_label(SLOPE, exact=True) == "bias=2^-24 range slope=3.0 clamp=0.0078125 range"
    # Results.where reads the shown label as the run's text
    assert label_key("bias=2^-24 range") == label_key(f"bias={2.0 ** -24:g} range")
    assert label_key("bias=2^-23 range") != label_key(f"bias={2.0 ** -24:g} range")


def test_dsm_plan_cuts_no_light_name(tmp_path, capsys):
    from dsm.cli import main
    cfg = tmp_path / "p.toml"
    cfg.write_text('[[scene]]\nbuiltin = "plane_box"\n[[light]]\ntype = "directional"\ndirection = [0, 0, -1]\n'
                   '[map]\nresolution = 64\n[[scheme]]\nname = "slope_scaled"\nbias = "2^-24 range"\n')
    assert main(["plan", str(cfg)]) == 0
    maps = [line for line in capsys.readouterr().out.splitlines() if line.startswith("    plane_box ")]
    assert maps and all(" 0:directional " in line and "slope_scaled bias=2^-24 range" in line for line in maps)


def test_results_show_as_an_html_table_labelled_as_the_console(tmp_path):
    """Results._repr_html_ (what Jupyter and the site show): one row a case, the params as the console
    labels them, an undefined rate as ``undefined``, text escaped."""
    from dsm.experiment.results import Results
    rows = [dict(_row("plane", "slope_scaled", SLOPE, 1), peterpan_rate=math.nan),
            dict(_row("plane", "constant", "bias=0.05", 5), scheme="<b>")]
    html = Results(tmp_path, rows, {})._repr_html_()
    assert html.startswith('<table class="dsm-results"><thead><tr><th>scheme</th><th>params</th>')
    assert html.count("<tr>") == 3 and "<td>bias=2^-24 range slope=3.0 clamp=0.0078125 range</td>" in html
    assert ">undefined</td>" in html and "&lt;b&gt;" in html and "<b>" not in html


def test_dsm_schemes_names_a_depth_step_as_the_report_does():
    from dsm.cli import schemes_text
    text = schemes_text()
    assert "    bias = 2^-24 range    " in text and "depth_bias=2^-24 range slope_scale=3.0" in text
    assert "5.96046e-08" not in text
