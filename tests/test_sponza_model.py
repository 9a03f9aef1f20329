"""[[scene]] model = "sponza": a user's copy by key or DSM_SPONZA, its version told by its size,
Crytek's centimetres put in the Dabrovic frame, and one line saying how to get a copy without one."""
import numpy as np
import pytest

from conftest import ROOT, cli_run, one_line


def _atrium(scale: float):
    """A stand-in for the atrium in the Dabrovic frame times ``scale``: a 35 x 16 courtyard floor
    at y = 0 and a 2 x 6 x 2 pillar on it (vertices, triangles), float64."""
    floor = [(-17.5, 0, -8), (17.5, 0, -8), (17.5, 0, 8), (-17.5, 0, 8)]
    lo, hi = np.array([-1.0, 0.0, -1.0]), np.array([1.0, 6.0, 1.0])
    box = [tuple(np.where([i & 1, i & 2, i & 4], hi, lo)) for i in range(8)]
    v = np.array(floor + box, np.float64) * scale
    quads = [(0, 3, 2, 1)] + [tuple(4 + c for c in q) for q in
                               [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]]
    f = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], np.int64)
    return v, f


def _write_ply(path, v, f):
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    faces = np.zeros(len(f), np.dtype([("n", "u1"), ("i", "<i4", (3,))]))
    faces["n"], faces["i"] = 3, f
    path.write_bytes(head.encode() + v.astype("<f4").tobytes() + faces.tobytes())
    return path


def _write_obj(path, v, f):
    path.write_text("".join(f"v {float(x)!r} {float(y)!r} {float(z)!r}\n" for x, y, z in v) + "".join(f"f {a+1} {b+1} {c+1}\n" for a, b, c in f))
    return path


