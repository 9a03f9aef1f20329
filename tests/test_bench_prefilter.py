"""``dsm perf`` (8), pre-filtered maps beside PCF (dsm.perf.bench_prefilter): its rows, the maps
it times (the run's own, bit for bit), and its section of bench.md."""
import math

import numpy as np


def test_the_table_has_one_row_per_resolution_kind_and_width_and_pcf_shared_per_width():
    from dsm.perf import bench_prefilter as bp
    kinds, widths, res = ("vsm", "msm"), (1, 3), (32, 48)
    p = bp.prefilter_cost(resolutions=res, widths=widths, kinds=kinds, repeats=1, camera=48)
    rows = p["rows"]
    assert len(rows) == len(kinds) * len(widths) * len(res)
    assert sorted((r["resolution"], r["kind"], r["width"]) for r in rows) == \
        sorted((R, k, w) for R in res for k in kinds for w in widths)
    for r in rows:
        for key in ("build_ms", "lookup_ms", "lookup_kernel_ms", "pcf_lookup_ms", "pcf_kernel_ms"):
            assert math.isfinite(r[key]) and r[key] > 0, (key, r)
    # PCF's cost is one measurement per (R, W), the same on every kind's row
    for R in res:
        for w in widths:
            pcf = {(r["pcf_lookup_ms"], r["pcf_kernel_ms"]) for r in rows if (r["resolution"], r["width"]) == (R, w)}
            assert len(pcf) == 1
    # the receivers are the camera's pixels facing the light within its map: fewer than the camera's
    assert all(0 < r["receivers"] < 48 * 48 for r in rows)
    md = bp.markdown(p)
    assert md[1].startswith("## (8) Pre-filtered maps") and sum(x.startswith("| 32 |") for x in md) == 4


def test_the_bench_times_the_runs_moment_map_bit_for_bit():
    """The map the bench times is pipeline.moment_map, i.e. prefilter.base.build of the depth map's
    z1; unblurred in float32, VSM's two moments are float32(t) and float32(t^2) of the normalized
    depth computed here in numpy float64."""
    import dsm.pipeline as pl
    from dsm import prefilter
    from dsm.prefilter import base
    from dsm.perf import bench_prefilter as bp
    sd, setup = bp.plates(32)
    view, smap, _ = bp.depth_map(sd, setup, 32)
    for kind in bp.KINDS:
        spec = bp.moment_spec(kind, 1)
        got = pl.moment_map(spec, smap, "float32")
        want = base.build(prefilter.get(kind), prefilter.get(kind).Params(), smap.z1.numpy(), view, "float32", 1)
        assert all(np.array_equal(a.numpy(), b.numpy()) for a, b in zip(got.b, want.b)) and got.far_b == want.far_b
    vsm = pl.moment_map(bp.moment_spec("vsm", 1), smap, "float32")
    t = np.clip((smap.z1.numpy().astype(np.float64) - view.near) / (view.far - view.near), 0.0, 1.0)
    assert np.array_equal(vsm.b[0].numpy(), t.astype(np.float32))
    assert np.array_equal(vsm.b[1].numpy(), (t * t).astype(np.float32))


def test_dsm_bench_takes_no_prefilter_and_bench_md_keeps_its_sections_without_it(capsys):
    from dsm import cli
    from dsm.perf import bench
    assert cli.main(["perf", "--help"]) == 0
    assert "--no-prefilter" in capsys.readouterr().out
    r = {"variant": "llvm_ad_rgb", "threads": 2, "repeats": 1, "builds": [], "lookups": [],
         "dou_table1_ms": bench.DOU_TABLE1}
    assert "(8)" not in bench.markdown(r)
    row = {"resolution": 64, "receivers": 10, "kind": "msm", "width": 5, "build_ms": 2.0, "lookup_ms": 0.5,
           "lookup_kernel_ms": 0.1, "lookup_compile_ms": 30.0, "pcf_lookup_ms": 1.0, "pcf_kernel_ms": 0.4,
           "pcf_compile_ms": 200.0}
    md = bench.markdown({**r, "prefilter": {"scene": "stacked_plates", "camera": 64, "repeats": 1, "rows": [row]}})
    assert "| 64 | 10 | msm | 5 | 2.00 | 0.500 | 0.100 | 1.000 | 0.400 | 0.25 | 30 / 200 |" in md
