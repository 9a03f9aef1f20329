"""Virtual shadow maps' inputs (dsm/maps/virtual.py): levels float32 cannot hold refused, levels that hold no
receiver failing their case alone, the plan's rays an upper bound."""
import json

import pytest

from conftest import cli_lines, one_line
from dsm import cli


def _virtual_toml(tmp_path, virtual: str = "", light: str = "[0.2, -0.3, -1]", map_table: str = "") -> str:
    cfg = tmp_path / "v.toml"
    cfg.write_text('[experiment]\nname = "v"\n[camera]\nresolution = [32, 32]\n[[scene]]\nbuiltin = "plane_box"\n'
                   f'[[light]]\ntype = "directional"\ndirection = {light}\n[map]\n{map_table}[map.virtual]\n'
                   f'preset = "ue5"\n{virtual}[[scheme]]\nname = "none"\n')
    return cfg


@pytest.mark.parametrize("virtual, valid", [
    ("unit_cm = 1e30\n", "no last_level up to 60 reaches it"),
    ("first_level = -60\nlast_level = -60\n", "last_level >= -19 (at most 60)")])
def test_virtual_levels_too_narrow_for_float32_are_refused_before_any_work(virtual, valid, tmp_path, capsys):
    """Known from the config: the coarsest level narrower than float32's step at one scene unit (2^-23 x scale)
    holds no receiver: exit 2 in one line naming map.virtual, its keys and their valid range, no folder written.
    The range is derived here: UE5's level l is 2^(l+3) cm wide, width(l) = 2^(l+3) / unit_cm scene units."""
    out = tmp_path / "o"
    for command in (["plan"], ["run", "--out", out]):
        rc, err = cli_lines(capsys, command[0], _virtual_toml(tmp_path, virtual), *command[1:])
        assert rc == 2
        last = -60 if "-60" in virtual else 22
        unit_cm = 1e30 if "1e30" in virtual else 100.0
        width = 2.0 ** (last + 3) / unit_cm
        assert width < 2.0 ** -23                                   # the case is the rule's, by hand
        one_line(err, "v.toml", "map.virtual", f"(last_level {last},", f"{width:.3g} scene units wide", valid,
                  f"map.virtual.unit_cm <= {2.0 ** (last + 3) / 2.0 ** -23:.3g}", "first_level, last_level or levels")
    assert 2.0 ** (-19 + 3) / 100 >= 2.0 ** -23 > 2.0 ** (-20 + 3) / 100      # -19: the lowest last_level that reaches
    assert not out.exists()


@pytest.mark.slow
def test_virtual_levels_that_hold_no_receiver_fail_their_case_alone(tmp_path, capsys):
    """levels = 1 (UE5's level 6, 5.12 m about the camera): wide enough for float32, yet the camera's receivers all
    lie farther; only the loaded scene's receivers say so. That case fails in one line naming the keys; the
    cascaded map of the same light beside it finishes."""
    out = tmp_path / "o"
    rc, err = cli_lines(capsys, "run", _virtual_toml(tmp_path, "levels = 1\n", map_table="cascades = 2\n"), "--out", out)
    assert rc == 1
    failed = [line for line in err if line.startswith("dsm: failed")]
    assert len(failed) == 1 and "Traceback" not in "\n".join(err) and "incompatible sizes" not in failed[0]
    for word in ("none of the", "map.virtual.first_level, last_level or levels", "unit_cm", "at most 60"):
        assert word in failed[0], failed[0]
    run = json.loads((out / "run.json").read_text())
    assert (run["n_failed"], run["n_cases_ok"]) == (1, 1)


def test_a_sun_from_below_gives_a_virtual_map_the_empty_case_it_gives_a_plain_map(tmp_path, capsys):
    out = tmp_path / "o"
    rc, err = cli_lines(capsys, "run", _virtual_toml(tmp_path, light="[0, 0, 1]"), "--out", out)
    assert rc == 0, err
    assert any("1 cases are empty" in line and "undefined" in line for line in err)
    plain = tmp_path / "plain.toml"
    plain.write_text(_virtual_toml(tmp_path, light="[0, 0, 1]").read_text().replace('[map.virtual]\npreset = "ue5"\n', ""))
    assert cli_lines(capsys, "run", plain, "--out", tmp_path / "p")[0] == 0
    counts = lambda o: [json.loads((o / "run.json").read_text())[k] for k in ("n_failed", "n_empty", "n_cases_ok")]
    assert counts(out) == counts(tmp_path / "p") == [0, 1, 0]


def test_a_map_resolution_that_sizes_no_map_beside_a_virtual_one_is_refused(tmp_path, capsys):
    for command in (["plan"], ["run", "--out", tmp_path / "o"]):
        rc, err = cli_lines(capsys, command[0], _virtual_toml(tmp_path, map_table="resolution = [64, 128]\n"),
                          *command[1:])
        assert rc == 2
        one_line(err, "map.resolution", "[64, 128] sizes no map", "map.virtual.resolution")
    assert not (tmp_path / "o").exists()


def test_the_plan_counts_a_virtual_maps_rays_as_at_most(tmp_path, capsys):
    rc = cli.main(["plan", str(_virtual_toml(tmp_path))])
    text = capsys.readouterr().out
    assert rc == 0
    exact = next(line for line in text.splitlines() if "rays (exact)" in line)
    bound = next(line for line in text.splitlines() if "rays (at most)" in line)
    assert "map_texel" not in exact and "map_texel 33,554,432" in bound
