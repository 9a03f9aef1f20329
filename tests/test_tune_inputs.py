"""dsm tune's inputs (dsm/tune): absurd or infinite values refused before any work, one-point grids and
starts outside their range said, the Optuna journal cut short or damaged."""
import tomllib

import pytest

from conftest import cli_run as _cli, one_line as _one_line, toml_text, base_config, cli_run, one_line, folder_files, write_toml
from dsm.config.read import ConfigError


CAMS3 = [{"position": [3.0, -5.0, 4.0], "target": [0.0, 0.0, 0.0]},
         {"position": [-3.0, -5.0, 4.0], "target": [0.0, 0.0, 0.0]},
         {"position": [-4.0, -3.0, 5.0], "target": [0.0, 0.0, 0.0], "role": "heldout"}]


def _tune_cfg(tune, schemes=({"name": "constant"},)):
    return {"experiment": {"name": "t"}, "camera": {"resolution": [32, 32]}, "scene": [{"builtin": "plane"}],
            "map": {"resolution": 32}, "scheme": list(schemes), "tune": tune}


@pytest.mark.parametrize("tune,key,words", [
    # an empty candidate list was an IndexError traceback
    ({"camera": CAMS3, "bias_map": {"fit": "residual", "block": []}}, "tune.bias_map.block", ["empty"]),
    ({"camera": CAMS3, "bias_map": {"fit": "residual", "radius": []}}, "tune.bias_map.radius", ["empty"]),
    ({"camera": CAMS3, "bias_map": {"block": []}}, "tune.bias_map.block", ["empty"]),
    # one scan point is the box's low end alone: table.md gave "tuned / scan" against it
    ({"scan": 1}, "tune.scan", ["both ends"]),
    # Adam's keys were silently ignored by the exact residual fit
    ({"camera": CAMS3, "bias_map": {"fit": "residual", "unit": "world"}}, "tune.bias_map.unit", ["adam"]),
    ({"camera": CAMS3, "bias_map": {"fit": "residual", "lr": 0.1}}, "tune.bias_map.lr", ["adam"]),
    ({"camera": CAMS3, "bias_map": {"fit": "residual", "steps": 5}}, "tune.bias_map.steps", ["adam"]),
])
def test_bad_tune_input_is_one_config_error(tmp_path, capsys, tune, key, words):
    path = tmp_path / "c.toml"
    path.write_text(toml_text(_tune_cfg(tune)))
    rc, err = _cli(capsys, "tune", path, "--out", tmp_path / "out")
    assert rc == 2
    _one_line(err, str(path), key, *words)
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_an_infinite_start_names_the_schemes_index_and_tune_params():
    """combined's default slope_clamp is inf: the error named "scheme.slope_clamp" (no index)."""
    from dsm.tune import tuner as tu
    from dsm.config.read import coerce
    cfg = _tune_cfg({}, [{"name": "constant"}, {"name": "combined"}])
    with pytest.raises(ConfigError) as e:
        tu.parse_tune(coerce(cfg))
    assert e.value.key == "scheme[1].slope_clamp" and "tune.params.combined" in str(e.value)
    cfg["tune"] = {"params": {"combined": ["depth_bias"]}}
    assert tu.parse_tune(coerce(cfg)).spec.params["combined"] == ("depth_bias",)


def test_dsm_tune_refuses_an_area_light(tmp_path, capsys):
    """It tuned against V* >= 0.5 and an "oracle" of that hard V*, where dsm run counts acne in the
    lit region alone and computes no oracle for an area light: a number where none is defined."""
    cfg = _tune_cfg({}, [{"name": "constant"}])
    cfg["light"] = [{"type": "area", "shape": "rectangle", "position": [0.6, -0.4, 3.0], "size": 0.5}]
    path = tmp_path / "c.toml"
    path.write_text(toml_text(cfg))
    rc, err = _cli(capsys, "tune", path, "--out", tmp_path / "out")
    assert rc == 2
    _one_line(err, str(path), "light[0].type", "area", "directional")


TUNE_CAMS = ('[[tune.camera]]\nposition = [3.0, -5.0, 4.0]\ntarget = [0.0, 0.0, 0.0]\n'
             '[[tune.camera]]\nposition = [-4.0, -3.0, 5.0]\ntarget = [0.0, 0.0, 0.0]\nrole = "heldout"\n')


@pytest.mark.parametrize("extra, key, words", [
    ("[tune]\nseed = -7\n", "tune.seed", ">= 0"),
    ("[tune]\nlambda = 1e30\n", "tune.lambda", "<= 1000000"),
    ("[oracle]\nlambda = [1.0, 1e9]\n", "oracle.lambda", "<= 1000000"),
    ('[tune]\n' + TUNE_CAMS + '[[tune.camera]]\nposition = [3.0, -5.0, 4.0]\ntarget = [0.0, 0.0, 0.0]\n'
     'role = "heldout"\nname = "twin"\n', "tune.camera[2]", "same pose"),
])
def test_tune_refuses_absurd_values_before_any_work(tmp_path, capsys, extra, key, words):
    """A negative seed (numpy refuses it mid-run), a weight that overflows the relaxed loss, a held-out
    camera on a training camera's pose: one line naming the key, exit 2, nothing written."""
    cfg = tmp_path / "t.toml"
    cfg.write_text('[experiment]\nname = "t"\n[[scene]]\nbuiltin = "l_shape"\n[[scheme]]\nname = "constant"\n' + extra)
    rc, err = _cli(capsys, "tune", cfg, "--out", tmp_path / "o")
    assert rc == 2
    _one_line(err, key, words)
    assert not (tmp_path / "o").exists()


