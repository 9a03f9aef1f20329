"""A sweep's small maps built together (dsm.maps.stacked, ``[timing] builds = "together"``): every
texel the same bits, rays and counts as its map built alone (the second computation), one launch
for a first-layer stack, and a run's rows equal to the one that builds every map alone."""
import math

import numpy as np
import pytest

from conftest import base_config

LIGHTS = [{"type": "scene"}, {"type": "spot", "position": [-2.0, 2.5, 2.6], "target": [0.0, 0.0, 0.0], "cutoff": 40},
          {"type": "point", "position": [0.6, -0.8, 2.2]}]
SIZES = (8, 13, 24)      # 13: lanes past the end of a CPU packet (where a per-lane divisor gathers 0)


@pytest.fixture(scope="module")
def room():
    """plane_box loaded with a directional, spot and point light: (scene, lights, spawn extents, closedness)."""
    from dsm import pipeline
    from dsm.config import read as config
    from dsm.scenes import load as scenes
    c = config.parse(base_config(scene=[{"builtin": "plane_box"}], light=LIGHTS,
                                 map={"resolution": 16, "view": ["paraboloid", "dual_paraboloid", "cube"]}), "<test>")
    sd = scenes.load(c.scenes[0], c.camera_resolution)
    return sd, sd.lights_for(c.lights), pipeline.spawn_extents(sd.scene), pipeline.closedness(sd)[0]


def _views(light, kind, sd):
    from dsm import pipeline
    pts = np.array([[-0.5, -0.5, 0.0], [0.5, 0.6, 0.3]])
    return [pipeline.make_view(light, R, pts, sd.bbox, kind) for R in SIZES]


def _bits(a):
    return None if a is None else np.asarray(a.numpy()).view(np.uint32)


@pytest.mark.parametrize("culling", ["none", "back_closed"])
def test_stacked_maps_are_the_bits_of_each_map_alone(room, culling):
    """Every view kind, with and without culling, first layer alone and with slope and second
    layer: z1, shape, slope and z2 bit for bit, rays by kind, re-hits and unfinished texels."""
    from dsm import pipeline
    from dsm.maps import shadowmap, stacked
    sd, lights, ext, closed = room
    kinds = {"directional": [None], "spot": [None], "point": ["paraboloid", "dual_paraboloid", "cube"]}
    seen = set()
    for light in lights:
        for kind in kinds[light.type]:
            views = _views(light, kind, sd)
            modes = pipeline.map_cull_modes(sd.scene, views[0], culling, closed if culling != "none" else None)
            for needs in (set(), {"slope", "z2"}):
                together = stacked.build_together(sd.scene, views, needs, culling, modes, ext)
                for v, t in zip(views, together):
                    a = shadowmap.build(sd.scene, v, needs, culling, modes, extents=ext)
                    for k in ("z1", "shape", "slope", "z2"):
                        assert np.array_equal(_bits(getattr(a, k)), _bits(getattr(t, k))), (v.kind, needs, k)
                    assert (a.rays, a.rehits, a.unfinished) == (t.rays, t.rehits, t.unfinished)
                    assert t.shared == len(SIZES)
                seen.add(views[0].kind)
                if needs:
                    assert sum(t.rays["map_continue"] for t in together) > 0
    assert seen == {"orthographic", "perspective", "paraboloid", "dual_paraboloid", "cube"}


def test_a_first_layer_stack_is_one_launch(room):
    """Three maps' first layers: three kernels built alone, one built together (Dr.Jit's kernel history)."""
    import drjit as dr
    from dsm.maps import shadowmap, stacked
    from dsm.core import timing
    sd, lights, ext, _ = room
    views = _views(lights[0], None, sd)
    timing.enable_history()

    def launches(fn):
        """JIT kernels launched evaluating fn()'s arrays."""
        dr.sync_thread()
        dr.kernel_history_clear()
        dr.eval(*fn())
        dr.sync_thread()
        return sum(1 for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT)
    alone = launches(lambda: [a for v in views for a in shadowmap.arrays(shadowmap.build(sd.scene, v, set()))])
    lane = stacked.stack_view(views)
    together = launches(lambda: list(stacked.build_arrays(sd.scene, lane, set()).values()))
    assert (alone, together) == (3, 1)


