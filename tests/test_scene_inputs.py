"""Scene file inputs (dsm/scenes): XML emitters missing or not finite, placement keys on an XML scene, OBJ
files cut mid record, each one readable line."""
from pathlib import Path

import pytest

from conftest import cli_run as _cli, one_line as _one_line
from dsm import cli


def test_an_xml_without_an_emitter_says_its_default_light_in_one_readable_line(tmp_path):
    import dsm
    from conftest import base_config
    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><shape type="rectangle"><transform name="to_world"><scale value="3"/>'
                   '</transform></shape><shape type="cube"><transform name="to_world"><scale value="0.3"/>'
                   '<translate z="0.5"/></transform></shape><sensor type="perspective"><transform name="to_world">'
                   '<lookat origin="3,-3,3" target="0,0,0" up="0,0,1"/></transform><film type="hdrfilm">'
                   '<integer name="width" value="32"/><integer name="height" value="32"/></film></sensor></scene>')
    res = dsm.run(base_config(scene=[{"file": str(xml)}], light=[{"type": "scene"}], map={"resolution": 32},
                              camera={"resolution": [32, 32]}), out=tmp_path / "r")
    notes = [s["error"] for s in res.run["status"] if s["status"] == "note"]
    assert len(notes) == 1 and "default directional light shining along (" in notes[0], notes
    assert "LightSpec" not in notes[0] and "\n" not in notes[0]


@pytest.mark.parametrize("emitter,what", [
    ('<emitter type="point"><point name="position" x="nan" y="0" z="3"/></emitter>', "position"),
    ('<emitter type="point"><point name="position" x="inf" y="0" z="3"/></emitter>', "position"),
    ('<emitter type="spot"><float name="cutoff_angle" value="nan"/><transform name="to_world">'
     '<lookat origin="0,0,3" target="0,0,0"/></transform></emitter>', "cutoff_angle")])
def test_an_xml_emitter_that_is_not_finite_is_one_line(tmp_path, capsys, emitter, what):
    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><shape type="rectangle"><transform name="to_world"><scale value="3"/>'
                   '</transform></shape>' + emitter + '<sensor type="perspective"><transform name="to_world">'
                   '<lookat origin="3,-3,3" target="0,0,0" up="0,0,1"/></transform><film type="hdrfilm">'
                   '<integer name="width" value="32"/><integer name="height" value="32"/></film></sensor></scene>')
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[experiment]\nname = "c"\n[[scene]]\nfile = "{xml}"\n[map]\nresolution = 16\n'
                   '[[scheme]]\nname = "none"\n')
    capsys.readouterr()
    assert cli.main(["plan", str(cfg)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "scene[0].file" in err[0] and what in err[0] and "not finite" in err[0], err


CBOX = Path(__file__).resolve().parent.parent / "data" / "meshes" / "cbox_mitsuba" / "cbox.xml"


@pytest.mark.parametrize("key,value", [("up", '"z"'), ("ground", '"no"')])
def test_a_placement_key_on_an_xml_scene_names_that_key(tmp_path, capsys, key, value):
    """The error named scene[0] and "up/ground/...", not the key given (an XML scene takes scale,
    translate and, since issue 77, precision: tests/test_derive.py runs it)."""
    path = tmp_path / "c.toml"
    path.write_text(f'[experiment]\nname = "x"\n[[scene]]\nfile = "{CBOX}"\n{key} = {value}\n'
                    '[map]\nresolution = 16\n[[scheme]]\nname = "none"\n')
    rc, err = _cli(capsys, "plan", path)
    assert rc == 2
    _one_line(err, str(path), f"scene[0].{key}:", "XML", "precision")


@pytest.mark.parametrize("tail, what", [("f 2 4", "face with fewer than 3 corners"),
                                        ("v 1 1", "vertex with fewer than 3 coordinates")])
def test_an_obj_cut_mid_record_is_refused_naming_the_line(tmp_path, capsys, tail, what):
    obj = tmp_path / "cut.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\n" + tail)
    cfg = tmp_path / "c.toml"
    cfg.write_text('[[scene]]\nfile = "cut.obj"\n[[scheme]]\nname = "none"\n')
    rc, err = _cli(capsys, "run", cfg, "--out", tmp_path / "o")
    assert rc == 2
    _one_line(err, "scene[0].file", "line 6", what)


def test_an_unknown_key_of_an_xml_scene_lists_the_keys_an_xml_scene_takes(tmp_path, capsys):
    """An XML scene's unknown key lists what an XML scene takes (it listed a mesh file's keys, such
    as ground and up, which an XML scene refuses)."""
    from conftest import MESHES
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[[scene]]\nfile = "{MESHES / "cbox_mitsuba" / "cbox.xml"}"\nbogus = 1\n[[scheme]]\nname = "none"\n')
    rc, err = _cli(capsys, "plan", cfg)
    assert rc == 2
    _one_line(err, "scene[0].bogus", "unknown key", "scale", "translate")
    assert "ground" not in err[0] and "up," not in err[0]


def test_a_truncated_sponza_obj_names_its_line_not_numpy(tmp_path):
    from dsm.core.types import ConfigError
    from dsm.scenes import models
    obj = tmp_path / "sponza.obj"
    obj.write_text("v 0 0 0\nv 1 1 1\nv 2 2\n")
    with pytest.raises(ConfigError) as e:
        models.version_of(models.SPONZA, obj, None, "s.toml", "scene[0]")
    text = str(e.value)
    assert "scene[0].file" in text and "line 3 is a vertex with fewer than 3 coordinates" in text
    assert "inhomogeneous" not in text
