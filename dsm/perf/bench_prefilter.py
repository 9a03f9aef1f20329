"""``dsm perf`` (8): what a pre-filtered map costs beside PCF at the same kernel width.

On the builtin ``stacked_plates`` under its own sun (a 512^2 camera's receivers), per map
resolution, kind (vsm, esm, evsm, msm at their defaults, float32) and blur width W: the
moments-and-blur build (:func:`dsm.pipeline.moment_map`, as a run builds it: numpy float64 on
the host, then the four or fewer float32 arrays handed to Dr.Jit; wall clock only, as no
kernel runs but the copy) and the lookup (:func:`dsm.prefilter.visibility`: the nearest texel's
moments and the kind's bound), beside the ``pcf_wide:W`` lookup of constant bias on the same
depth map. Lookups are given as wall clock (Python's tracing included) and kernel time (the
kernels' own execution, Dr.Jit's history), both warm medians of the repeats with
``dr.sync_thread()`` around every clock read (:mod:`dsm.core.timing`); the cold call's JIT
compile time is reported apart. The PCF times depend on W and R only: one measurement per
(R, W), repeated on each kind's row.
"""
from __future__ import annotations

KINDS = ("vsm", "esm", "evsm", "msm")
WIDTHS = (1, 3, 5, 9)
RESOLUTIONS = (512, 1024)
SCENE = "stacked_plates"


def plates(camera: int):
    """(scene data, light set-up) of the bench's scene under its own sun, ``camera``^2 pixels."""
    from .. import pipeline as pl
    sd = pl.load_scene(pl.scene_spec({"builtin": SCENE}), (camera, camera))
    return sd, pl.light_setup(sd, pl.gbuffer(sd), sd.own_lights[0], "sun")


def depth_map(sd, setup, R: int) -> tuple:
    """(view, float32 depth map, receivers) of the set-up's light at resolution ``R``."""
    from .. import pipeline as pl
    view = pl.make_view(setup.light, R, pl.points_np(setup.p), sd.bbox)
    smap = pl.build_map(sd.scene, view)
    return view, smap, pl.receivers(view, setup, sd.diagonal)


def moment_spec(kind: str, width: int):
    """The MomentSpec of ``kind`` at its default parameters, a box blur ``width`` texels wide."""
    from .. import prefilter
    from ..core.types import MomentSpec
    return MomentSpec(kind, prefilter.get(kind).Params(), width)


def lookup_cost(fn, repeats: int) -> dict:
    """{wall ms, kernel ms, compile ms} of a lookup ``fn`` (returning one array): warm medians."""
    from ..core import timing
    wall = timing.measure(lambda: (fn(),), repeats)[1]
    return {"ms": wall.ms, "kernel_ms": timing.kernel_ms(lambda: (fn(),), repeats)[0], "compile_ms": wall.compile_ms}


def pcf_cost(rx, smap, width: int, repeats: int) -> dict:
    """lookup_cost of constant bias's ``pcf_wide:width`` lookup on ``smap``."""
    from .. import schemes
    from ..maps import lookup
    mod = schemes.get("constant")
    prm = mod.Params()
    return lookup_cost(lambda: lookup.visibility(mod, prm, rx, smap, f"pcf_wide:{width}")[0], repeats)


def kind_row(kind: str, width: int, smap, rx, repeats: int) -> dict:
    """One kind at one width: its moments-and-blur build (wall ms) and its lookup's costs."""
    from .. import pipeline as pl
    from .. import prefilter
    from ..core import timing
    spec = moment_spec(kind, width)

    def build_map():
        """The moment map's arrays (evaluated by the clock) and the map, as the runner times it."""
        mm = pl.moment_map(spec, smap, "float32")
        return (*mm.b, mm)
    out, build = timing.measure(build_map, repeats)
    mmap = out[-1]
    look = lookup_cost(lambda: prefilter.visibility(spec, rx, mmap), repeats)
    return {"kind": kind, "width": width, "build_ms": build.ms, "lookup_ms": look["ms"],
            "lookup_kernel_ms": look["kernel_ms"], "lookup_compile_ms": look["compile_ms"]}


def prefilter_cost(resolutions=RESOLUTIONS, widths=WIDTHS, kinds=KINDS, repeats: int = 3, camera: int = 512) -> dict:
    """(8): one row per resolution, kind and width (kinds x widths x resolutions rows)."""
    import drjit as dr
    sd, setup = plates(camera)
    rows = []
    for R in resolutions:
        _, smap, rx = depth_map(sd, setup, R)
        dr.eval(rx.depth, rx.u_map, rx.v_map, rx.texel_world, rx.to_light)
        for W in widths:
            pcf = pcf_cost(rx, smap, W, repeats)
            for kind in kinds:
                rows.append({"resolution": R, "receivers": dr.width(rx.depth), **kind_row(kind, W, smap, rx, repeats),
                             "pcf_lookup_ms": pcf["ms"], "pcf_kernel_ms": pcf["kernel_ms"],
                             "pcf_compile_ms": pcf["compile_ms"]})
    return {"scene": SCENE, "camera": camera, "repeats": repeats, "rows": rows}


def markdown(p: dict) -> list:
    """bench.md's section (8)."""
    lines = ["", f"## (8) Pre-filtered maps beside PCF at the same width ({p['scene']}, {p['camera']}^2 camera, "
             f"median of {p['repeats']} warm runs)", "",
             "Build: the moments and their W x W box blur (numpy float64 on the host, then float32 arrays to "
             "Dr.Jit), wall clock. Lookup: the kind's bound at the nearest texel of the blurred map; PCF: constant "
             "bias with pcf_wide:W (W x W taps) on the same depth map. Wall clock includes Python's tracing; "
             "kernel time is the kernels' own execution (Dr.Jit's history); compile time (cold call) apart.", "",
             "| R | receivers | kind | W | build ms | lookup ms | lookup kernel ms | PCF ms | PCF kernel ms | "
             "lookup / PCF (kernel) | compile ms (lookup / PCF) |", "|---" * 11 + "|"]
    for x in p["rows"]:
        ratio = x["lookup_kernel_ms"] / x["pcf_kernel_ms"] if x["pcf_kernel_ms"] > 0 else float("nan")
        lines.append(f"| {x['resolution']} | {x['receivers']} | {x['kind']} | {x['width']} | {x['build_ms']:.2f} | "
                     f"{x['lookup_ms']:.3f} | {x['lookup_kernel_ms']:.3f} | {x['pcf_lookup_ms']:.3f} | "
                     f"{x['pcf_kernel_ms']:.3f} | {ratio:.2f} | {x['lookup_compile_ms']:.0f} / "
                     f"{x['pcf_compile_ms']:.0f} |")
    return lines
