"""dsm perf and dsm bench's inputs (dsm/perf): folders of other commands refused, maps above 16384 refused,
an interrupted run resumed, a missing --meshes folder in one line, one size's exponent undefined."""
import json

import pytest

from conftest import cli_run as _cli, one_line as _one_line, cli_lines, folder_files, one_line


def test_bench_with_a_missing_meshes_folder_is_one_line(tmp_path, capsys):
    rc, err = _cli(capsys, "perf", "--meshes", tmp_path / "nonexistent", "--out", tmp_path / "b")
    assert rc == 2
    _one_line(err, "--meshes", str(tmp_path / "nonexistent"), "no such folder")
    assert not (tmp_path / "b").exists()
    (tmp_path / "file").write_text("")
    rc, err = _cli(capsys, "perf", "--meshes", tmp_path / "file", "--out", tmp_path / "b")
    assert rc == 2 and "not a folder" in err[0]


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
    before = folder_files(out)
    rc, err = cli_lines(capsys, *PERF, "--meshes", tmp_path, "--out", out)
    assert rc == 2
    one_line(err, f"--out {out}", *words)
    assert folder_files(out) == before


@pytest.mark.parametrize("flag", ["--resolutions", "--scaling"])
def test_perf_refuses_a_map_above_16384(flag, tmp_path, capsys):
    argv = [a if a != "32" or flag != "--resolutions" else "100000" for a in PERF]
    if flag == "--scaling":
        argv[argv.index("--scaling") + 1] = "1024,100000"
    rc, err = cli_lines(capsys, *argv, "--out", tmp_path / "p")
    assert rc == 2
    one_line(err, flag, "100000", "16384")
    assert not (tmp_path / "p").exists()


@pytest.mark.slow
def test_perf_interrupted_keeps_its_measured_sections_and_resume_goes_on(tmp_path, capsys, monkeypatch):
    from dsm.perf import bench

    def interrupted(*a, **k):          # Ctrl-C at a known point: as the frame section starts
        raise KeyboardInterrupt
    monkeypatch.setattr(bench, "frame_cost", interrupted)
    out, meshes = tmp_path / "p", tmp_path / "no-meshes"
    meshes.mkdir()
    argv = [*PERF, "--meshes", meshes, "--out", out]
    rc, err = cli_lines(capsys, *argv)
    assert rc == 130
    one_line(err, "interrupted", str(out / "bench.json"), "builds and lookups of terrain", "the rest not measured",
              "--resume")
    kept = json.loads((out / "bench.json").read_text())
    assert kept["complete"] is False and [b["scene"] for b in kept["builds"]] == ["plane_box", "terrain"]
    assert "Interrupted: measured only builds and lookups of plane_box" in (out / "bench.md").read_text()
    assert sorted(p.name for p in out.iterdir()) == ["bench.json", "bench.md"]
    rc, err = cli_lines(capsys, *argv)            # neither --resume nor --force: refused, kept as it was
    assert rc == 2 and "--resume" in err[0] and json.loads((out / "bench.json").read_text()) == kept
    rc, err = cli_lines(capsys, *[a if a != "1" else "2" for a in argv], "--resume")   # other repeats
    assert rc == 2
    one_line(err, "cannot resume", "repeats = 1, this one 2")
    monkeypatch.setattr(bench, "frame_cost", lambda *a, **k: {"scene": "terrain", "map": 32})
    monkeypatch.setattr(bench, "_scene_bench", interrupted)        # a kept section is not measured again
    monkeypatch.setattr(bench, "markdown", lambda r: "")
    rc, err = cli_lines(capsys, *argv, "--resume")
    assert rc == 0, err
    done = json.loads((out / "bench.json").read_text())
    assert done["complete"] is True and done["builds"] == kept["builds"] and done["frame"]["map"] == 32
    assert done["sections"] == kept["sections"] + ["frame"]


@pytest.mark.slow
def test_perf_force_replaces_an_earlier_perf(tmp_path, capsys):
    out, meshes = tmp_path / "p", tmp_path / "no-meshes"
    meshes.mkdir()
    out.mkdir()
    (out / "bench.json").write_text("{}")
    (out / "notes.txt").write_text("mine")
    rc, err = cli_lines(capsys, *PERF, "--no-frame", "--meshes", meshes, "--out", out, "--force")
    assert rc == 0, err
    assert json.loads((out / "bench.json").read_text())["complete"] is True
    assert (out / "notes.txt").read_text() == "mine"


def test_a_fitted_exponent_of_one_size_is_undefined_not_nan():
    from dsm.perf import bench, bench_geometry
    nan = float("nan")
    geometry = {"rows": [], "exponents": {k: nan for k in ("build_kernel_ms", "build_wall_ms", "frame_kernel_ms",
                                                            "frame_wall_ms")}}
    text = "\n".join(bench_geometry.markdown(geometry))
    assert "build undefined (one size" in text and "nan" not in text
    assert bench.fitted_exponent([1024], [3.0]) != bench.fitted_exponent([1024], [3.0])     # NaN: one size
    assert bench_geometry.exponent_text(bench.fitted_exponent([1024], [3.0])).startswith("undefined")
