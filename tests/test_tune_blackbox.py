"""dsm tune's black-box search (search = "optuna"): TPE and the AD tuner both reach the exact oracle,
the evaluations written are those made (counted here at the call sites), Optuna missing is one line,
an interrupted study resumes into the same trials, and NSGA-II's front is the non-dominated trials."""
import sys

import numpy as np
import pytest

pytest.importorskip("optuna", reason="the optional extra dsm[tune] (pip install 'dsm[tune]')")

PLATE = {"builtin": "floating_plate"}


def _cfg(tune, schemes=({"name": "constant", "bias": 0.01},)):
    return {"experiment": {"name": "t"}, "camera": {"resolution": [48, 48]}, "scene": [PLATE],
            "map": {"resolution": 64}, "scheme": list(schemes), "tune": {"search": "optuna", **tune}}


def _oracle(cfg):
    """The least exact objective of any constant world bias over the training views (numpy, from thresholds)."""
    import dsm.pipeline as pl
    from dsm.config.read import coerce
    from dsm.tune import cases as tcase, tuner as tu
    tc = tu.parse_tune(coerce(cfg))
    tc.config = pl.prepare(tc.config)
    groups, cases, _ = tcase.prepare_cases(tc)
    th, vs = tcase.pooled_thresholds(cases, groups)
    cands = np.concatenate([[-np.inf], np.unique(th.tau)])
    return min(((vs & (th.tau > b)).sum() + (~vs & (th.tau <= b)).sum()) / vs.size for b in cands)


@pytest.mark.slow
def test_tpe_and_the_ad_tuner_reach_the_oracle_with_the_evaluations_they_report(monkeypatch):
    """Both within 5 % of the exact oracle's objective (recomputed here); every exact evaluation, relaxed
    pass and line search counted by wrappers at the call sites equals what tune.json's entry reports."""
    from dsm.tune import blackbox, compare, refine, search, tuner as tu
    made = {"ad_exact": 0, "ad_relaxed": 0, "ad_line": 0, "tpe_exact": 0}

    def counting(module, name, key):
        real = getattr(module, name)

        def wrapper(*a, **k):
            made[key] += 1
            return real(*a, **k)
        monkeypatch.setattr(module, name, wrapper)
    counting(search, "hard_counts", "ad_exact")          # the start, coarse grid, Adam and refinement
    counting(search, "relaxed_loss", "ad_relaxed")
    counting(refine, "margin_line", "ad_line")
    counting(blackbox, "hard_counts", "tpe_exact")
    cfg = _cfg({"steps": 80})
    res = tu.tune(cfg)
    e = res.schemes[0]
    best = _oracle(cfg)
    assert best > 0
    assert e["train"]["objective"] <= 1.05 * best
    assert e["optuna"]["train"]["objective"] <= 1.05 * best
    assert e["ad"]["evaluations"] == {"exact": made["ad_exact"], "relaxed": made["ad_relaxed"], "line": made["ad_line"]}
    assert e["optuna"]["evaluations"] == {"exact": made["tpe_exact"], "relaxed": 0, "line": 0}
    assert e["optuna"]["trials"] == made["ad_exact"] == made["tpe_exact"]
    assert res.comparison[0]["tuned_evaluations"] == made["ad_exact"]
    assert compare.hard_counts is not search.hard_counts       # the grid's evaluations are not the AD tuner's


