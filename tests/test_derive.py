"""dsm run SCENE.xml: the experiment derived from a scene file (dsm.config.derive), rule by rule on
scenes written here, each with the answer known from the scene (or computed here in numpy float64)."""
import csv
import json
import math

import numpy as np
import pytest

import dsm

from dsm import cli
from dsm.config import derive, derived_files, scene_facts
from dsm.core import env

GROUND = '<shape type="rectangle" id="ground"><transform name="to_world"><scale value="{s}"/>{t}</transform></shape>'
PLATE = ('<shape type="rectangle" id="plate"><transform name="to_world"><scale x="0.8" y="0.6"/>'
         '<translate x="{x}" y="{y}" z="{z}"/></transform></shape>')
BOX = ('<shape type="cube" id="box"><transform name="to_world"><scale value="0.5"/>'
       '<translate x="{x}" y="{y}" z="{z}"/></transform></shape>')
SUN = '<emitter type="directional"><vector name="direction" x="0.5" y="0.3" z="-0.8"/></emitter>'
POINT = '<emitter type="point"><point name="position" x="0.5" y="-0.5" z="3"/></emitter>'
LUMINAIRE = ('<shape type="rectangle" id="lamp"><transform name="to_world"><scale value="0.5"/>'
             '<rotate x="1" angle="180"/><translate z="3"/></transform>'
             '<emitter type="area"><rgb name="radiance" value="5"/></emitter></shape>')


def sensor(origin, target, up="0, 0, 1", fov=45, w=48, h=36):
    """A perspective sensor at ``origin`` looking at ``target`` (strings "x, y, z"), fov degrees, w x h pixels."""
    return (f'<sensor type="perspective"><float name="fov" value="{fov}"/><transform name="to_world">'
            f'<lookat origin="{origin}" target="{target}" up="{up}"/></transform><film type="hdrfilm">'
            f'<integer name="width" value="{w}"/><integer name="height" value="{h}"/></film></sensor>')


def write(tmp_path, name, *elements):
    """A Mitsuba 3 scene file of ``elements`` in tmp_path."""
    path = tmp_path / f"{name}.xml"
    path.write_text('<scene version="3.0.0">' + "".join(elements) + "</scene>")
    return path


def derived(path):
    """(facts, derivation) of a scene file."""
    env.use_variant(None)
    facts = scene_facts.measure(path)
    return facts, derive.derive(facts)


def choice(d, rule):
    return next(c for c in d.choices if c.rule == rule)


def scheme_names(d):
    return {t.get("name") for t in d.tables["scheme"]} - {None}


def small_scene(tmp_path, name, emitter, *shapes, offset=(0.0, 0.0, 0.0)):
    """The 8 x 8 ground and ``shapes`` seen from above and aside, moved by ``offset``."""
    ox, oy, oz = offset
    t = f'<translate x="{ox}" y="{oy}" z="{oz}"/>' if any(offset) else ""
    cam = sensor(f"{4 + ox}, {-6 + oy}, {5 + oz}", f"{ox}, {oy}, {0.3 + oz}")
    return write(tmp_path, name, cam, emitter, GROUND.format(s=4, t=t), *shapes)


def test_point_light_and_open_meshes_get_both_point_views_no_culling_and_shrinking(tmp_path):
    path = small_scene(tmp_path, "open", POINT, PLATE.format(x=0.3, y=-0.2, z=0.6))
    facts, d = derived(path)
    assert set(d.tables["map"]["view"]) == {"cube", "dual_paraboloid"}
    assert {v.kind for v in facts.views} == {"cube", "dual_paraboloid"}
    assert not scheme_names(d) & set(derive.TWO_LAYER)
    assert choice(d, "culling").choice == "no culling or two-layer scheme"
    assert d.offered and d.offered[0][1].startswith("shrink = ")
    assert "# shrink = " in derived_files.toml_text(d)          # offered, commented out


