"""Every experiment in experiments/ runs at tiny resolution (no skip list; the built-in default: test_cli.py)."""
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

# the built-in default (DEFAULT_CONFIG) runs at its own size in tests/test_cli.py's
# test_default_experiment_writes_the_report, which asserts all this test does of it: a tiny run of it proves nothing more
FILES = sorted((ROOT / "experiments").glob("*.toml"))


@pytest.mark.slow
@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_experiment_runs_tiny(path, tmp_path):
    cfg = config.load(path)          # absent optional meshes are skipped by the run, never here
    if cfg.scenes and all(s.missing for s in cfg.scenes):
        names = sorted({_absent_name(s) for s in cfg.scenes})
        assert set(names) <= NOT_SHIPPED | MODELS, names
        pytest.skip(f"{path.name} needs {', '.join(names)}, not shipped (data/meshes/README.md); a copy of your own "
                    "runs it (docs/sponza.md: DSM_SPONZA)")
    res = dsm.run(_tiny(cfg), out=tmp_path / "out")
    assert res.run["n_failed"] == 0, res.run["status"]
    # the shipped meshes are there; only the files without redistribution terms may be absent
    absent = {_absent_name(s) for s in cfg.scenes if s.missing}
    assert absent <= NOT_SHIPPED | MODELS, absent
    assert res.run["n_skipped"] == sum(s.missing != "" for s in cfg.scenes)
    assert len(res.rows) >= len(cfg.schemes)
    assert (tmp_path / "out" / "table.md").is_file()


# a tiny run's sizes: what runs is every case of the experiment (its scenes, lights, views, schemes, filters,
# motions and report), each at a size that makes its work small
CAMERA_PX = (48, 48)
MAP_PX = 32
VIRTUAL_SHRINK = 16             # a virtual map's texels per side and per page both /16: the same page grid
TERRAIN_STRIDE = 8              # every 8th DEM sample: about 4,300 triangles of the 275,772


def _tiny(cfg):
    """``cfg`` with every size made tiny, nothing left out: the camera, the maps (a virtual map keeps its page
    grid and levels, so a spot's level constraint still holds), the terrain's samples; one timing repeat."""
    virtual = tuple(dataclasses.replace(v, resolution=v.resolution // VIRTUAL_SHRINK,
                                        page_size=v.page_size // VIRTUAL_SHRINK)
                    if v.page_size % VIRTUAL_SHRINK == 0 and v.resolution % VIRTUAL_SHRINK == 0 else v
                    for v in cfg.map.virtual)
    mapspec = dataclasses.replace(cfg.map, resolution=(MAP_PX,) if not _virtual_only(cfg) else cfg.map.resolution,
                                  texels=(6 * MAP_PX ** 2,) if cfg.map.texels else (), virtual=virtual)
    scenes = tuple(dataclasses.replace(s, params=dataclasses.replace(s.params, stride=max(s.params.stride,
                                                                                          TERRAIN_STRIDE)))
                   if s.builtin == "terrain" else s for s in cfg.scenes)
    return dataclasses.replace(cfg, camera_resolution=CAMERA_PX, timing_repeats=1, map=mapspec, scenes=scenes)


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