def _config(builds: str):
    return base_config(scene=[{"builtin": "l_shape"}], light=LIGHTS, camera={"resolution": [48, 48]},
                       map={"resolution": [32, 64, 128], "view": ["dual_paraboloid"]},
                       scheme=[{"name": "constant"}, {"name": "dual", "culling": ["none", "back_closed"]},
                               {"name": "second_depth"}],
                       timing={"repeats": 2, "builds": builds})


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    """_config run with builds = "alone" and "together": {mode: Results}."""
    import dsm
    out = tmp_path_factory.mktemp("stack")
    return {mode: dsm.run(_config(mode), out=out / mode, report=False) for mode in ("alone", "together")}


def _method(rows):
    machine = ("_ms", "_mb", "kernels_compiled", "_shared")
    return [{k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()
             if not any(m in k for m in machine)} for r in rows]


@pytest.mark.slow
def test_together_rows_equal_every_map_built_alone(both):
    """Every count and rate of every case, the rays and each map's layers and re-hits equal the run
    that builds each map alone; one stack per light and culling (none, back_closed, front_closed)."""
    a, b = both["alone"], both["together"]
    assert _method(a.rows) == _method(b.rows) and len(a.rows) == 3 * 3 * 4
    assert a.run["rays"] == b.run["rays"]
    keep = ("resolution", "culling", "layers", "rays", "rehits")
    assert [{k: m[k] for k in keep} for m in a.run["maps"]] == [{k: m[k] for k in keep} for m in b.run["maps"]]
    assert {r["build_shared"] for r in a.rows} == {1} and {r["build_shared"] for r in b.rows} == {3}
    assert len(b.run["plan"]["stacks"]) == 3 * 3 and a.run["plan"]["stacks"] == []


@pytest.mark.slow
def test_a_stacked_map_gets_its_share_of_texels(both):
    """A stack's time is attributed by texels: within a stack (a light, culling and scheme), the
    maps' build_ms are in the ratio of their texel counts, R^2."""
    rows = [r for r in both["together"].rows if r["filter"] == "nearest"]
    groups = {}
    for r in rows:
        groups.setdefault((r["light"], r["culling"], r["scheme"]), {})[r["resolution"]] = r
    for key, by_r in groups.items():
        assert sorted(by_r) == [32, 64, 128]
        for R in (64, 128):
            for col in ("build_ms", "build_compile_ms"):
                assert by_r[R][col] == pytest.approx(by_r[32][col] * (R / 32) ** 2, rel=1e-9), (key, col)
        assert by_r[128]["build_ms"] > 0


def test_a_stacked_maps_first_layer_is_its_share_whatever_the_order(both):
    """build_first_ms of a stacked map is its share of its stack's first layer without culling, also
    where the view group's first map is a culled one (second_depth's front_closed and dual's
    back_closed maps are planned beside the culling-none map): constant, which needs no layer but
    the first, has build_ms == build_first_ms on the culling-none maps (one measurement), and every
    case of a map has the build_first_ms of that map's own stack."""
    rows = both["together"].rows
    for r in rows:
        if r["scheme"] == "constant":
            assert r["build_ms"] == r["build_first_ms"], r
    by_map = {}
    for r in rows:
        by_map.setdefault((r["light"], r["culling"], r["resolution"]), set()).add(r["build_first_ms"])
    assert all(len(v) == 1 for v in by_map.values())
    for light in {r["light"] for r in rows}:
        for culling in ("none", "back_closed", "front_closed"):
            first = {R: by_map[(light, culling, R)].pop() for R in (32, 64, 128)}
            assert first[128] == pytest.approx(first[32] * 16, rel=1e-9) and first[64] == pytest.approx(first[32] * 4)