def test_a_closed_box_brings_the_culling_and_two_layer_schemes(tmp_path):
    path = small_scene(tmp_path, "closed", POINT, PLATE.format(x=0.3, y=-0.2, z=0.6), BOX.format(x=-1, y=0.5, z=0.5))
    facts, d = derived(path)
    assert facts.closed == ("box",)
    assert set(derive.TWO_LAYER) <= scheme_names(d)
    assert "box" in choice(d, "culling").reason
    cfg = derived_files.config_of(d, tmp_path)                  # a valid config: culling instances planned
    assert {s.params.culling for s in cfg.schemes if s.name == "dual"} == {"back_closed"}


def ground_view(tmp_path, name, origin, target, fov, up="0, 0, 1"):
    """A sun over a 2 km ground (1 km half side) seen from ``origin``."""
    return write(tmp_path, name, sensor(origin, target, up, fov, 64, 48), SUN, GROUND.format(s=1000, t=""))


def test_a_sun_over_a_2_km_ground_seen_from_1_7_m_gets_cascades(tmp_path):
    facts, d = derived(ground_view(tmp_path, "eye", "0, 0, 1.7", "0, 40, 0", 60))
    ratio = derive.footprint_ratio(facts.views[0].footprint_texels)
    assert ratio > derive.CASCADE_RATIO
    assert d.tables["map"]["cascades"] == derive.CASCADES


def test_the_same_ground_from_100_m_above_with_a_narrow_view_is_one_map(tmp_path):
    facts, d = derived(ground_view(tmp_path, "above", "0, 0, 100", "0, 0, 0", 10, up="0, 1, 0"))
    # straight down through a 10 degree view: the pixel widths differ by cos^-1.5 of 5 degrees at most
    assert derive.footprint_ratio(facts.views[0].footprint_texels) < 1.02
    assert "cascades" not in d.tables["map"]
    assert choice(d, "cascades").choice == "one map"


def test_the_precision_axis_appears_far_from_the_origin_only(tmp_path):
    box = BOX.format(x=-1, y=0.5, z=0.5)
    _, near = derived(small_scene(tmp_path, "origin", SUN, box))
    far_box = BOX.format(x=1e6 - 1, y=1e6 + 0.5, z=0.5)
    facts, far = derived(small_scene(tmp_path, "far", SUN, far_box, offset=(1e6, 1e6, 0.0)))
    assert "precision" not in near.tables["scene"][0]
    assert far.tables["scene"][0]["precision"] == ["world", "camera_relative"]
    # float32's step at 1e6 is 2^-4: the median texel spans fewer than 64 of them
    assert far.measured["f32_step"] == 0.0625
    assert far.measured["texel_world_finest"] / 0.0625 < 64
    cfg = derived_files.config_of(far, tmp_path)                # an XML scene takes the precision axis
    assert [s.params.precision for s in cfg.scenes] == ["world", "camera_relative"]


def test_an_area_emitter_brings_the_reference_and_pcss_and_none_without(tmp_path):
    lit = write(tmp_path, "lamp", sensor("4, -6, 5", "0, 0, 0.3"), LUMINAIRE, GROUND.format(s=4, t=""),
                PLATE.format(x=0, y=0, z=1))
    facts, d = derived(lit)
    assert len(facts.area_lights) == 1
    assert d.tables["light"] == [{"type": "area", "shape": "emitter"}]     # no default point light beside it
    assert d.tables["map"]["filter"] == ["nearest", "pcss"]
    _, hard = derived(small_scene(tmp_path, "hard", SUN))
    assert all(t.get("type") != "area" for t in hard.tables["light"])
    assert "filter" not in hard.tables["map"]
    assert choice(hard, "soft shadows").choice.startswith("none")


