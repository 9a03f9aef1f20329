"""Every experiment in experiments/ and the built-in default runs at tiny resolution (no skip list)."""
import dataclasses

import pytest

import dsm
from conftest import MESHES, ROOT

# files an experiment may name without the kit shipping them: their publishers state no
# redistribution terms (data/meshes/README.md); a user's own copy in data/meshes/ is used
NOT_SHIPPED = {"mitsuba_teapot.ply"}
# models a user supplies by [[scene]] model (dsm.scenes.models; their copies: docs/sponza.md)
MODELS = {"sponza"}


def _absent_name(spec):
    """What an absent scene is: its model's name, or its file's."""
    return spec.model or spec.file.name
from dsm.config import read as config
from dsm.cli import DEFAULT_CONFIG

FILES = sorted((ROOT / "experiments").glob("*.toml")) + [DEFAULT_CONFIG]


@pytest.mark.slow
@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_experiment_runs_tiny(path, tmp_path):
    cfg = config.load(path)          # absent optional meshes are skipped by the run, never here
    if cfg.scenes and all(s.missing for s in cfg.scenes):
        names = sorted({_absent_name(s) for s in cfg.scenes})
        assert set(names) <= NOT_SHIPPED | MODELS, names
        pytest.skip(f"{path.name} needs {', '.join(names)}, not shipped (data/meshes/README.md); a copy of your own "
                    "runs it (docs/sponza.md: DSM_SPONZA)")
    tiny = dataclasses.replace(cfg, camera_resolution=(48, 48), timing_repeats=1,
                               map=dataclasses.replace(cfg.map, resolution=(32,) if not _virtual_only(cfg) else
                                                       cfg.map.resolution,
                                                       texels=(6 * 32 ** 2,) if cfg.map.texels else ()))
    res = dsm.run(tiny, out=tmp_path / "out")
    assert res.run["n_failed"] == 0, res.run["status"]
    # the shipped meshes are there; only the files without redistribution terms may be absent
    absent = {_absent_name(s) for s in cfg.scenes if s.missing}
    assert absent <= NOT_SHIPPED | MODELS, absent
    assert res.run["n_skipped"] == sum(s.missing != "" for s in cfg.scenes)
    assert len(res.rows) >= len(cfg.schemes)
    assert (tmp_path / "out" / "table.md").is_file()


def _virtual_only(cfg) -> bool:
    """Whether every map of ``cfg`` is a virtual one (its size is map.virtual's: a [map] resolution is refused)."""
    return bool(cfg.map.virtual) and not cfg.map.cascade


def test_every_mesh_in_data_is_credited_and_the_unshipped_are_named():
    """data/meshes/README.md names each file the kit ships (its source and terms) and each file
    an experiment may use without the kit shipping it."""
    text = (MESHES / "README.md").read_text()
    shipped = [p for p in MESHES.iterdir() if p.name != "README.md" and not p.name.startswith("LICENSE")
               and p.name not in NOT_SHIPPED]
    assert {p.name for p in shipped} >= {"mitsuba_bunny.ply", "bunny_watertight_mitsuba.ply", "armadillo.ply",
                                         "dragon_vrip_res3.ply", "cbox_mitsuba"}
    for p in shipped + [MESHES / n for n in NOT_SHIPPED]:
        assert f"`{p.name}{'/' if p.is_dir() else ''}`" in text, p.name
    for name in MODELS:                 # a model's section: how to give a copy, and its terms
        assert f'model = "{name}"' in text, name
