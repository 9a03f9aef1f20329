"""Bad config input (dsm/config): clip planes, thread counts, names over 255 bytes, repeated case dimensions,
seeds and --out, each one line and exit 2 before any work, or the right result."""
from pathlib import Path

import pytest

from conftest import tiny_toml, cli_run as _cli, one_line as _one_line, base_config
from dsm import cli
from dsm.config import read as config
from dsm.config.read import ConfigError


@pytest.mark.parametrize("key,value", [("far", "1e-3"), ("near", "100")])
def test_a_clip_plane_alone_that_crosses_the_other_is_a_config_error(tmp_path, capsys, key, value):
    cfg = tmp_path / "c.toml"
    cfg.write_text(tiny_toml().replace("resolution = [32, 32]", f"resolution = [32, 32]\n{key} = {value}"))
    for cmd in (["plan", cfg], ["run", cfg, "--out", tmp_path / "o"]):
        rc, err = _cli(capsys, *cmd)
        assert rc == 2
        _one_line(err, "config error", f"camera.{key}", value.replace("1e-3", "0.001"))
    assert not (tmp_path / "o").exists()


def test_a_clip_plane_alone_that_fits_still_runs(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(tiny_toml().replace("resolution = [32, 32]", "resolution = [32, 32]\nfar = 100"))
    assert _cli(capsys, "run", cfg, "--out", tmp_path / "o")[0] == 0


def test_an_absurd_thread_count_is_one_line(tmp_path, capsys, cfg_file):
    for n in ("100000", "1025"):
        rc, err = _cli(capsys, "run", cfg_file, "--threads", n, "--out", tmp_path / "o")
        assert rc == 2
        _one_line(err, "--threads", "1024", n)
    assert not (tmp_path / "o").exists()
    from dsm.core import env
    with pytest.raises(env.SetupError, match="1 to 1024"):
        env.use_variant(None, 100000)


def test_a_name_over_255_bytes_is_one_line(tmp_path, capsys, cfg_file, monkeypatch):
    long = "x" * 300
    rc, err = _cli(capsys, "run", cfg_file, "--out", tmp_path / long / "o")
    assert rc == 2
    _one_line(err, "--out", "300 bytes", "255")
    rc, err = _cli(capsys, "report", tmp_path / long)
    assert rc == 2
    _one_line(err, "report", "300 bytes")
    half = "y" * 130                                    # each fine, the default compare-A-B is not
    rc, err = _cli(capsys, "report", tmp_path / half, tmp_path / (half + "z"))
    assert rc == 2
    _one_line(err, "--out", "compare-", "270 bytes")
    named = tmp_path / "n.toml"
    named.write_text(tiny_toml(name="e" * 240))
    monkeypatch.chdir(tmp_path)
    rc, err = _cli(capsys, "run", named)
    assert rc == 2
    _one_line(err, "experiment.name", "240 bytes")
    assert not (tmp_path / "runs").exists()
    named.write_text(tiny_toml(name="e" * 230))             # the longest name a run folder takes (suffix -n included)
    assert config.load(named).name == "e" * 230


def test_clip_planes_equal_in_float32_are_one_line(tmp_path, capsys):
    """near = 5, far = 5.0000001: one float32 value, which Mitsuba refused with a traceback."""
    cfg = tmp_path / "c.toml"
    cfg.write_text('[experiment]\nname = "c"\n[camera]\nresolution = [32, 32]\nnear = 5.0\nfar = 5.0000001\n'
                   '[[scene]]\nbuiltin = "plane_box"\n[map]\nresolution = 16\n[[scheme]]\nname = "none"\n')
    capsys.readouterr()
    assert cli.main(["plan", str(cfg)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "camera" in err[0] and "near clip" in err[0] and "Traceback" not in err[0], err


@pytest.mark.parametrize("over, key, words", [
    ({"map": {"resolution": [64, 128, 64]}}, "map.resolution", ("64 is given twice",)),
    ({"map": {"resolution": 64, "filter": ["nearest", "pcss", "nearest"]}}, "map.filter", ("nearest is given twice",)),
    ({"map": {"resolution": 64, "format": ["unorm16", "unorm16"]}}, "map.format", ("unorm16 is given twice",)),
    # "1 texel" and "1.0 texel" are one length: the same instance twice
    ({"scheme": [{"name": "constant", "bias": ["1 texel", "2 texel", "1.0 texel"]}]}, "scheme[0].bias",
     ("'1.0 texel' is given twice", "as '1 texel'")),
    ({"scheme": [{"name": "none"}, {"name": "constant", "bias": 0.1}, {"name": "constant", "bias": [0.2, 0.1]}]},
     "scheme[2]", ("constant bias=0.1", "already scheme[1]'s")),
])
def test_a_repeated_case_dimension_is_refused(over, key, words):
    """A value given twice in a case dimension would run the same cases twice under two ids (and a
    resumed run could not tell them apart): refused, naming the key and the repeated value."""
    with pytest.raises(ConfigError) as e:
        config.parse(base_config(**over))
    msg = str(e.value)
    assert key in msg and all(w in msg for w in words), msg


def test_a_negative_experiment_seed_is_refused(tmp_path, capsys):
    cfg = tmp_path / "t.toml"
    cfg.write_text('[experiment]\nname = "t"\nseed = -3\n[[scene]]\nbuiltin = "plane"\n[[scheme]]\nname = "none"\n')
    rc, err = _cli(capsys, "plan", cfg)
    assert rc == 2
    _one_line(err, "experiment.seed", ">= 0")


def test_an_empty_out_is_refused_and_default_folders_never_collide(tmp_path, capsys, monkeypatch):
    """--out '' is a mistake, not the default; two default folders made in one second differ."""
    from dsm import cli
    cfg = tmp_path / "t.toml"
    cfg.write_text('[experiment]\nname = "t"\n[[scene]]\nbuiltin = "plane"\n[[scheme]]\nname = "none"\n')
    rc, err = _cli(capsys, "run", cfg, "--out", "")
    assert rc == 2
    _one_line(err, "--out", "empty")
    monkeypatch.chdir(tmp_path)
    a, b = cli.fresh_folder("t"), cli.fresh_folder("t")
    assert a != b and a.is_dir() and b.is_dir() and a.parent == b.parent == Path("runs")
