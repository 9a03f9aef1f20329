"""Issue 76: every hostile input on the newest surfaces answered. Each row: the exit code, the one
line (naming the file, key or flag and what is valid) and no file outside the command's own
written or lost."""
import json

import pytest

from dsm import cli


def _files(folder) -> dict:
    """Every file under ``folder`` with its bytes (the lock file aside): what a refusal must leave."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != ".dsm-lock"}


def _answer(capsys, *argv) -> tuple:
    """(exit status, stderr's lines) of ``dsm argv``."""
    capsys.readouterr()
    rc = cli.main([str(a) for a in argv])
    return rc, capsys.readouterr().err.strip().splitlines()


def _one_line(err: list, *words):
    assert len(err) == 1, err
    assert "Traceback" not in err[0]
    for w in words:
        assert w in err[0], (w, err[0])


# ---------------------------------------------------------------- lost or mixed work: folders

FOREIGN = {"a dsm run's folder": ({"run.json": "{}", "metrics.csv": "case\n", "report.html": "<p>"}, "holds a dsm run"),
           "a user's folder": ({"notes.txt": "mine", "thesis/ch1.tex": "x"}, "not a dsm benchmark's")}


@pytest.mark.parametrize("force", [False, True])
@pytest.mark.parametrize("kind", list(FOREIGN))
def test_benchmark_refuses_a_folder_of_another_commands_files(kind, force, tmp_path, capsys):
    out = tmp_path / "f"
    for name, text in FOREIGN[kind][0].items():
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text(text)
    before = _files(out)
    rc, err = _answer(capsys, "benchmark", "--out", out, *(["--force"] if force else []))
    assert rc == 2
    _one_line(err, f"--out {out}", FOREIGN[kind][1], "choose another --out")
    assert _files(out) == before
    (tmp_path / "a.json").write_text(json.dumps(GOOD))
    rc, err = _answer(capsys, "benchmark", "--compare", tmp_path / "a.json", tmp_path / "a.json", "--out", out)
    assert rc == 2                   # --compare's compare.json and compare.txt: not among them either
    _one_line(err, f"--out {out}", FOREIGN[kind][1])
    assert _files(out) == before


def test_benchmark_takes_a_folder_that_holds_only_its_own_compare(tmp_path):
    from dsm.benchmark import command
    out = tmp_path / "benchmark"
    out.mkdir()
    (out / "compare.json").write_text("{}")
    (out / "compare.txt").write_text("")
    assert command.folder_problem(out, force=False, resume=False) is None


def test_benchmark_page_with_out_is_refused(tmp_path, capsys):
    rc, err = _answer(capsys, "benchmark", "--page", tmp_path / "a", "--out", tmp_path / "b")
    assert rc == 2
    _one_line(err, "--page", "--out does not apply")
    assert list(tmp_path.iterdir()) == []


PERF = ["perf", "--resolutions", "32", "--scaling", "", "--repeats", "1", "--no-sweep", "--no-prefilter"]


@pytest.mark.parametrize("held, words", [
    ({"run.json": "{}", "metrics.csv": "case\n"}, ["holds a dsm run", "choose another --out"]),
    ({"bench.json": "{}", "bench.md": "# earlier"}, ["holds an earlier dsm perf (bench.json)", "--force"]),
])
def test_perf_refuses_a_run_folder_and_an_earlier_perf(held, words, tmp_path, capsys):
    out = tmp_path / "p"
    out.mkdir()
    for name, text in held.items():
        (out / name).write_text(text)
    before = _files(out)
    rc, err = _answer(capsys, *PERF, "--meshes", tmp_path, "--out", out)
    assert rc == 2
    _one_line(err, f"--out {out}", *words)
    assert _files(out) == before


@pytest.mark.parametrize("flag", ["--resolutions", "--scaling"])
def test_perf_refuses_a_map_above_16384(flag, tmp_path, capsys):
    argv = [a if a != "32" or flag != "--resolutions" else "100000" for a in PERF]
    if flag == "--scaling":
        argv[argv.index("--scaling") + 1] = "1024,100000"
    rc, err = _answer(capsys, *argv, "--out", tmp_path / "p")
    assert rc == 2
    _one_line(err, flag, "100000", "16384")
    assert not (tmp_path / "p").exists()


def test_perf_interrupted_keeps_its_measured_sections_and_resume_goes_on(tmp_path, capsys, monkeypatch):
    from dsm.perf import bench

    def interrupted(*a, **k):          # Ctrl-C at a known point: as the frame section starts
        raise KeyboardInterrupt
    monkeypatch.setattr(bench, "frame_cost", interrupted)
    out, meshes = tmp_path / "p", tmp_path / "no-meshes"
    meshes.mkdir()
    argv = [*PERF, "--meshes", meshes, "--out", out]
    rc, err = _answer(capsys, *argv)
    assert rc == 130
    _one_line(err, "interrupted", str(out / "bench.json"), "builds and lookups of terrain", "the rest not measured",
              "--resume")
    kept = json.loads((out / "bench.json").read_text())
    assert kept["complete"] is False and [b["scene"] for b in kept["builds"]] == ["plane_box", "terrain"]
    assert "Interrupted: measured only builds and lookups of plane_box" in (out / "bench.md").read_text()
    assert sorted(p.name for p in out.iterdir()) == ["bench.json", "bench.md"]
    rc, err = _answer(capsys, *argv)            # neither --resume nor --force: refused, kept as it was
    assert rc == 2 and "--resume" in err[0] and json.loads((out / "bench.json").read_text()) == kept
    rc, err = _answer(capsys, *[a if a != "1" else "2" for a in argv], "--resume")   # other repeats
    assert rc == 2
    _one_line(err, "cannot resume", "repeats = 1, this one 2")
    monkeypatch.setattr(bench, "frame_cost", lambda *a, **k: {"scene": "terrain", "map": 32})
    monkeypatch.setattr(bench, "_scene_bench", interrupted)        # a kept section is not measured again
    monkeypatch.setattr(bench, "markdown", lambda r: "")
    rc, err = _answer(capsys, *argv, "--resume")
    assert rc == 0, err
    done = json.loads((out / "bench.json").read_text())
    assert done["complete"] is True and done["builds"] == kept["builds"] and done["frame"]["map"] == 32
    assert done["sections"] == kept["sections"] + ["frame"]


def test_perf_force_replaces_an_earlier_perf(tmp_path, capsys):
    out, meshes = tmp_path / "p", tmp_path / "no-meshes"
    meshes.mkdir()
    out.mkdir()
    (out / "bench.json").write_text("{}")
    (out / "notes.txt").write_text("mine")
    rc, err = _answer(capsys, *PERF, "--no-frame", "--meshes", meshes, "--out", out, "--force")
    assert rc == 0, err
    assert json.loads((out / "bench.json").read_text())["complete"] is True
    assert (out / "notes.txt").read_text() == "mine"


# ---------------------------------------------------------------- dsm benchmark's documents and kept cases

from dsm.benchmark import caselog, compare, document  # noqa: E402

GOOD = {"suite": "dsm-bench-4", "suite_sha256": "x", "size": "test", "dsm_version": "0", "versions": {
    "dsm": "0", "mitsuba": "3", "drjit": "1"}, "variant": "llvm_ad_rgb", "machine": {}, "cases": [
    {"scene": "s", "unit": "m", "offset": "0", "light": "directional", "contender": "p", "n_receivers": 100,
     "n_acne": 3, "n_peterpan": 1, "flip": 0.01, "error_rate": 0.04, "map_bytes": 1, "page_table_bytes": 0,
     "map_rays": 1, "taps": 1}], "results_version": 3}


def _doc(**case):
    return {**GOOD, "cases": [{**GOOD["cases"][0], **case}]}


@pytest.mark.parametrize("doc, word", [
    (_doc(error_rate="0.04"), "cases[0].error_rate is '0.04', not a number"),
    ({**GOOD, "cases": [{k: v for k, v in GOOD["cases"][0].items() if k != "n_receivers"}]}, "has no n_receivers"),
    ({**GOOD, "cases": []}, "cases is empty"),
    ({**GOOD, "cases": GOOD["cases"] * 2}, "cases[1] repeats cases[0]"),
    (_doc(offset=[1]), "cases[0].offset is a list"),
    (_doc(error_rate=1.5), "cases[0].error_rate is 1.5, not a rate"),
    (_doc(n_gt_shadowed="10"), "cases[0].n_gt_shadowed is '10', not a count"),
])
def test_page_and_compare_refuse_a_damaged_document_in_one_line(doc, word, tmp_path, capsys):
    folder = tmp_path / "b"
    folder.mkdir()
    (folder / "results.json").write_text(json.dumps(doc))
    before = _files(folder)
    rc, err = _answer(capsys, "benchmark", "--page", folder)
    assert rc == 2
    _one_line(err, "--page", str(folder / "results.json"), word)
    assert _files(folder) == before
    (tmp_path / "good.json").write_text(json.dumps(GOOD))
    rc, err = _answer(capsys, "benchmark", "--compare", tmp_path / "good.json", folder / "results.json",
                      "--out", tmp_path / "cmp")
    assert rc == 2
    _one_line(err, "--compare", word)
    assert not (tmp_path / "cmp" / "compare.json").exists()


@pytest.mark.parametrize("a, b, changed", [(0.01, float("nan"), 1), (float("nan"), 0.01, 1),
                                           (float("nan"), float("nan"), 0), (0.01, 0.0105, 0)])
def test_compare_counts_a_flip_that_became_undefined_as_changed(a, b, changed):
    diff = compare.compare(_doc(flip=a), _doc(flip=b))
    assert (len(diff["changed"]), diff["n_tied"]) == (changed, 1 - changed)


def _record(**over) -> dict:
    rec = {"scene": "s", "unit": "m", "light": "directional", "contender": "p", "n_receivers": 795,
           "n_gt_shadowed": 40, "n_acne": 21, "n_peterpan": 4}
    rec.update(over)
    n, sh = rec["n_receivers"], rec["n_gt_shadowed"]
    rates = {"acne_rate": rec["n_acne"] / (n - sh), "peterpan_rate": rec["n_peterpan"] / sh,
             "error_rate": (rec["n_acne"] + rec["n_peterpan"]) / n}
    return {**rec, **rates, **over}


@pytest.mark.parametrize("edit", [{}, {"n_acne": 99999}, {"error_rate": 0.5}, {"n_peterpan": 41}, {"n_acne": -1},
                                  {"n_receivers": 10}])
def test_a_kept_case_edited_to_impossible_counts_runs_again(edit, tmp_path):
    from types import SimpleNamespace
    log = caselog.CaseLog(tmp_path, {"suite": "dsm-bench-4"})
    log.start(resume=False)
    log.keep(0, SimpleNamespace(scene="s", unit="m", offset="0"), [_record(**edit)], [], "llvm_ad_rgb")
    log.keep(1, SimpleNamespace(scene="t", unit="m", offset="0"), [_record(), {"contender": "oracle",
                                                                               "n_receivers": 3}], [], "llvm_ad_rgb")
    assert sorted(log.finished()) == ([0, 1] if not edit else [1])


# ---------------------------------------------------------------- virtual shadow maps

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
        rc, err = _answer(capsys, command[0], _virtual_toml(tmp_path, virtual), *command[1:])
        assert rc == 2
        last = -60 if "-60" in virtual else 22
        unit_cm = 1e30 if "1e30" in virtual else 100.0
        width = 2.0 ** (last + 3) / unit_cm
        assert width < 2.0 ** -23                                   # the case is the rule's, by hand
        _one_line(err, "v.toml", "map.virtual", f"(last_level {last},", f"{width:.3g} scene units wide", valid,
                  f"map.virtual.unit_cm <= {2.0 ** (last + 3) / 2.0 ** -23:.3g}", "first_level, last_level or levels")
    assert 2.0 ** (-19 + 3) / 100 >= 2.0 ** -23 > 2.0 ** (-20 + 3) / 100      # -19: the lowest last_level that reaches
    assert not out.exists()


def test_virtual_levels_that_hold_no_receiver_fail_their_case_alone(tmp_path, capsys):
    """levels = 1 (UE5's level 6, 5.12 m about the camera): wide enough for float32, yet the camera's receivers all
    lie farther; only the loaded scene's receivers say so. That case fails in one line naming the keys; the
    cascaded map of the same light beside it finishes."""
    out = tmp_path / "o"
    rc, err = _answer(capsys, "run", _virtual_toml(tmp_path, "levels = 1\n", map_table="cascades = 2\n"), "--out", out)
    assert rc == 1
    failed = [line for line in err if line.startswith("dsm: failed")]
    assert len(failed) == 1 and "Traceback" not in "\n".join(err) and "incompatible sizes" not in failed[0]
    for word in ("none of the", "map.virtual.first_level, last_level or levels", "unit_cm", "at most 60"):
        assert word in failed[0], failed[0]
    run = json.loads((out / "run.json").read_text())
    assert (run["n_failed"], run["n_cases_ok"]) == (1, 1)


def test_a_sun_from_below_gives_a_virtual_map_the_empty_case_it_gives_a_plain_map(tmp_path, capsys):
    out = tmp_path / "o"
    rc, err = _answer(capsys, "run", _virtual_toml(tmp_path, light="[0, 0, 1]"), "--out", out)
    assert rc == 0, err
    assert any("1 cases are empty" in line and "undefined" in line for line in err)
    plain = tmp_path / "plain.toml"
    plain.write_text(_virtual_toml(tmp_path, light="[0, 0, 1]").read_text().replace('[map.virtual]\npreset = "ue5"\n', ""))
    assert _answer(capsys, "run", plain, "--out", tmp_path / "p")[0] == 0
    counts = lambda o: [json.loads((o / "run.json").read_text())[k] for k in ("n_failed", "n_empty", "n_cases_ok")]
    assert counts(out) == counts(tmp_path / "p") == [0, 1, 0]


def test_a_map_resolution_that_sizes_no_map_beside_a_virtual_one_is_refused(tmp_path, capsys):
    for command in (["plan"], ["run", "--out", tmp_path / "o"]):
        rc, err = _answer(capsys, command[0], _virtual_toml(tmp_path, map_table="resolution = [64, 128]\n"),
                          *command[1:])
        assert rc == 2
        _one_line(err, "map.resolution", "[64, 128] sizes no map", "map.virtual.resolution")
    assert not (tmp_path / "o").exists()


def test_the_plan_counts_a_virtual_maps_rays_as_at_most(tmp_path, capsys):
    rc = cli.main(["plan", str(_virtual_toml(tmp_path))])
    text = capsys.readouterr().out
    assert rc == 0
    exact = next(line for line in text.splitlines() if "rays (exact)" in line)
    bound = next(line for line in text.splitlines() if "rays (at most)" in line)
    assert "map_texel" not in exact and "map_texel 33,554,432" in bound


# ---------------------------------------------------------------- dsm grad

GRAD = '[gradient]\nscene = "plate"\nlight = "{light}"\nmap_resolution = 32\nimage_resolution = 32\nparams = ["{param}"]\n{extra}'


@pytest.mark.parametrize("light, param, extra, key, words", [
    ("point", "occluder_z", "light_angle = 30\n", "gradient.light_angle", ['only with light = "directional"', "'point'"]),
    ("point", "occluder_z", "reference_step = {occluder_z = 10}\n", "gradient.reference_step.occluder_z",
     ["10 moves the occluder under the ground", "valid: 0 < step < 0.5"]),
    ("point", "occluder_z", "fd_step = {occluder_z = 1.6}\n", "gradient.fd_step.occluder_z",
     ["the occluder under the ground", "valid: 0 < step < 0.5"]),
    ("point", "light_height", "reference_step = {light_height = 1.5}\n", "gradient.reference_step.light_height",
     ["the light under the occluder's top", "valid: 0 < step < 1.5"]),
    ("point", "occluder_z", "inverse_starts = [1e30]\n", "gradient.inverse_starts",
     ["1e+30 moves occluder_z out of the scene", "|offset| < 0.5"]),
    ("directional", "light_angle", "inverse_starts = [-0.5, 75]\n", "gradient.inverse_starts",
     ["75 moves light_angle out of the scene", "|offset| < 70 degree"]),
    ("point", "occluder_x", "reference_step = {occluder_x = 10}\n", "gradient.reference_step.occluder_x",
     ["10 moves the occluder out of the image", "valid: 0 < step < 1"]),
])
def test_grad_refuses_what_it_would_ignore_or_measure_in_another_scene(light, param, extra, key, words, tmp_path,
                                                                       capsys):
    cfg = tmp_path / "g.toml"
    cfg.write_text(GRAD.format(light=light, param=param, extra=extra))
    rc, err = _answer(capsys, "grad", cfg, "--compare", "--out", tmp_path / "o")
    assert rc == 2
    _one_line(err, str(cfg), key, *words)
    assert not (tmp_path / "o").exists()


def test_a_relative_error_is_undefined_where_the_truth_is_zero_within_its_error():
    from dsm.grad.check import relative_within
    assert relative_within(0.0507, 0.00095, 0.0025) is None       # was 5237.5 %
    assert relative_within(0.0, 0.0, 0.0) is None
    assert relative_within(1.1, 1.0, 0.01) == pytest.approx(0.1)


def test_projective_rows_that_measured_nothing_do_not_agree(tmp_path):
    from types import SimpleNamespace
    from dsm.grad import findings, tables
    blind = SimpleNamespace(value=0.0, error=0.0)
    p = SimpleNamespace(integrator="direct_projective", param="occluder_z", spp=4, grads=[0.0, 0.0], mean=0.0,
                        spread=0.0, primal_mismatch=0.0, ms=1.0)
    assert tables.agrees(p, blind) is None and tables.verdict(p, blind) == "measured nothing"
    tables.write_rows(tmp_path / "projective.csv", tables.PROJECTIVE_COLUMNS, [tables.projective_values(p, blind, None)])
    import csv
    (row,) = csv.DictReader(open(tmp_path / "projective.csv"))
    assert row["agrees"] == "" and row["rel_error"] == ""
    words = findings.projective_words([row])
    assert "agreed with the truth in 0 of 1" in words and "measured nothing" in words


def test_the_words_say_why_no_technique_is_closest_where_the_truth_is_zero_within_its_error():
    from dsm.grad import findings
    rows = [{"technique": t, "param": "occluder_x", "ad": ad, "reference": "0.00095", "reference_error": "0.0025",
             "rel_error": "", "sign": "", "cosine": ""} for t, ad in (("nearest", "0.05"), ("pcss", "0.01"))]
    text = findings.compare_words(rows)
    assert "undefined" in text and "the truth is 0 within its own error" in text and "nearest (" not in text


# ---------------------------------------------------------------- also

def test_a_truncated_sponza_obj_names_its_line_not_numpy(tmp_path):
    from dsm.core.types import ConfigError
    from dsm.scenes import models
    obj = tmp_path / "sponza.obj"
    obj.write_text("v 0 0 0\nv 1 1 1\nv 2 2\n")
    with pytest.raises(ConfigError) as e:
        models.version_of(models.SPONZA, obj, None, "s.toml", "scene[0]")
    text = str(e.value)
    assert "scene[0].file" in text and "line 3 is a vertex with fewer than 3 coordinates" in text
    assert "inhomogeneous" not in text


def test_a_fitted_exponent_of_one_size_is_undefined_not_nan():
    from dsm.perf import bench, bench_geometry
    nan = float("nan")
    geometry = {"rows": [], "exponents": {k: nan for k in ("build_kernel_ms", "build_wall_ms", "frame_kernel_ms",
                                                            "frame_wall_ms")}}
    text = "\n".join(bench_geometry.markdown(geometry))
    assert "build undefined (one size" in text and "nan" not in text
    assert bench.fitted_exponent([1024], [3.0]) != bench.fitted_exponent([1024], [3.0])     # NaN: one size
    assert bench_geometry.exponent_text(bench.fitted_exponent([1024], [3.0])).startswith("undefined")