def test_every_stack_layout_runs_one_compiled_kernel(room):
    """The per-lane values come from host arrays, not literals: stacks of other resolutions (and
    counts of maps) launch the same kernel (its hash in Dr.Jit's kernel history), compiled once."""
    import drjit as dr
    from dsm.maps import stacked
    from dsm.core import timing
    sd, lights, _, _ = room
    timing.enable_history()
    hashes = set()
    for sizes in ((8, 13, 24), (8, 16, 24), (9, 13), (24, 8, 13)):
        from dsm import pipeline
        pts = np.array([[-0.5, -0.5, 0.0], [0.5, 0.6, 0.3]])
        lane = stacked.stack_view([pipeline.make_view(lights[0], R, pts, sd.bbox) for R in sizes])
        dr.sync_thread()
        dr.kernel_history_clear()
        dr.eval(*stacked.build_arrays(sd.scene, lane, {"slope"}).values())
        dr.sync_thread()
        hashes |= {k["hash"] for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT}
    assert len(hashes) == 1


def test_what_the_plan_stacks():
    """Stacks hold one light, view kind and culling with the same layers; their estimated peaks fit
    the memory budget beyond the camera's buffers (a small budget splits them as it tiles a map);
    a cluster run stacks nothing (a Ray task runs one map); a case's key tells the modes apart."""
    from dsm import pipeline
    from dsm.config import plan as planmod
    from dsm.experiment import resume
    cfg = base_config(scene=[{"builtin": "plane_box"}], light=LIGHTS, camera={"resolution": [48, 48]},
                      map={"resolution": [32, 64, 128, 256], "view": ["cube"]}, scheme=[{"name": "midpoint"}],
                      timing={"repeats": 1, "builds": "together"})
    plan = planmod.make(pipeline.prepare(cfg))
    assert [[m.resolution for m in st] for st in plan.stacks] == [[32, 64, 128, 256]] * 3
    for st in plan.stacks:
        assert len({(m.scene, m.light, m.view, m.culling, m.needs) for m in st}) == 1
    small = planmod.make(pipeline.prepare({**cfg, "memory": {"budget_mb": 4}}))
    base = 48 * 48 * planmod.PIXEL_BYTES
    assert small.stacks and all(sum(m.peak_bytes for m in st) <= small.budget_bytes - base for st in small.stacks)
    assert sum(len(st) for st in small.stacks) < sum(len(st) for st in plan.stacks)
    ray = pipeline.prepare({**cfg, "execution": {"backend": "ray"}})
    assert planmod.make(ray).stacks == []
    alone = pipeline.prepare({**cfg, "timing": {"repeats": 1}})
    keys = lambda c: [k for _, k in resume.case_keys(c, planmod.make(c), "v")]
    assert set(keys(pipeline.prepare(cfg))).isdisjoint(keys(alone))


def test_builds_choice_is_checked(tmp_path):
    """A [timing] builds value outside the choices is one line naming the file, the key and the choices."""
    from dsm.config import read as config
    from dsm.core.types import ConfigError
    with pytest.raises(ConfigError) as e:
        config.parse({**base_config(), "timing": {"builds": "sometimes"}}, "exp.toml")
    msg = str(e.value)
    assert "exp.toml" in msg and "timing.builds" in msg and "together" in msg and "\n" not in msg


@pytest.mark.slow
def test_bench_compares_the_build_modes(tmp_path, monkeypatch):
    """dsm perf (5c): a light's resolution sweep built together launches fewer timed kernels than
    each map alone (a count, not a clock: alone, one first-layer build per map and repeat), every
    row equal."""
    from dsm.perf import bench_modes
    small = {**bench_modes.BUILD_SWEEP, "scene": [{"builtin": "plane_box"}], "camera": {"resolution": [32, 32]},
             "light": [{"type": "scene"}], "map": {"resolution": [16, 32, 64]},
             "scheme": [{"name": "constant"}], "timing": {"repeats": 2}}
    monkeypatch.setattr(bench_modes, "BUILD_SWEEP", small)
    r = bench_modes.build_modes(tmp_path)
    assert r["rows_equal"] and r["cases"] == 3
    assert (r["alone"]["stacked_maps"], r["together"]["stacked_maps"]) == (0, 3)
    # the builds' timed kernels: 3 maps x 2 repeats alone, one stack x 2 repeats together
    assert r["alone"]["launches"]["timed_repeats"] - r["together"]["launches"]["timed_repeats"] == 3 * 2 - 2
    assert "(5c)" in "\n".join(bench_modes.markdown_builds(r))
