"""cuda_ad_rgb gives the counts llvm_ad_rgb gives, on a machine with a CUDA device (DEVELOPERS.md).

The same config runs under both variants (each in its own process). For every scheme whose
bias is well above the depth rounding, the acne and peter-panning counts agree within 0.5 % of
the receivers (CUDA's fast math makes division approximate, so a receiver within a rounding
of its caster may flip; every bias here is at least half a texel); ``none`` (no bias: every self-shadowing receiver sits exactly at the
rounding) is reported, not asserted. Skipped, saying why, where no CUDA device exists.
"""
import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MESHES = ROOT / "data" / "meshes"          # the real test meshes, shipped with the kit (data/meshes/README.md)
TOLERANCE = 0.005                 # of the receivers
REPORTED_ONLY = {"none"}          # rounding-dominated: reported, not asserted


def _cuda_available() -> tuple[bool, str]:
    code = "import mitsuba as mi; mi.set_variant('cuda_ad_rgb'); import drjit as dr; dr.eval(mi.Float(1) + 1)"
    try:
        p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    except subprocess.TimeoutExpired:
        return False, "starting cuda_ad_rgb timed out"
    if p.returncode != 0:
        last = (p.stderr.strip().splitlines() or ["no output"])[-1]
        return False, f"no CUDA device for cuda_ad_rgb here ({last[:160]})"
    return True, ""


pytestmark = pytest.mark.gpu


@pytest.fixture(scope="module", autouse=True)
def cuda_device():
    ok, why = _cuda_available()
    if not ok:
        pytest.skip(why)

CONFIG = """
experiment = {{ name = "gpu_vs_cpu" }}
camera = {{ resolution = [256, 256] }}
map = {{ resolution = [512, 1024] }}
timing = {{ repeats = 1 }}
light = [{{ type = "directional", direction = [-0.4, -0.3, -1.0] }},
         {{ type = "directional", direction = [0.25, -1.0, 0.15] }}]
scheme = [  # one entry per scheme instance, as [[scheme]] blocks
    {{ name = "none" }}, {{ name = "constant", bias = ["1 texel", "3 texel"] }},
    {{ name = "slope_scaled", bias = "1 texel" }}, {{ name = "normal_offset" }},
    {{ name = "receiver_plane", bias = "0.5 texel" }}, {{ name = "midpoint" }}, {{ name = "dual" }},
]
[[scene]]
builtin = "plane_box"
{bunny}
"""
BUNNY = """[[scene]]
file = "{path}"
up = "y"
"""


def _run(cfg, variant, out):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(ROOT / "plugins"), env.get("PYTHONPATH", "")])
    p = subprocess.run([sys.executable, "-m", "dsm", "run", str(cfg), "--variant", variant, "--out", str(out)],
                       capture_output=True, text=True, timeout=1800, env=env)
    assert p.returncode == 0, (variant, p.stderr[-2000:])
    with open(out / "metrics.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def test_cuda_counts_equal_llvm_counts(tmp_path):
    bunny = MESHES / "mitsuba_bunny.ply"
    cfg = tmp_path / "gpu.toml"
    cfg.write_text(CONFIG.format(bunny=BUNNY.format(path=bunny) if bunny.is_file() else ""))
    cpu = _run(cfg, "llvm_ad_rgb", tmp_path / "llvm")
    gpu = _run(cfg, "cuda_ad_rgb", tmp_path / "cuda")
    assert [r["case"] for r in gpu] == [r["case"] for r in cpu]
    lines, bad = [], []
    from dsm.report.publish import count_share
    for c, g in zip(cpu, gpu):
        worst = count_share(c, g)
        lines.append(f"{c['scene']} {c['light']} R={c['resolution']} {c['scheme']} {c['params']}: "
                     f"receivers {c['n_receivers']}/{g['n_receivers']} acne {c['n_acne']}/{g['n_acne']} "
                     f"peter-panning {c['n_peterpan']}/{g['n_peterpan']} ({100 * worst:.3f} % of receivers)")
        if c["scheme"] not in REPORTED_ONLY and worst > TOLERANCE:
            bad.append(lines[-1])
    print("llvm/cuda counts per case:\n" + "\n".join(lines))
    assert not bad, "counts differ by more than 0.5 % of receivers:\n" + "\n".join(bad)
