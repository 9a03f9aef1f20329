"""A map's lookup wavefront (dsm.experiment.wavefront): its cases' results are those of their own
lookups, the cases that share a timed kernel are the ones Dr.Jit compiles to one kernel, and a
map cut into several waves gives the same rows."""
import math

import pytest

from conftest import base_config

# machine columns and the mode's own column: everything else must be equal between the modes
MACHINE = ("_ms", "_mb", "kernels_compiled", "lookup_shared")

SCHEMES = [{"name": "constant", "bias": ["1 texel", "3 texel", 0.05]}, {"name": "receiver_plane"},
           {"name": "normal_offset", "offset": ["0.5 texel", "1.5 texel"]}, {"name": "dual", "culling": ["none", "back_closed"]},
           {"name": "midpoint"}]


def _config(lookups: str, **over):
    return base_config(scene=[{"builtin": "l_shape"}], camera={"resolution": [64, 64]},
                       map={"resolution": [64, 128], "filter": ["nearest", "pcf_bilinear", "pcss"],
                            "format": ["float32", "unorm16"]},
                       scheme=SCHEMES, timing={"repeats": 2, "lookups": lookups}, **over)


def _method(rows):
    return [{k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()
             if not any(m in k for m in MACHINE)} for r in rows]


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    import dsm
    out = tmp_path_factory.mktemp("wave")
    return {mode: dsm.run(_config(mode), out=out / mode, report=False) for mode in ("per_case", "wavefront")}


@pytest.mark.slow
def test_wavefront_rows_equal_each_case_timing_its_own_lookup(both):
    """Every count, rate and image-free column of every case equals the per-case path's, where each
    case looks up alone (the second computation)."""
    a, b = both["per_case"].rows, both["wavefront"].rows
    assert len(a) == len(b) == 2 * 3 * 2 * (3 + 1 + 2 + 2 + 1)
    assert _method(a) == _method(b)
    assert sum(r["n_acne"] + r["n_peterpan"] for r in b) > 0


@pytest.mark.slow
def test_cases_share_a_timing_only_within_one_kernel(both):
    """lookup_shared counts the cases of a map whose scheme, parameter units, filter and format
    match: the two texel biases share, the world bias does not; per_case rows stand for themselves."""
    rows = both["wavefront"].rows
    for r in rows:
        if r["scheme"] == "constant":
            assert r["lookup_shared"] == (1 if r["params"] == "bias=0.05" else 2), r["params"]
        elif r["scheme"] == "normal_offset":
            assert r["lookup_shared"] == 2
        else:
            assert r["lookup_shared"] == 1
    assert {r["lookup_shared"] for r in both["per_case"].rows} == {1}
    maps = both["wavefront"].run["maps"]
    assert [(m["resolution"], m["culling"], m["waves"], m["wave_cases"]) for m in maps] == [
        (64, "none", 1, 48), (64, "back_closed", 1, 6), (128, "none", 1, 48), (128, "back_closed", 1, 6)]
    assert all(m["lookup_wave_ms"] > 0 for m in maps)


def _kernel_hashes(spec_table, rx, smap):
    """Dr.Jit's hashes of the kernels that one case's lookup launches (its history: an outside witness)."""
    import drjit as dr
    import dsm.pipeline as pl
    spec = pl.scheme_specs(spec_table)[0]
    dr.kernel_history_clear()
    v, tap = pl.visibility(spec, rx, smap, "nearest", 7)
    dr.eval(v, tap)
    return [k["hash"] for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT]


