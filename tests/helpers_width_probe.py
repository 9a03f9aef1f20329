"""A test helper, run as a script by tests/test_machine_independence.py: build the room's cube maps
and the G-buffer with Dr.Jit's LLVM vector width forced to argv[1] lanes, and save every array to
the .npz file argv[2].

Dr.Jit picks its width from the CPU (8 on AVX2, 16 on AVX-512) and exposes no setting for it
in Python; drjit-core's C function ``jit_llvm_set_target`` sets it (after the backend starts,
before the first kernel).
The target is Haswell's feature set (AVX2, FMA), which every machine this runs on has (the
test checks the CPU's flags first). tests/test_machine_independence.py compares the files."""
import ctypes
import sys

import drjit as dr
import mitsuba as mi


def force_width(width: int):
    """Dr.Jit's LLVM backend to ``width`` lanes on a Haswell target (before any kernel)."""
    lib = ctypes.CDLL(dr.__path__[0] + "/libdrjit-core.so")
    set_target = getattr(lib, "_Z19jit_llvm_set_targetPKcS0_j")     # jit_llvm_set_target(cpu, features, width)
    set_target.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint32]
    set_target(b"haswell", b"+avx2,+fma,+f16c,+avx,+sse4.2,+sse4.1,+ssse3,+sse3,+sse2,+popcnt,+bmi,+bmi2,+lzcnt",
               width)
    get = getattr(lib, "_Z21jit_llvm_vector_widthv")
    get.restype = ctypes.c_uint32
    return get()


def arrays() -> dict:
    """Every array the machine-independence test compares, by name."""
    import numpy as np
    from dsm.config import read as config
    from dsm.scenes import gbuffer, load as scenes
    from dsm.maps import shadowmap
    from dsm.pipeline import make_view
    from dsm.core.types import LightSpec
    raw = {"experiment": {"name": "w"}, "scene": [{"builtin": "room"}], "scheme": [{"name": "none"}]}
    sd = scenes.load(config.parse(raw, "<probe>").scenes[0], (64, 64))
    view = make_view(LightSpec("point", position=(0.2, 0.1, 1.8), direction=(0, 0, -1.0)), 48, None, sd.bbox, "cube")
    rays = view.texel_rays(0, view.n_texels)
    out = {"ray_d": rays.d.numpy()}
    closed = [True] * len(sd.shape_names)
    for needs, culling in (((), "none"), (("slope", "z2"), "none"), (("z2",), "back")):
        modes = shadowmap.cull_modes_for(culling, closed)
        smap = shadowmap.build(sd.scene, view, set(needs), culling, modes)
        for i, a in enumerate(shadowmap.arrays(smap)):
            out[f"{'_'.join(needs) or 'z1'}_{culling}_{i}"] = a.numpy()
    gb = gbuffer.cast(sd.scene, sd.sensor, 64, 64)
    out["gbuffer_p"], out["gbuffer_shape"] = gb.p.numpy(), gb.shape.numpy()
    return {k: np.asarray(v) for k, v in out.items()}


if __name__ == "__main__":
    import numpy as np
    mi.set_variant("llvm_ad_rgb")          # the LLVM backend up, no kernel compiled yet
    width = force_width(int(sys.argv[1]))
    from dsm.core import env
    env.use_variant("llvm_ad_rgb")
    np.savez(sys.argv[2], width=width, **arrays())