def test_the_resolution_rule_on_a_plane_matches_the_footprint_computed_here(tmp_path):
    h, fov, w, ht = 10.0, 60.0, 64, 48
    facts, d = derived(write(tmp_path, "plane", sensor(f"0, 0, {h}", "0, 0, 0", "0, 1, 0", fov, w, ht),
                             '<emitter type="directional"><vector name="direction" x="0" y="0" z="-1"/></emitter>',
                             GROUND.format(s=100, t="")))
    # every pixel sees the plane z = 0; the sun's map is fitted to the hit points, 4 texels spare a side
    tx = math.tan(math.radians(fov) / 2)
    ty = tx * ht / w
    x = ((np.arange(w) + 0.5) / w * 2 - 1) * tx * h
    y = ((np.arange(ht) + 0.5) / ht * 2 - 1) * ty * h
    px, py = np.meshgrid(x, y)
    dist = np.sqrt(px ** 2 + py ** 2 + h ** 2)
    pixel = (2 * tx / w) * (h / dist) ** 1.5 * dist
    r0 = scene_facts.MEASURE_R
    texel = (x.max() - x.min()) * r0 / (r0 - 8) / r0
    exact = r0 / np.median(pixel / texel)
    assert d.measured["lights"][0]["resolution_exact"] == pytest.approx(exact, rel=1e-4)
    r = 2 ** round(math.log2(exact))
    assert d.tables["map"]["resolution"] == [r // 2, r, 2 * r]


def test_rules_on_known_quantities():
    assert derive.footprint_ratio(np.array([0.5, 1.0, 4.0])) == 8.0
    assert math.isnan(derive.footprint_ratio(np.zeros(0)))
    per_light, _ = derive.resolution_rule({"sun": 4.0})   # 4 texels a pixel at 1024: one at 256
    assert per_light == {"sun": (256.0, 256)} and derive.resolutions(per_light) == (128, 256, 512)
    per_light, _ = derive.resolution_rule({"sun": 1024 / 700})   # 700 rounds to 512 (log2 9.45)
    assert per_light["sun"][1] == 512
    # two lights: each its own bracket, swept together
    per_light, c = derive.resolution_rule({"sun": 1.0, "lamp": 16.0})
    assert derive.resolutions(per_light) == (32, 64, 128, 512, 1024, 2048)
    assert "sun: one texel per pixel at 1024, so 1024" in c.reason and "lamp: one texel per pixel at 64" in c.reason
    assert derive.resolutions({}) == (256, 512, 1024) and derive.power_of_two(math.nan)[1] == derive.DEFAULT_R
    assert derive.precision_rule(1e6, 1.0)[0] == ("world", "camera_relative")      # 16 steps a texel
    assert derive.precision_rule(1e6, 4.0)[0] == ("world",)                        # 64 steps: not fewer
    assert derive.unorm_steps(1.0, 65536.0)["unorm16"] == 1.0


def test_dsm_plan_explain_prints_the_measured_quantities_and_runs_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = small_scene(tmp_path, "explain", SUN, BOX.format(x=-1, y=0.5, z=0.5))
    assert cli.main(["plan", str(path), "--explain"]) == 0
    out = capsys.readouterr().out
    assert "footprint (texels per pixel) median" in out and "closed meshes: box" in out
    assert "derived resolution:" in out and "cases:" not in out     # no plan, no case
    assert not (tmp_path / "runs").exists()
    assert cli.main(["plan", str(path)]) == 0 and "cases:" in capsys.readouterr().out


MACHINE = (("_ms", "_mb"), "compiled")     # timing, peak memory and kernel-cache columns: the machine's


@pytest.mark.slow
def test_derived_toml_run_again_gives_the_derived_runs_results(tmp_path, capsys):
    path = small_scene(tmp_path, "tiny", SUN, BOX.format(x=-1, y=0.5, z=0.5))
    path.write_text(path.read_text().replace('value="48"', 'value="24"').replace('value="36"', 'value="18"'))
    first, again = tmp_path / "first", tmp_path / "again"
    assert cli.main(["run", str(path), "--out", str(first)]) == 0
    assert "dsm: derived cascades: one map" in capsys.readouterr().out
    assert cli.main(["run", str(first / "derived.toml"), "--out", str(again)]) == 0
    a, b = (list(csv.DictReader(open(p / "metrics.csv"))) for p in (first, again))
    assert len(a) == len(b) > 0
    for x, y in zip(a, b):
        assert {k: v for k, v in x.items() if not k.endswith(MACHINE[0]) and MACHINE[1] not in k} == \
               {k: v for k, v in y.items() if not k.endswith(MACHINE[0]) and MACHINE[1] not in k}
    record = json.loads((first / "derivation.json").read_text())
    assert [c["rule"] for c in record["choices"]][:2] == ["lights", "views"]
    page = (first / "report.html").read_text()
    assert 0 < page.index("id=derived") < page.index("id=costs")      # the reasons before the answer
    assert "## Derived from" in (first / "table.md").read_text()
    assert "id=derived" not in (again / "report.html").read_text()    # a config file's run derived nothing
    api = dsm.run(path, out=tmp_path / "api", report=False)               # the Python API derives as dsm run does
    assert (tmp_path / "api" / "derived.toml").read_text() == (first / "derived.toml").read_text()
    c = list(csv.DictReader(open(tmp_path / "api" / "metrics.csv")))
    assert [x["case"] for x in c] == [x["case"] for x in a] and len(api.rows) == len(a)
    assert [x["n_acne"] for x in c] == [x["n_acne"] for x in a]


def test_an_xml_scene_at_1e6_rendered_camera_relative_keeps_the_origins_float32_headroom(tmp_path):
    """[[scene]] precision on an XML scene (the axis the precision rule derives): the exact side is the
    origin's (receivers, exact shadow); world precision leaves a texel fewer than 64 float32 steps at
    1e6, camera_relative as many as at the origin."""
    from dsm import run
    box = BOX.format(x=-1, y=0.5, z=0.5)
    origin = small_scene(tmp_path, "origin", SUN, box)
    far = small_scene(tmp_path, "far", SUN, BOX.format(x=1e6 - 1, y=1e6 + 0.5, z=0.5), offset=(1e6, 1e6, 0.0))
    base = {"map": {"resolution": 128}, "scheme": [{"name": "constant", "bias": "1 texel"}],
            "timing": {"repeats": 1}, "report": {"images": "none"}}
    rows = []
    for scene in ({"file": str(origin)}, {"file": str(far), "precision": ["world", "camera_relative"]}):
        rows += run({**base, "scene": [scene]}, out=tmp_path / ("run_" + scene["file"].split("/")[-1])).rows
    at0, world, relative = rows
    for r in (world, relative):
        assert (r["n_receivers"], r["n_gt_shadowed"]) == (at0["n_receivers"], at0["n_gt_shadowed"])
    assert world["f32_step"] == 0.0625 and world["texel_f32_steps"] < 64
    assert relative["texel_f32_steps"] >= 64 and at0["texel_f32_steps"] >= 64


def facts_of(views=(), closed=(), open_=(), analytic=(), thinnest=math.inf):
    """SceneFacts made here (the rules are functions of them alone)."""
    return scene_facts.SceneFacts(path=None, film=(4, 3), delta_lights=(), area_lights=(), default_light="",
                                  closed=closed, open=open_, analytic=analytic, thinnest_closed=thinnest,
                                  max_abs_coordinate=1.0, diagonal=1.0, views=views)


def view_of(texel_world, near, far, kind="orthographic"):
    n = len(texel_world)
    return scene_facts.ViewFacts("0:sun", "directional", kind, np.ones(n), np.asarray(texel_world, float), near, far)


def test_the_formats_rule_offers_a_unorm_format_where_its_step_passes_a_texel():
    # at MEASURE_R the texel is 2 world units, so 1 at twice it: unorm16's step over 0..131070 is 2
    r = {"0:sun": 2 * scene_facts.MEASURE_R}
    assert derive.formats_rule(facts_of((view_of([2.0], 0.0, 2.0 * 65535),)), r)[0] == ("float32", "unorm16")
    assert derive.formats_rule(facts_of((view_of([2.0], 0.0, 0.5 * 65535),)), r)[0] == ("float32",)
    # unorm24 as well only where its step (range / (2^24 - 1)) passes the texel too
    assert derive.formats_rule(facts_of((view_of([2.0], 0.0, 2.0 * (2 ** 24 - 1)),)), r)[0] == \
        ("float32", "unorm16", "unorm24")


def test_the_shrink_rule_offers_half_a_texel_below_a_quarter_of_the_thinnest_solid():
    v = (view_of([1.0], 0.0, 1.0),)
    assert derive.shrink_rule(facts_of(v, open_=(("plate", "4 boundary edges"),)), 0.5)[0] == 0.25
    assert derive.shrink_rule(facts_of(v, closed=("box",), open_=(("plate", "open"),), thinnest=0.4), 0.5)[0] == 0.1
    assert derive.shrink_rule(facts_of(v, closed=("box",)), 0.5)[0] == 0.0                  # nothing open
    assert derive.shrink_rule(facts_of(v, open_=(("s", "analytic"),), analytic=("s",)), 0.5)[0] == 0.0


def test_the_schemes_rule_takes_every_family_and_preset_once():
    from dsm import schemes
    from dsm.schemes import presets
    v = (view_of([1.0], 0.0, 1.0),)
    tables, _ = derive.schemes_rule(facts_of(v), two_layer=False)
    names = [t["name"] for t in tables if "name" in t]
    assert names == [m.NAME for m in schemes.REGISTRY if m.NAME not in ("combined",) + derive.TWO_LAYER]
    assert [t["preset"] for t in tables if "preset" in t] == presets.names()
    tables, _ = derive.schemes_rule(facts_of(v), two_layer=True)
    assert set(derive.TWO_LAYER) <= {t.get("name") for t in tables}


def test_a_scene_file_that_cannot_be_derived_from_is_one_line(tmp_path, capsys):
    assert cli.main(["run", str(tmp_path / "absent.xml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "absent.xml" in err[0] and "scene.file" in err[0]
    ortho = write(tmp_path, "ortho", '<sensor type="orthographic"><film type="hdrfilm"><integer name="width" '
                  'value="8"/><integer name="height" value="8"/></film></sensor>', SUN, GROUND.format(s=4, t=""))
    assert cli.main(["plan", str(ortho)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "perspective" in err[0]
    assert not (tmp_path / "o").exists()


def test_a_spot_light_is_one_perspective_view_and_writes_no_map_view(tmp_path):
    spot = ('<emitter type="spot"><float name="cutoff_angle" value="40"/><transform name="to_world">'
            '<lookat origin="1, -1, 4" target="0, 0, 0"/></transform></emitter>')
    facts, d = derived(small_scene(tmp_path, "spot", spot, BOX.format(x=-1, y=0.5, z=0.5)))
    assert [(v.light_type, v.kind) for v in facts.views] == [("spot", "perspective")]
    assert "view" not in d.tables["map"] and d.tables["light"] == [{"type": "scene"}]


def test_a_light_no_pixel_faces_derives_the_defaults_and_says_so(tmp_path):
    below = '<emitter type="directional"><vector name="direction" x="0" y="0" z="1"/></emitter>'
    facts, d = derived(small_scene(tmp_path, "below", below))
    assert len(facts.views[0].footprint_texels) == 0
    assert d.tables["map"]["resolution"] == [derive.DEFAULT_R // 2, derive.DEFAULT_R, 2 * derive.DEFAULT_R]
    assert choice(d, "resolution").reason.startswith("0:directional: no receiver seen")
    assert d.measured["views"][0]["footprint_median"] is None                # undefined, not 0
    json.dumps(derived_files.record(d), allow_nan=False)                      # valid JSON: no NaN