def test_without_optuna_the_search_is_one_line_naming_the_extra(tmp_path, monkeypatch, capsys):
    from dsm import cli
    cfg = tmp_path / "t.toml"
    cfg.write_text('[experiment]\nname = "t"\n[camera]\nresolution = [32, 32]\n[[scene]]\nbuiltin = "plane_box"\n'
                   '[map]\nresolution = 32\n[[scheme]]\nname = "constant"\n[tune]\nsteps = 4\nsearch = "optuna"\n')
    monkeypatch.setitem(sys.modules, "optuna", None)            # import optuna raises ImportError
    assert cli.main(["tune", str(cfg), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "dsm[tune]" in err[0] and "t.toml" in err[0] and "tune.search" in err[0]
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_two_objectives_need_optuna_and_a_search_name_is_checked(tmp_path):
    from dsm.config.read import coerce
    from dsm.core.types import ConfigError
    for tune, key in (({"objectives": 2, "search": "ad"}, "tune.objectives"), ({"search": "tpe"}, "tune.search"),
                      ({"objectives": 3}, "tune.objectives")):
        with pytest.raises(ConfigError) as e:
            coerce(dict(_cfg({}), tune=tune))
        assert e.value.key == key


@pytest.mark.slow
def test_an_interrupted_study_resumes_into_the_same_trials(tmp_path, monkeypatch):
    """Interrupted between a trial's draw and its result (the 8th exact evaluation), then resumed: the
    completed trials' values, in order, and the result equal an uninterrupted run's."""
    from dsm.tune import blackbox, tuner as tu
    cfg = _cfg({"steps": 24})
    whole = tu.tune(cfg, out=tmp_path / "whole")
    real, calls = blackbox.hard_counts, [0]

    def stop_at_eighth(*a, **k):
        calls[0] += 1
        if calls[0] == 8:
            raise KeyboardInterrupt
        return real(*a, **k)
    monkeypatch.setattr(blackbox, "hard_counts", stop_at_eighth)
    with pytest.raises(KeyboardInterrupt):
        tu.tune(cfg, out=tmp_path / "cut")
    monkeypatch.setattr(blackbox, "hard_counts", real)
    resumed = tu.tune(cfg, out=tmp_path / "cut", resume=True)

    def trials(folder):
        import optuna
        store = blackbox.storage(folder)
        (name,) = [s.study_name for s in optuna.get_all_study_summaries(store)]
        st = optuna.load_study(study_name=name, storage=store)
        done = st.get_trials(states=(optuna.trial.TrialState.COMPLETE,))
        return [(t.params, t.values) for t in sorted(done, key=lambda t: t.number)], len(st.trials)
    (a, n_whole), (b, n_cut) = trials(tmp_path / "whole"), trials(tmp_path / "cut")
    assert a == b and len(a) == whole.schemes[0]["optuna"]["trials"]
    assert n_cut == n_whole + 1                                 # the one cut short, failed
    assert resumed.schemes[0]["optuna"]["values"] == whole.schemes[0]["optuna"]["values"]
    assert resumed.schemes[0]["optuna"]["train"] == whole.schemes[0]["optuna"]["train"]


@pytest.mark.slow
def test_nsga2_front_is_the_non_dominated_trials(tmp_path):
    """objectives = 2: the front written holds exactly the (acne, peter-panning) points no trial of the study
    dominates (recomputed here from the journal), and the AD tuner's point is placed against it."""
    import optuna
    from dsm.tune import blackbox, tuner as tu
    res = tu.tune(_cfg({"steps": 24, "objectives": 2}), out=tmp_path / "o")
    f = res.schemes[0]["optuna_front"]
    store = blackbox.storage(tmp_path / "o")
    (name,) = [s.study_name for s in optuna.get_all_study_summaries(store) if s.study_name.endswith("nsga2")]
    pts = {tuple(t.values) for t in optuna.load_study(study_name=name, storage=store).get_trials(
        states=(optuna.trial.TrialState.COMPLETE,))}
    expect = sorted(p for p in pts if not any(q[0] <= p[0] and q[1] <= p[1] and q != p for q in pts))
    assert [(p["acne_per_receiver"], p["peterpan_per_receiver"]) for p in f["front"]] == expect
    ad = (f["ad_point"]["acne_per_receiver"], f["ad_point"]["peterpan_per_receiver"])
    assert f["ad_point"]["dominated"] == any(q[0] <= ad[0] and q[1] <= ad[1] and q != ad for q in pts)
