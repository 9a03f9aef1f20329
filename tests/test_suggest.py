"""Errors that suggest: a misspelt scheme, config key, Results column and testing metric each give one
line that names the nearest valid name (dsm.core.suggest), and dsm.testing hides its own frames."""
import difflib

import pytest

from conftest import base_config
from dsm import ConfigError, parse_config, schemes
from dsm.core import record, suggest
from dsm.experiment.results import Results
from dsm.testing import assert_rate


def _one_line(e) -> str:
    text = str(e.value).strip("'\"")        # a KeyError's str() quotes its message
    assert "\n" not in text
    return text


def _rows():
    """Two cases with every column of metrics.csv (text columns as words, the others as numbers)."""
    row = {c: ("x" if c in record.TEXT_COLUMNS else 0.5) for c in record.NAMES}
    return [dict(row, case="c0", scheme="normal_offset", params="scale=1"), dict(row, case="c1", scheme="constant",
                                                                                 params="bias=1 texel")]


def test_the_nearest_name_is_difflibs_best_and_a_tie_names_both():
    words = ["constant", "normal_offset", "slope_scaled"]
    assert suggest.nearest("normal_ofset", words) == ["normal_offset"]
    assert suggest.nearest("zzzz", words) == []
    # two names at the same ratio from the given one: both, in listed order (a tie said as a tie)
    ratio = difflib.SequenceMatcher(None, "ab", "abc").ratio()
    assert ratio == difflib.SequenceMatcher(None, "ab", "abd").ratio()
    assert suggest.nearest("ab", ["abd", "abc", "xyz"]) == ["abd", "abc"]
    assert suggest.unknown("scheme", "zzzz", words) == "unknown scheme 'zzzz' (valid: constant, normal_offset, slope_scaled)"


def test_a_misspelt_scheme_names_the_nearest():
    with pytest.raises(ConfigError) as e:
        parse_config(base_config(scheme=[{"name": "normal_ofset"}]), "t.toml")
    assert _one_line(e).startswith("t.toml: scheme[0].name: unknown value 'normal_ofset' "
                                   "(did you mean 'normal_offset'? valid: none, constant,")
    with pytest.raises(KeyError) as e:
        schemes.get("slope_scaling")
    assert _one_line(e).startswith("unknown scheme 'slope_scaling' (did you mean 'slope_scaled'? valid: ")


def test_a_misspelt_key_names_the_nearest():
    with pytest.raises(ConfigError) as e:
        parse_config(base_config(map={"resoluton": 64}), "t.toml")
    assert _one_line(e).startswith("t.toml: map.resoluton: unknown key (did you mean 'resolution'? valid: ")
    with pytest.raises(ConfigError) as e:
        parse_config(dict(base_config(), shceme=[{"name": "none"}]), "t.toml")
    assert "(did you mean 'scheme'? valid: " in _one_line(e)


def test_a_misspelt_column_and_value_name_the_nearest(tmp_path):
    res = Results(tmp_path, _rows(), {})
    with pytest.raises(KeyError) as e:
        res.where(shceme="constant")
    assert "no column or scheme parameter shceme (did you mean 'scheme'? columns:" in _one_line(e)
    with pytest.raises(ValueError) as e:
        res.where(scheme="constnt")
    assert _one_line(e).startswith("Results.where: no row has scheme='constnt' (did you mean 'constant'? scheme holds: "
                                   "constant, normal_offset)")
    with pytest.raises(KeyError) as e:
        res.column("acne_rte")
    assert "no column 'acne_rte' (did you mean 'acne_rate'? columns:" in _one_line(e)


def test_a_misspelt_metric_names_the_nearest_and_the_numeric_columns(tmp_path):
    res = Results(tmp_path, _rows(), {})
    with pytest.raises(ValueError) as e:
        assert_rate(res, "acne_rte", below=0.1)
    text = _one_line(e)
    assert text.startswith("assert_rate: no column 'acne_rte' (did you mean 'acne_rate'? numeric columns: ")
    assert "error_rate" in text and "peterpan_rate" in text


def _shown_frames(e) -> list:
    """The names of the frames pytest prints for a failure (those without __tracebackhide__)."""
    return [entry.frame.code.name for entry in e.traceback if not entry.ishidden(e)]


def test_testing_hides_its_own_frames_from_pytest(tmp_path):
    """A threshold's failure and a filter's mistake show only the caller's frame: every dsm.testing
    frame (and Results.where's) sets __tracebackhide__."""
    res = Results(tmp_path, _rows(), {})
    here = "test_testing_hides_its_own_frames_from_pytest"
    with pytest.raises(AssertionError) as e:
        assert_rate(res, "acne_rate", below=0.1, scheme="constant")
    assert _shown_frames(e) == [here]
    with pytest.raises(ValueError) as e:
        assert_rate(res, "acne_rte", below=0.1)
    assert _shown_frames(e) == [here]
    with pytest.raises(ValueError) as e:
        assert_rate(res, "acne_rate", below=0.1, scheme="constnt")
    assert _shown_frames(e) == [here]


def test_a_misspelt_command_names_the_nearest(capsys):
    from dsm.cli import main
    assert main(["plna"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "invalid choice: 'plna' (did you mean 'plan'? valid: run, report, plan," in err


def test_a_misspelt_smrt_preset_or_rule_names_the_nearest():
    """SMRT's filter label: a preset or march rule one edit off is named; a far one is not guessed."""
    from dsm.maps import smrt_presets
    for label, near in (("smrt:ue5_locl", "'ue5_local'"), ("smrt:4x4:hld", "'hold'")):
        with pytest.raises(ValueError) as e:
            smrt_presets.settings(label)
        assert f"did you mean {near}?" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(ValueError) as e:
        smrt_presets.settings("smrt:qqqqqqqq")
    assert "did you mean" not in str(e.value)
