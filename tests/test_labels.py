"""Parameter labels a reader can read (dsm.report.labels): floats to four significant digits, a
depth-range bias that is a power of two named as one, the exact text kept for the hover."""
import math

from dsm.report import labels


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