def test_kernel_key_matches_what_drjit_compiles():
    """Two values of a texel bias run one compiled kernel (the same hash in Dr.Jit's history), as
    kernel_key says; a world bias of the same scheme is another kernel and another key."""
    import drjit as dr
    import dsm.pipeline as pl
    from dsm.experiment.wavefront import kernel_key
    sd = pl.load_scene(pl.scene_spec({"builtin": "plane_box"}), (48, 48))
    gb = pl.gbuffer(sd)
    setup = pl.light_setup(sd, gb, sd.own_lights[0], "0:directional")
    view = pl.make_view(setup.light, 64, pl.points_np(setup.p), sd.bbox)
    setup = setup.subset(view.inside(setup.p).numpy().astype(bool))
    smap = pl.store(pl.build_map(sd.scene, view), "float32")
    rx = pl.receivers(smap.view, setup, sd.diagonal)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    tables = [{"name": "constant", "bias": "1 texel"}, {"name": "constant", "bias": "4 texel"},
              {"name": "constant", "bias": 0.05}]
    _kernel_hashes(tables[0], rx, smap)          # the receivers' own pending work evaluated first
    hashes = [_kernel_hashes(t, rx, smap) for t in tables]
    assert len(hashes[0]) == 1
    keys = [kernel_key(pl.scheme_specs(t)[0], "nearest", "float32") for t in tables]
    assert hashes[0] == hashes[1] and keys[0] == keys[1]
    assert hashes[0] != hashes[2] and keys[0] != keys[2]


@pytest.mark.slow
def test_a_map_cut_into_waves_gives_the_same_rows(both, tmp_path, monkeypatch):
    """With room for one case a wave, each of a map's 48 cases runs in its own wave, and every row
    is the same as in one wave."""
    import dsm
    from dsm.config import plan
    monkeypatch.setattr(plan, "WAVE_BYTES", 1)
    cfg = _config("wavefront")
    cfg["map"]["resolution"] = [64]
    res = dsm.run(cfg, out=tmp_path / "w", report=False)
    first = [m for m in res.run["maps"] if m["culling"] == "none"]
    assert [(m["wave_cases"], m["waves"]) for m in first] == [(48, 48)]
    strip = lambda rows: [{k: v for k, v in r.items() if k != "case"} for r in _method(rows)]
    assert strip(res.rows) == strip([r for r in both["wavefront"].rows if r["resolution"] == 64])


def test_wave_cases_fit_the_budget():
    """wave_cases: as many cases as fit WAVE_BYTES (at least one), by the outputs' bytes per case."""
    from dsm.config import plan
    per = 1000 * plan.WAVE_RECEIVER_BYTES + 200 * plan.WAVE_BACK_BYTES
    assert plan.wave_cases(1000, 200) == plan.WAVE_BYTES // per
    assert plan.wave_cases(plan.WAVE_BYTES, 0) == 1
    assert plan.wave_cases(0, 0) >= 1 << 20


def test_an_unknown_lookup_mode_is_refused_before_any_work(tmp_path):
    import dsm
    from dsm.core.types import ConfigError
    with pytest.raises(ConfigError) as e:
        dsm.run(_config("fused"), out=tmp_path / "x", report=False)
    msg = str(e.value)
    assert "timing.lookups" in msg and "wavefront" in msg and "per_case" in msg
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
def test_bench_compares_the_modes_on_a_sweep(tmp_path, monkeypatch):
    """dsm perf (5b): on a sweep whose cases share kernels, the wavefront launches fewer timed
    kernels than one lookup per case (a count, not a clock), and every row is equal."""
    from dsm.perf import bench_modes
    small = {**bench_modes.LOOKUP_SWEEP, "camera": {"resolution": [48, 48]},
             "map": {"resolution": [64], "filter": ["nearest"]}, "timing": {"repeats": 2}}
    monkeypatch.setattr(bench_modes, "LOOKUP_SWEEP", small)
    r = bench_modes.lookup_modes(tmp_path)
    assert r["rows_equal"] and r["cases"] == 2 * (8 + 4 + 6)      # two scenes
    # per case: 36 cases x 2 repeats; wavefront: per map 3 kernels (constant, normal_offset, slope_scaled) x 2,
    # plus the wave's
    assert r["per_case"]["launches"]["timed_repeats"] >= 36 * 2
    assert r["wavefront"]["launches"]["timed_repeats"] < r["per_case"]["launches"]["timed_repeats"] / 2
    assert "(5b)" in "\n".join(bench_modes.markdown(r))
