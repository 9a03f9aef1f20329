"""Bad input: a clear error naming the file, the key and the valid choices, before any work."""
import pytest

from dsm.config import read as config
from dsm.config.read import ConfigError, Length

GOOD = """
[experiment]
name = "t"
[[scene]]
builtin = "plane"
[[scheme]]
name = "constant"
bias = ["1 texel", 0.01]
"""

BAD = [
    # (replacement config text, key expected in the message, a valid choice expected in it)
    (GOOD + "\n[bogus]\nx = 1\n", "bogus", "scheme"),
    (GOOD.replace('name = "constant"', 'name = "constnat"'), "scheme[0].name", "slope_scaled"),
    (GOOD.replace('builtin = "plane"', 'builtin = "plnae"'), "scene[0].builtin", "plane_box"),
    (GOOD.replace('"1 texel"', '"1 texle"'), "scheme[0].bias", "texel"),
    (GOOD.replace('"1 texel"', 'true'), "scheme[0].bias", None),
    (GOOD.replace('bias = ["1 texel", 0.01]', 'bais = 0.1'), "scheme[0].bais", "bias"),
    (GOOD + '\n[map]\nresolution = "big"\n', "map.resolution", None),
    (GOOD + '\n[map]\nfilter = "gaussian"\n', "map.filter", "nearest"),
    (GOOD + '\n[[light]]\ntype = "laser"\n', "light[0].type", "directional"),
    (GOOD + '\n[[light]]\ntype = "directional"\ndirection = [0, 0]\n', "light[0].direction", None),
    (GOOD.replace('builtin = "plane"', 'builtin = "plane"\ntilt = "steep"'), "scene[0].tilt", None),
    (GOOD.replace('[[scene]]\nbuiltin = "plane"', '[[scene]]\nfile = "missing.ply"'), "scene[0].file", None),
]


@pytest.mark.parametrize("text,key,choice", BAD)
def test_bad_config_names_file_key_and_choices(tmp_path, text, key, choice):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as e:
        config.load(path)
    msg = str(e.value)
    assert str(path) in msg and key in msg, msg
    if choice:
        assert choice in msg, msg


def test_good_config_sweeps(tmp_path):
    path = tmp_path / "good.toml"
    path.write_text(GOOD + '\n[map]\nresolution = [64, 128]\n')
    cfg = config.load(path)
    assert [s.params.bias for s in cfg.schemes] == [Length(1.0, "texel"), Length(0.01, "world")]
    assert cfg.map.resolution == (64, 128)


@pytest.mark.slow
def test_xml_without_usable_emitter_gets_a_default_light(tmp_path, run_dict):
    """An area-lit XML scene gets a point light at its luminaire, said in run.json; the plan agrees."""
    from dsm.config import plan
    xml = tmp_path / "area.xml"
    xml.write_text('<scene version="3.0.0"><sensor type="perspective"><transform name="to_world">'
                   '<lookat origin="0, -4, 3" target="0, 0, 0" up="0, 0, 1"/></transform>'
                   '<film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="48"/>'
                   '</film></sensor>'
                   '<shape type="rectangle"><transform name="to_world"><scale value="3"/></transform></shape>'
                   '<shape type="cube"><transform name="to_world"><scale value="0.3"/>'
                   '<translate z="0.4"/></transform></shape>'
                   '<shape type="rectangle"><transform name="to_world"><scale value="0.2"/><rotate x="1" angle="180"/>'
                   '<translate z="2.5"/></transform><emitter type="area"/></shape></scene>')
    raw = {"scene": [{"file": str(xml)}], "camera": {"resolution": [64, 64]}, "map": {"resolution": 64, "view": "cube"},
           "scheme": [{"name": "adaptive"}]}
    cfg = config.parse(raw, "<test>")
    p = plan.make(cfg)
    assert p.scenes[0][1:3] == (64, 48) and p.scenes[0][3] == [("0:point", "point")]
    res = run_dict(raw)
    assert [r["light"] for r in res.rows] == ["0:point"] and res.rows[0]["n_gt_shadowed"] > 20
    notes = [s for s in res.run["status"] if s["status"] == "note"]
    assert notes and "default point light" in notes[0]["error"]
    assert res.run["rays"]["gbuffer"] == p.rays["gbuffer"]


def test_length_parsing():
    assert Length.parse("2 texel") == Length(2.0, "texel")
    assert Length.parse("0.5 texels") == Length(0.5, "texel")
    assert Length.parse(3) == Length(3.0, "world")
    assert str(Length(2.0, "texel")) == "2 texel"
    with pytest.raises(ConfigError):
        Length.parse("nan texel")


def test_cli_prints_config_error_without_traceback(tmp_path, capsys):
    from dsm import cli
    path = tmp_path / "bad.toml"
    path.write_text(BAD[1][0])
    capsys.readouterr()
    rc = cli.main(["run", str(path), "--out", str(tmp_path / "o")])      # in-process: a traceback would raise here
    err = capsys.readouterr().err
    assert rc == 2
    assert "Traceback" not in err
    lines = [l for l in err.splitlines() if l.strip()]
    assert 1 <= len(lines) <= 2 and "scheme[0].name" in lines[0] and "valid:" in lines[0]
    assert not (tmp_path / "o").exists()          # nothing started