def test_a_start_outside_its_range_is_noted(tmp_path):
    """[tune.range] that leaves out a scheme's start: the search begins from the start clipped into the
    box, and the notes say so (the result may be worse than the start)."""
    from dsm.tune import tuner as tu
    cfg = tomllib.loads('[experiment]\nname = "t"\n[camera]\nresolution = [32, 32]\n[[scene]]\nbuiltin = "l_shape"\n'
                        '[map]\nresolution = 32\n[[scheme]]\nname = "constant"\nbias = "1 texel"\n'
                        '[tune]\nsteps = 6\nrange.constant = { bias = [3.0, 4.0] }\n')
    res = tu.tune(cfg)
    assert res.schemes[0]["start_outside_box"] == ["bias"]
    assert 3.0 <= res.schemes[0]["values"]["bias"] <= 4.0
    assert any("outside its [tune.range] box" in n for n in res.notes)
    assert any("no [[tune.camera]]" in n for n in res.notes)


def test_a_one_point_grid_is_the_box_centre_and_said(tmp_path):
    """steps below 2^p leave the grid one point a parameter: the box's centre (not its lower corner,
    all zeros), and table.md says it compares nothing."""
    from dsm.tune import tuner as tu
    from dsm.tune.output import table_text
    cfg = tomllib.loads('[experiment]\nname = "t"\n[camera]\nresolution = [32, 32]\n[[scene]]\nbuiltin = "l_shape"\n'
                        '[map]\nresolution = 32\n[[scheme]]\nname = "combined"\nnormal_offset = "1 texel"\n'
                        'depth_bias = "0.5 texel"\nslope_scale = 0.5\nslope_clamp = "4 texel"\n[tune]\nsteps = 6\n')
    res = tu.tune(cfg)
    e = res.schemes[0]
    assert e["grid"]["points_per_parameter"] == 1
    for name, (lo, hi) in e["box"].items():
        assert e["grid"]["values"][name] == pytest.approx(0.5 * (lo + hi))
    assert "a grid of one point per parameter" in table_text(res)


def _journal_with_trials(folder, n: int):
    """A study of ``n`` completed trials in folder/optuna.journal, written by Optuna itself."""
    optuna = pytest.importorskip("optuna")
    from optuna.storages.journal import JournalFileBackend
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    store = optuna.storages.JournalStorage(JournalFileBackend(str(folder / "optuna.journal")))
    study = optuna.create_study(study_name="s", storage=store, sampler=optuna.samplers.RandomSampler(seed=1))
    study.optimize(lambda t: t.suggest_float("x", 0.0, 1.0) ** 2, n_trials=n)
    return optuna, [t.params["x"] for t in study.trials]


def _complete(optuna, folder) -> list:
    from optuna.storages.journal import JournalFileBackend
    store = optuna.storages.JournalStorage(JournalFileBackend(str(folder / "optuna.journal")))
    study = optuna.load_study(study_name="s", storage=store)
    return [t.params["x"] for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]


def test_an_append_a_kill_cut_short_is_cut_off_before_the_resume_appends(tmp_path):
    """kill -9 while Optuna appends leaves a last line without its newline; the resume's next record
    joined it into a line Optuna could not read (a JSONDecodeError, the study lost)."""
    from dsm.tune import blackbox
    optuna, xs = _journal_with_trials(tmp_path, 3)
    raw = (tmp_path / "optuna.journal").read_bytes()
    (tmp_path / "optuna.journal").write_bytes(raw[:-37])           # the last record cut short
    assert blackbox.journal_problem(tmp_path) is None
    kept = (tmp_path / "optuna.journal").read_bytes()
    assert kept.endswith(b"\n") and raw.startswith(kept) and len(kept) == raw.rfind(b"\n", 0, len(raw) - 37) + 1
    from optuna.storages.journal import JournalFileBackend
    store = optuna.storages.JournalStorage(JournalFileBackend(str(tmp_path / "optuna.journal")))
    study = optuna.load_study(study_name="s", storage=store)
    study.optimize(lambda t: t.suggest_float("x", 0.0, 1.0) ** 2, n_trials=1)       # the resume appends
    got = _complete(optuna, tmp_path)
    assert got[:2] == xs[:2] and len(got) == 3                     # the two whole trials kept, one more run


@pytest.mark.parametrize("damage", [b"\x00\x01garbage\n{not json\n", b"[1, 2]\n"])
def test_resume_refuses_a_damaged_journal_in_one_line(damage, tmp_path, capsys):
    from dsm.tune import resume as tune_resume
    cfg = write_toml(tmp_path / "t.toml", base_config(
        camera={"resolution": [32, 32]}, scene=[{"builtin": "plane_box"}], map={"resolution": 32},
        scheme=[{"name": "constant", "bias": "1 texel"}], tune={"steps": 4, "search": "optuna"}))
    out = tmp_path / "tune"
    out.mkdir()
    tune_resume.write_state(out, "test", [])
    (out / "optuna.journal").write_bytes(damage)
    (out / "notes.txt").write_text("mine")
    before = folder_files(tmp_path)
    pytest.importorskip("optuna")
    rc, err = cli_run(capsys, "tune", cfg, "--out", out, "--resume")
    assert rc == 2
    one_line(err, f"{out / 'optuna.journal'} line 1", "not a record of Optuna's journal", "--force")
    assert folder_files(tmp_path) == before
