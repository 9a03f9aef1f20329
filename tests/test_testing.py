"""dsm.testing and the pytest plugin: a failing threshold lists the offending cases (rates, where,
image paths), a filter that matches nothing and an undefined rate never pass, and the plugin's
fixture runs a config once for several tests."""
import math

import pytest

from conftest import base_config
from dsm.testing import assert_no_worse_than, assert_oracle_gap, assert_rate

CFG = base_config(scene=[{"builtin": "plane_box"}, {"builtin": "plane"}], camera={"resolution": [32, 32]},
                  map={"resolution": 64}, scheme=[{"name": "none"}, {"name": "constant", "bias": "2 texel"}])


@pytest.fixture(scope="module")
def res(tmp_path_factory):
    import dsm
    return dsm.run(CFG, out=tmp_path_factory.mktemp("t") / "run")


def test_a_failing_threshold_lists_the_offending_cases(res):
    none = res.where(scheme="none").rows
    with pytest.raises(AssertionError) as e:
        assert_rate(res, "acne_rate", below=0.01, scheme="none")
    text = str(e.value)
    bad = [r for r in none if not r["acne_rate"] < 0.01]
    assert bad and text.splitlines()[0] == f"acne_rate < 0.01 fails in {len(bad)} of {len(none)} cases ({{'scheme': 'none'}}):"
    for r in bad:
        line = next(line for line in text.splitlines() if f"case {r['case']}:" in line)
        assert f"acne_rate = {r['acne_rate']:.6g}" in line and r["scene"] in line and "_error.png" in line
    assert_rate(res, "acne_rate", below=0.01, scheme="constant")     # the biased one holds


def test_nothing_matched_and_undefined_rates_never_pass(res):
    with pytest.raises(ValueError, match="no row has scheme='nonne'"):
        assert_rate(res, "acne_rate", below=1.0, scheme="nonne")
    plane = res.where(scene=[r["scene"] for r in res.rows if r["n_gt_shadowed"] == 0][0], scheme="constant")
    assert math.isnan(plane.rows[0]["peterpan_rate"])               # no shadow on a lone plane: undefined
    with pytest.raises(AssertionError, match="undefined"):
        assert_rate(plane, "peterpan_rate", below=1.0)
    assert_rate(plane, "peterpan_rate", below=1.0, allow_undefined=True)


def test_no_worse_than_and_the_oracle_gap(res):
    assert_no_worse_than(res, "error_rate", "constant", than="none")
    with pytest.raises(AssertionError, match="none is worse than constant"):
        assert_no_worse_than(res, "error_rate", "none", than="constant")
    r = res.where(scheme="none", scene="plane_box").rows[0]
    (o,) = [o for o in res.oracle if o["scene"] == "plane_box"]
    gap = (r["n_acne"] + r["n_peterpan"]) / r["n_receivers"] - o["world_objective"]
    assert gap > 0.05
    assert_oracle_gap(res, below=gap + 1e-9, scheme="none", scene="plane_box")
    with pytest.raises(AssertionError, match=f"gap {gap:.6g}"):
        assert_oracle_gap(res, below=gap / 2, scheme="none", scene="plane_box")


def test_the_plugin_fixture_runs_a_config_once_for_several_calls(dsm_results, monkeypatch):
    import dsm
    calls = []
    real = dsm.run
    monkeypatch.setattr(dsm, "run", lambda *a, **k: calls.append(1) or real(*a, **k))
    cfg = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [24, 24]}, map={"resolution": 32},
                      experiment={"name": "plugin-once"})
    first = dsm_results(cfg)
    assert dsm_results(dict(cfg)) is first and dsm_results(cfg) is first
    assert len(calls) == 1


@pytest.mark.parametrize("call, error, words", [
    (lambda r: assert_rate(r, "acne", below=0.5), ValueError, ["no column 'acne'", "acne_rate", "dsm.core.record.NAMES"]),
    (lambda r: assert_rate(r, "err", below=0.5), ValueError, ["no column 'err'", "error_rate"]),
    (lambda r: assert_no_worse_than(r, "eror_rate", "none", than="constant"), ValueError, ["no column", "error_rate"]),
    (lambda r: assert_rate(r, "scheme", below=0.5), TypeError, ["'scheme' is a text column", "acne_rate"]),
    (lambda r: assert_rate(r, "acne_rate", below="0.5"), TypeError, ["below must be a number", "'0.5'"]),
    (lambda r: assert_rate(r, "acne_rate", above=float("nan")), ValueError, ["above = nan", "finite"]),
    (lambda r: assert_no_worse_than(r, "error_rate", "none", than="constant", tolerance=float("nan")), ValueError,
     ["tolerance = nan", "finite"]),
    (lambda r: assert_oracle_gap(r, below="0.1"), TypeError, ["below must be a number"]),
    (lambda r: assert_no_worse_than(r, "error_rate", "none", than="constant", tolerance=None), TypeError,
     ["tolerance must be a number"]),
    (lambda r: assert_rate(r.where(allow_empty=True, scheme="nonne"), "acne_rate", below=0.5), ValueError,
     ["the Results hold no case"]),
])
def test_a_misspelt_column_or_a_threshold_that_is_no_number_is_named(res, call, error, words):
    """Issue 76: a KeyError naming nothing, a bare TypeError, and NaN passing where 0 fails."""
    with pytest.raises(error) as e:
        call(res)
    assert all(w in str(e.value) for w in words), str(e.value)


def test_the_plugin_fixture_on_a_missing_config_raises_dsm_runs_config_error(dsm_results, tmp_path):
    import dsm
    from dsm.core.types import ConfigError
    with pytest.raises(ConfigError) as direct:
        dsm.run(tmp_path / "missing.toml", out=tmp_path / "a")
    with pytest.raises(ConfigError) as fixture:
        dsm_results(tmp_path / "missing.toml")
    assert str(fixture.value).replace(str(fixture.value.source), "") == str(direct.value).replace(
        str(direct.value.source), "") or str(fixture.value) == str(direct.value)


def test_loading_the_plugin_imports_neither_mitsuba_nor_drjit():
    import subprocess
    import sys
    code = "import sys, dsm.pytest_plugin; assert 'mitsuba' not in sys.modules and 'drjit' not in sys.modules"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0