def _config(scene: dict, **extra) -> dict:
    return {"experiment": {"name": "sponza"}, "camera": {"resolution": [64, 64], "position": [-9.0, 7.0, 4.0],
            "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0]}, "scene": [scene, *extra.get("more", [])],
            "light": [{"type": "directional", "direction": [0.3, -1.0, 0.2]}], "map": {"resolution": 128},
            "scheme": [{"name": "constant", "bias": "1 texel"}], "timing": {"repeats": 1}}


def test_a_copy_is_told_by_its_size_or_its_key(tmp_path):
    """35 units long is the Dabrovic model, 3,500 Crytek's remodel in centimetres (units 0.01), in
    PLY and OBJ alike; a size of neither is refused naming the version key, which also decides."""
    from dsm.core.types import ConfigError
    from dsm.scenes.models import SPONZA, version_of
    for ext, write in ((".ply", _write_ply), (".obj", _write_obj)):
        m = write(tmp_path / f"m{ext}", *_atrium(1.0))
        cm = write(tmp_path / f"cm{ext}", *_atrium(100.0))
        assert (version_of(SPONZA, m, None, "c.toml", "scene[0]").name, version_of(SPONZA, m, None, "c", "s").units) \
            == ("dabrovic", 1.0)
        assert (version_of(SPONZA, cm, None, "c", "s").name, version_of(SPONZA, cm, None, "c", "s").units) \
            == ("crytek", 0.01)
    tiny = _write_ply(tmp_path / "tiny.ply", *_atrium(0.1))
    with pytest.raises(ConfigError) as e:
        version_of(SPONZA, tiny, None, "c.toml", "scene[0]")
    assert e.value.key == "scene[0].version" and "3.5" in str(e.value) and "dabrovic" in str(e.value)
    assert version_of(SPONZA, tiny, "crytek", "c", "s").units == 0.01
    with pytest.raises(ConfigError, match=r"scene\[0\]\.version: unknown sponza version 'sibenik'"):
        version_of(SPONZA, tiny, "sibenik", "c", "scene[0]")


def test_the_key_wins_over_the_variable_and_a_relative_key_is_the_configs(tmp_path, monkeypatch):
    from dsm.config.read import parse
    m = _write_ply(tmp_path / "m.ply", *_atrium(1.0))
    monkeypatch.setenv("DSM_SPONZA", str(tmp_path / "elsewhere.ply"))
    cfg = parse(_config({"model": "sponza", "file": "m.ply"}), str(tmp_path / "c.toml"), tmp_path)
    (s,) = cfg.scenes
    assert (s.file, s.missing, s.model, s.units, s.label) == (m, "", "sponza", 1.0, "sponza_dabrovic")
    cfg = parse(_config({"model": "sponza"}), str(tmp_path / "c.toml"))
    assert cfg.scenes[0].file == tmp_path / "elsewhere.ply" and "elsewhere.ply is absent" in cfg.scenes[0].missing


@pytest.mark.slow
def test_crytek_centimetres_land_in_the_dabrovic_frame(tmp_path, monkeypatch, run_dict):
    """The same atrium in metres and in centimetres, with the same poses in metres: the same
    bounds (float64, within float32 rounding) and the same receivers and exact shadow."""
    monkeypatch.delenv("DSM_SPONZA", raising=False)
    m = _write_ply(tmp_path / "m.ply", *_atrium(1.0))
    cm = _write_obj(tmp_path / "cm.obj", *_atrium(100.0))
    from dsm.config.read import parse
    from dsm.scenes.load import load
    loaded = [load(parse(_config({"model": "sponza", "file": str(p), "ground": "no"}), "c").scenes[0], (64, 64))
              for p in (m, cm)]
    v, _ = _atrium(1.0)
    for sd in loaded:
        np.testing.assert_allclose(np.concatenate(sd.bbox), np.concatenate([v.min(0), v.max(0)]), atol=2e-6 * 35)
    rows = [run_dict(_config({"model": "sponza", "file": str(p), "ground": "no"}), name=p.stem).rows[0] for p in (m, cm)]
    assert rows[0]["scene"] == "sponza_dabrovic(ground=no)" and rows[1]["scene"] == "sponza_crytek(ground=no)"
    assert rows[0]["n_receivers"] > 2000 and rows[0]["n_gt_shadowed"] > 50        # the pillar's shadow is seen
    for k in ("n_receivers", "n_gt_shadowed"):
        assert abs(rows[0][k] - rows[1][k]) <= 0.002 * rows[0][k], (k, rows[0][k], rows[1][k])


def test_without_a_copy_one_line_says_the_key_the_variable_and_where(tmp_path, monkeypatch, capsys):
    """No file key and no DSM_SPONZA: the scene is skipped (the config's other scenes run); a
    config of nothing else exits 1 with one line naming the key, the variable and the archive."""
    monkeypatch.delenv("DSM_SPONZA", raising=False)
    import tomllib
    from dsm.config.read import check_runnable, parse
    both = parse(_config({"model": "sponza"}, more=[{"builtin": "plane"}]), "c.toml")
    check_runnable(both)                                    # the plane still runs
    assert [bool(s.missing) for s in both.scenes] == [True, False]
    for word in ("scene[0].model", "DSM_SPONZA", "https://casual-effects.com/data/", "data/meshes/README.md"):
        assert word in both.scenes[0].missing
    cfg = tmp_path / "only.toml"
    text = (ROOT / "experiments" / "dou_table1.toml").read_text()
    cfg.write_text(text)
    assert tomllib.loads(text)["scene"][0] == {"model": "sponza", "up": "y", "ground": "no"}
    rc, err = cli_run(capsys, "run", cfg, "--out", tmp_path / "o")
    assert rc == 1 and not (tmp_path / "o").exists()
    one_line(err, "nothing to run", "scene[0].model", "DSM_SPONZA", "casual-effects.com")


def test_a_model_takes_no_builtin_or_optional_and_only_a_mesh(tmp_path):
    from dsm.core.types import ConfigError
    from dsm.config.read import parse
    with pytest.raises(ConfigError, match=r"scene\[0\]\.model: unknown model 'sibenik' \(valid: sponza\)"):
        parse(_config({"model": "sibenik"}), "c")
    with pytest.raises(ConfigError, match=r"scene\[0\]\.optional"):
        parse(_config({"model": "sponza", "optional": True}), "c")
    xml = tmp_path / "s.xml"
    xml.write_text("<scene version='3.0.0'/>")
    with pytest.raises(ConfigError, match=r"scene\[0\]\.file: sponza's copy must be a mesh file"):
        parse(_config({"model": "sponza", "file": str(xml)}), "c")
    with pytest.raises(ConfigError, match=r"scene\[0\]\.version: a version is a named model's"):
        parse(_config({"builtin": "plane", "version": "crytek"}), "c")


def test_a_bad_version_or_a_folder_as_the_copy_is_a_config_error_with_or_without_a_copy(tmp_path, monkeypatch):
    """An unknown version is a config mistake whether or not a copy is given (it was hidden behind
    "no copy"); a folder given as the copy, by key or by DSM_SPONZA, is named as a folder, not absent."""
    from dsm.core.types import ConfigError
    from dsm.config.read import parse
    monkeypatch.delenv("DSM_SPONZA", raising=False)
    with pytest.raises(ConfigError, match=r"scene\[0\]\.version: unknown sponza version 'foo' \(valid: dabrovic, crytek\)"):
        parse(_config({"model": "sponza", "version": "foo"}), "c")
    with pytest.raises(ConfigError, match=r"scene\[0\]\.file: .* is a folder, not sponza's OBJ or PLY file"):
        parse(_config({"model": "sponza", "file": str(tmp_path)}), "c")
    monkeypatch.setenv("DSM_SPONZA", str(tmp_path))
    with pytest.raises(ConfigError, match=r"DSM_SPONZA: .* is a folder"):
        parse(_config({"model": "sponza"}), "c")
