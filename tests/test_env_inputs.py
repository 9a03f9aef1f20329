"""The variant (dsm/core/env.py): an unknown one is a config error as the TOML key's is; a CUDA variant
without a GPU leaves dsm importable and names the variant."""
import subprocess
import sys

import pytest

from dsm.config.read import ConfigError


def test_an_unknown_variant_argument_is_a_config_error_as_the_toml_key_is(tmp_path):
    import dsm
    from conftest import base_config
    with pytest.raises(ConfigError, match="variant.*bogus.*llvm_ad_rgb"):
        dsm.run(base_config(), out=tmp_path / "r", variant="bogus", report=False)
    assert not (tmp_path / "r").exists()


@pytest.mark.slow
def test_a_cuda_variant_without_a_gpu_leaves_dsm_importable_and_names_the_variant(tmp_path):
    """Item 13: Mitsuba's own set_variant("cuda_ad_rgb") fails without a GPU; `import dsm` still
    works after it, and the first call that needs the GPU raises the kit's SetupError naming it."""
    from dsm.core import env
    if env.has_cuda():
        pytest.skip("this machine has a CUDA GPU")
    code = ("import mitsuba as mi\n"
            "try:\n    mi.set_variant('cuda_ad_rgb')\nexcept Exception as e:\n    print('mitsuba:', type(e).__name__)\n"
            "import dsm\nfrom dsm.core.env import SetupError\n"
            "try:\n    dsm.run({'scene': [{'builtin': 'plane'}], 'scheme': [{'name': 'none'}]}, "
            f"out={str(tmp_path / 'o')!r}, variant='cuda_ad_rgb')\n"
            "except SetupError as e:\n    print('SetupError:', e)\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    assert "SetupError: variant cuda_ad_rgb needs an NVIDIA GPU" in p.stdout
    assert not (tmp_path / "o").exists()
