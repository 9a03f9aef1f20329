"""The Results API a user's threshold test reads: a filter that matches nothing raises (naming what
the column holds), values compared by their column's kind, a short repr, the terminal's first
answer, and a run without a folder that leaves none behind."""
import gc

import pytest

from conftest import base_config, small_run

CFG = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [32, 32]}, map={"resolution": [32, 64]},
                  scheme=[{"name": "constant", "bias": ["1 texel", 0.02]}, {"name": "adaptive"}])


@pytest.fixture(scope="module")
def res(tmp_path_factory):
    import dsm
    return dsm.run(CFG, out=tmp_path_factory.mktemp("api") / "run", report=False)


@pytest.mark.parametrize("kw, words", [
    ({"scheme": "adaptiv"}, ["scheme='adaptiv'", "adaptive", "constant"]),
    ({"params": "bias=3 texel"}, ["params='bias=3 texel'", "bias=1 texel"]),
    ({"resolution": 512}, ["resolution=512", "32", "64"]),
    ({"scheme": "dual"}, ["scheme='dual'", "adaptive, constant"]),
    ({"scheme": "adaptive", "params": "bias=1 texel"}, ["no row matches them all"]),
])
def test_a_filter_that_matches_nothing_raises_naming_what_there_is(res, kw, words):
    with pytest.raises(ValueError) as e:
        res.where(**kw)
    assert all(w in str(e.value) for w in words), str(e.value)
    assert len(res.where(allow_empty=True, **kw)) == 0          # empty only when asked for


def test_values_are_compared_by_their_columns_kind(res):
    n = sum(1 for r in res.rows if r["resolution"] == 64)
    assert n == 3 and len(res.where(resolution="64")) == len(res.where(resolution=64.0)) == n
    assert len(res.where(params="bias=1texel")) == len(res.where(params="bias=1.0 texel")) == 2
    assert len(res.where(params="bias=1 texel")) == 2
    # a scheme parameter by its name, its value and unit compared as words and numbers
    assert [r["params"] for r in res.where(bias="1.0 texel").rows] == ["bias=1 texel"] * 2
    assert len(res.where(bias=0.02)) == 2 and len(res.where(K=1e-4)) == 2
    with pytest.raises(ValueError, match="bias holds: 0.02, 1 texel"):
        res.where(bias="3 texel")
    with pytest.raises(KeyError, match="parameters of these rows: K, bias"):
        res.where(bais=1)


def test_the_repr_is_short_and_says_where_the_run_is(res):
    text = repr(res)
    assert len(text) < 300 and "6 cases" in text and str(res.out) in text


def test_the_terminal_answer_says_ties_and_the_lowest_pooled_error(res):
    from dsm.report import frontier, summary
    lines = summary.terminal_answer(res.rows)
    found = frontier.answers(frontier.points_from_rows(res.rows))
    first = frontier.answer_lines(found) + frontier.time_lines(found)       # what accuracy costs comes first
    assert lines[:len(first)] == first and first[0].startswith("directional (")
    lines = lines[len(first):]
    assert lines[0] == summary.answer(res.rows) and lines[0].startswith("Lowest pooled error rate")
    best = summary.best_per_light(res.rows)
    assert len(lines) == 1 + len(best) == 1 + 2               # one light, two resolutions
    for b, line in zip(best, lines[1:]):
        assert f"R = {b['resolution']}" in line and summary.best_cell(b) in line


@pytest.mark.slow
def test_a_run_without_a_folder_leaves_none_behind():
    """dsm.run without out: its folder lives while its Results (or a part of it) does, then goes."""
    import dsm
    res = dsm.run(CFG, report=False)
    out = res.out
    part = res.where(scheme="adaptive")
    del res
    gc.collect()
    assert (out / "metrics.csv").is_file()                   # the part keeps it
    del part
    gc.collect()
    assert not out.exists()


def test_dsm_run_ends_with_its_first_answer_then_the_folder(tmp_path, capsys):
    from dsm import cli
    toml = tmp_path / "e.toml"
    toml.write_text('[experiment]\nname = "e"\n[camera]\nresolution = [32, 32]\n[[scene]]\nbuiltin = "plane_box"\n'
                    '[map]\nresolution = 32\n[[scheme]]\nname = "constant"\nbias = ["1 texel", 0.02]\n')
    assert cli.main(["run", str(toml), "--out", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out.splitlines()
    first = [i for i, line in enumerate(out) if "Lowest pooled error rate" in line]
    where = [i for i, line in enumerate(out) if str(tmp_path / "r") in line]
    assert first and where and first[0] < where[0]
    assert any(line.startswith("dsm: best for light") for line in out)


def test_results_name_an_unknown_column_and_a_missing_case(tmp_path):
    res = small_run(tmp_path)
    with pytest.raises(KeyError, match="no column or scheme parameter schem"):
        res.where(schem="constant")
    assert len(res.where(scheme="constant")) == len(res.rows) == 1
    with pytest.raises(KeyError, match="no image of case 999.*'0001'"):
        res.rgb(999)
    assert res.rgb(res.rows[0]).shape == (32, 32, 3)
