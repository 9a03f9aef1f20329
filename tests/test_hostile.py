"""Hostile inputs of issue 27: one writer per results folder (an OS lock a SIGKILL releases), the
API under the command line's folder rules, crossed clip planes, damaged PLY indices, absurd thread
counts, over-long names, light directions beyond float32, a missing --meshes folder. Each answer
is one line and exit 2 (a user's mistake) or the right result; the expected values are written
here (the holder's pid, the names, the reference light's counts), not read from the kit."""
import csv
import json
import os
import signal
import struct
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import dsm
from conftest import cli_run as _cli, one_line as _one_line, write_toml
from dsm import cli
from dsm.config import read as config
from dsm.experiment import lock
from dsm.config.read import ConfigError

ROOT = Path(__file__).resolve().parent.parent
# holds flock on <folder>/.dsm-lock as any process could, writes its pid there, then waits
HOLDER = ("import fcntl, os, sys, time\n"
          "d = sys.argv[1]; os.makedirs(d, exist_ok=True)\n"
          "fd = os.open(os.path.join(d, '.dsm-lock'), os.O_RDWR | os.O_CREAT)\n"
          "fcntl.flock(fd, fcntl.LOCK_EX)\n"
          "os.ftruncate(fd, 0); os.write(fd, str(os.getpid()).encode())\n"
          "print('held', flush=True); time.sleep(600)\n")


def _tiny(extra: str = "", scene: str = 'builtin = "plane"', name: str = "t") -> str:
    return (f'[experiment]\nname = "{name}"\n[camera]\nresolution = [32, 32]\n[[scene]]\n{scene}\n'
            f'[map]\nresolution = 32\n[[scheme]]\nname = "none"\n[timing]\nrepeats = 1\n{extra}')


class Holder:
    """A second process holding ``folder``'s lock until killed with SIGKILL."""

    def __init__(self, folder: Path):
        self.proc = subprocess.Popen([sys.executable, "-c", HOLDER, str(folder)], stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout.readline().strip() == "held"
        self.pid = self.proc.pid

    def kill(self):
        os.kill(self.pid, signal.SIGKILL)
        assert self.proc.wait(timeout=30) == -signal.SIGKILL


@pytest.fixture
def holder():
    made = []

    def hold(folder):
        made.append(Holder(folder))
        return made[-1]
    yield hold
    for h in made:
        if h.proc.poll() is None:
            h.kill()


@pytest.fixture
def cfg_file(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(_tiny())
    return path


def _rows(folder: Path) -> list:
    with open(folder / "metrics.csv", newline="") as fh:
        return list(csv.DictReader(fh))


# ---------------------------------------------------------------- 1: a lock per folder

@pytest.mark.parametrize("flag", [None, "--resume", "--force"])
def test_a_run_into_a_held_folder_is_refused_naming_the_holder_and_free_after_sigkill(tmp_path, capsys, cfg_file,
                                                                                       holder, flag):
    out = tmp_path / "o"
    if flag:                                  # --resume and --force act on a previous run
        assert _cli(capsys, "run", cfg_file, "--out", out)[0] == 0
        before = (out / "metrics.csv").read_bytes()
    h = holder(out)
    rc, err = _cli(capsys, "run", cfg_file, "--out", out, *([flag] if flag else []))
    assert rc == 2
    _one_line(err, str(out), f"process {h.pid}", "in use")
    if flag:
        assert (out / "metrics.csv").read_bytes() == before          # nothing written or cleared
    h.kill()                                  # the OS drops the lock; the lock file stays behind
    assert (out / ".dsm-lock").is_file()
    rc, err = _cli(capsys, "run", cfg_file, "--out", out, *([flag] if flag else []))
    assert rc == 0, err
    assert len(_rows(out)) == 1 and not (out / ".dsm-lock").exists()


def test_tune_bench_and_report_refuse_a_held_folder(tmp_path, capsys, holder):
    tune_cfg = tmp_path / "t.toml"
    tune_cfg.write_text(_tiny('[tune]\nsteps = 2\n', 'builtin = "plane_box"').replace('"none"', '"constant"'))
    a = tmp_path / "a"
    assert _cli(capsys, "run", tune_cfg, "--out", a)[0] == 0
    for args in (["tune", tune_cfg, "--out"], ["perf", "--resolutions", "32", "--scaling", "", "--repeats", "1",
                                              "--no-sweep", "--no-frame", "--out"], ["report", a, a, "--out"]):
        out = tmp_path / args[0]
        h = holder(out)
        rc, err = _cli(capsys, *args, out)
        assert rc == 2, (args, err)
        _one_line(err, str(out), f"process {h.pid}")
        assert sorted(p.name for p in out.iterdir()) == [".dsm-lock"]       # nothing written
        h.kill()
    rc, err = _cli(capsys, "report", a, a, "--out", tmp_path / "report")   # free again after SIGKILL
    assert rc == 0, err
    assert (tmp_path / "report" / "compare.md").is_file()


def test_the_api_takes_the_same_lock(tmp_path, holder):
    out = tmp_path / "o"
    h = holder(out)
    with pytest.raises(ConfigError) as e:
        dsm.run(config.parse(tomllib.loads(_tiny())), out=out)
    assert e.value.key == "out" and f"process {h.pid}" in str(e.value) and str(out) in str(e.value)
    assert sorted(p.name for p in out.iterdir()) == [".dsm-lock"]
    h.kill()
    res = dsm.run(config.parse(tomllib.loads(_tiny())), out=out)
    assert len(res.rows) == 1 and not (out / ".dsm-lock").exists()


def test_the_lock_is_an_os_lock_on_the_file(tmp_path):
    """Held here, a second open of the file cannot flock it; released, the file is gone."""
    import fcntl
    held = lock.acquire(tmp_path / "o")
    assert (tmp_path / "o" / ".dsm-lock").read_text().strip() == str(os.getpid())
    fd = os.open(tmp_path / "o" / ".dsm-lock", os.O_RDWR)
    with pytest.raises(BlockingIOError):
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    os.close(fd)
    held.release()
    assert not (tmp_path / "o" / ".dsm-lock").exists()
    lock.acquire(tmp_path / "o").release()              # free again


def test_a_rerun_after_a_kill_names_resume_and_force(tmp_path, capsys, cfg_file, holder):
    """A run killed with SIGKILL: run.json says running and a stale lock file stays; a plain re-run
    says how to go on (--resume) or start again (--force)."""
    out = tmp_path / "o"
    assert _cli(capsys, "run", cfg_file, "--out", out)[0] == 0
    run = json.loads((out / "run.json").read_text())
    (out / "run.json").write_text(json.dumps(dict(run, state="running")))
    holder(out).kill()
    rc, err = _cli(capsys, "run", cfg_file, "--out", out)
    assert rc == 2
    _one_line(err, str(out), "--resume", "--force")
    rc, err = _cli(capsys, "run", cfg_file, "--out", out, "--resume")
    assert rc == 0 and any("1 finished cases kept" in l for l in err), err
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == []


# ---------------------------------------------------------------- 3: the API follows the CLI's rules

def test_the_api_keeps_a_previous_run_unless_told(tmp_path):
    a = tomllib.loads(_tiny())
    b = tomllib.loads(_tiny().replace('name = "none"', 'name = "constant"'))
    out = tmp_path / "o"
    dsm.run(a, out=out)
    before = (out / "metrics.csv").read_bytes()
    with pytest.raises(ConfigError) as e:
        dsm.run(b, out=out)
    assert e.value.key == "out" and "resume=True" in str(e.value) and "force=True" in str(e.value)
    assert (out / "metrics.csv").read_bytes() == before
    assert [r["scheme"] for r in _rows(out)] == ["none"]
    res = dsm.run(a, out=out, resume=True)
    assert res.run["resumed_cases"] == 1
    dsm.run(b, out=out, force=True)
    assert [r["scheme"] for r in _rows(out)] == ["constant"]
    other = tomllib.loads(_tiny(name="other"))
    with pytest.raises(ConfigError) as e:
        dsm.run(other, out=out, resume=True)
    assert "holds experiment 't'" in str(e.value)
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "keep.txt").write_text("mine")
    with pytest.raises(ConfigError):
        dsm.run(a, out=tmp_path / "mine", force=True)
    assert [p.name for p in (tmp_path / "mine").iterdir()] == ["keep.txt"]


# ---------------------------------------------------------------- 5: a clip plane given alone

@pytest.mark.parametrize("key,value", [("far", "1e-3"), ("near", "100")])
def test_a_clip_plane_alone_that_crosses_the_other_is_a_config_error(tmp_path, capsys, key, value):
    cfg = tmp_path / "c.toml"
    cfg.write_text(_tiny().replace("resolution = [32, 32]", f"resolution = [32, 32]\n{key} = {value}"))
    for cmd in (["plan", cfg], ["run", cfg, "--out", tmp_path / "o"]):
        rc, err = _cli(capsys, *cmd)
        assert rc == 2
        _one_line(err, "config error", f"camera.{key}", value.replace("1e-3", "0.001"))
    assert not (tmp_path / "o").exists()


def test_a_clip_plane_alone_that_fits_still_runs(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(_tiny().replace("resolution = [32, 32]", "resolution = [32, 32]\nfar = 100"))
    assert _cli(capsys, "run", cfg, "--out", tmp_path / "o")[0] == 0


# ---------------------------------------------------------------- 6: face indices of a PLY

PLY = ("ply\nformat {fmt} 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 2\nproperty list uchar {idx} vertex_indices\nend_header\n")
CUBE = [(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]


def _ply(path: Path, fmt: str, faces, idx="int"):
    code = {"int": "i", "uint": "I"}[idx]
    head = PLY.format(fmt=fmt, idx=idx).encode()
    if fmt == "ascii":
        body = "".join("%g %g %g\n" % v for v in CUBE) + "".join("3 %d %d %d\n" % f for f in faces)
        path.write_bytes(head + body.encode())
        return
    e = "<" if fmt == "binary_little_endian" else ">"
    body = struct.pack(f"{e}24f", *[c for v in CUBE for c in v])
    body += b"".join(struct.pack(f"{e}B3{code}", 3, *f) for f in faces)
    path.write_bytes(head + body)


@pytest.mark.parametrize("fmt,idx,bad", [("binary_little_endian", "int", 99), ("binary_big_endian", "int", 99),
                                         ("ascii", "int", 99), ("binary_little_endian", "int", -1),
                                         ("binary_little_endian", "uint", 8)])
def test_a_ply_face_out_of_range_is_one_line_before_mitsuba_reads_it(tmp_path, capsys, fmt, idx, bad):
    _ply(tmp_path / "m.ply", fmt, [(0, 1, 2), (1, bad, 3)], idx)
    cfg = tmp_path / "c.toml"
    cfg.write_text(_tiny(scene='file = "m.ply"'))
    for cmd in (["plan", cfg], ["run", cfg, "--out", tmp_path / "o"]):
        rc, err = _cli(capsys, *cmd)
        assert rc == 2
        _one_line(err, "scene[0].file", f"refers to vertex {bad} of 8")
    assert not (tmp_path / "o").exists()


def test_a_ply_face_out_of_range_does_not_crash_a_process(tmp_path):
    """In a process of its own (a segfault would show as a negative status), run and plan."""
    _ply(tmp_path / "m.ply", "binary_little_endian", [(0, 1, 2), (1, 99, 3)])
    cfg = tmp_path / "c.toml"
    cfg.write_text(_tiny(scene='file = "m.ply"'))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), str(ROOT / "plugins"),
                                                       os.environ.get("PYTHONPATH", "")]))
    for cmd in (["plan", str(cfg)], ["run", str(cfg), "--out", str(tmp_path / "o")]):
        p = subprocess.run([sys.executable, "-m", "dsm.cli", *cmd], capture_output=True, text=True, env=env,
                           timeout=300)
        assert p.returncode == 2 and "vertex 99 of 8" in p.stderr, p.stderr


def test_a_ply_with_faces_in_range_passes(tmp_path, capsys):
    for fmt in ("binary_little_endian", "ascii"):
        _ply(tmp_path / "m.ply", fmt, [(0, 1, 3), (0, 3, 2)])
        cfg = tmp_path / "c.toml"
        cfg.write_text(_tiny(scene='file = "m.ply"'))
        rc, err = _cli(capsys, "plan", cfg)
        assert rc == 0, err


# ---------------------------------------------------------------- 7: thread counts

def test_an_absurd_thread_count_is_one_line(tmp_path, capsys, cfg_file):
    for n in ("100000", "1025"):
        rc, err = _cli(capsys, "run", cfg_file, "--threads", n, "--out", tmp_path / "o")
        assert rc == 2
        _one_line(err, "--threads", "1024", n)
    assert not (tmp_path / "o").exists()
    from dsm.core import env
    with pytest.raises(env.SetupError, match="1 to 1024"):
        env.use_variant(None, 100000)


# ---------------------------------------------------------------- 11: names over 255 bytes

def test_a_name_over_255_bytes_is_one_line(tmp_path, capsys, cfg_file, monkeypatch):
    long = "x" * 300
    rc, err = _cli(capsys, "run", cfg_file, "--out", tmp_path / long / "o")
    assert rc == 2
    _one_line(err, "--out", "300 bytes", "255")
    rc, err = _cli(capsys, "report", tmp_path / long)
    assert rc == 2
    _one_line(err, "report", "300 bytes")
    half = "y" * 130                                    # each fine, the default compare-A-B is not
    rc, err = _cli(capsys, "report", tmp_path / half, tmp_path / (half + "z"))
    assert rc == 2
    _one_line(err, "--out", "compare-", "270 bytes")
    named = tmp_path / "n.toml"
    named.write_text(_tiny(name="e" * 240))
    monkeypatch.chdir(tmp_path)
    rc, err = _cli(capsys, "run", named)
    assert rc == 2
    _one_line(err, "experiment.name", "240 bytes")
    assert not (tmp_path / "runs").exists()
    named.write_text(_tiny(name="e" * 230))             # the longest name a run folder takes (suffix -n included)
    assert config.load(named).name == "e" * 230


# ---------------------------------------------------------------- 15: light directions beyond float32

def test_a_light_direction_beyond_float32_gives_the_counts_of_its_direction(tmp_path):
    """Each hostile direction beside the plain one it points along, on plane_box: same counts."""
    pairs = [([1e-300, 0, -1e-300], [1, 0, -1]), ([1e308, 1e308, -1e308], [1, 1, -1]),
             ([0, 0, -1e-320], [0, 0, -1])]
    lights = "".join(f'[[light]]\ntype = "directional"\ndirection = [{", ".join(map(repr, map(float, d)))}]\n'
                     for pair in pairs for d in pair)
    cfg = tomllib.loads(_tiny(lights, 'builtin = "plane_box"'))
    rows = dsm.run(cfg, out=tmp_path / "o").rows
    assert len(rows) == 6
    keys = ("n_receivers", "n_gt_lit", "n_gt_shadowed", "n_acne", "n_peterpan", "n_excluded_backfacing")
    for i in range(3):
        hostile, plain = rows[2 * i], rows[2 * i + 1]
        assert plain["n_receivers"] > 0                    # the case was empty, every pixel "backfacing"
        assert {k: hostile[k] for k in keys} == {k: plain[k] for k in keys}, pairs[i]
    assert sum(r["n_gt_shadowed"] for r in rows) > 0      # the box casts a shadow under some of them


def test_a_light_direction_is_a_float64_unit_vector():
    raw = tomllib.loads(_tiny('[[light]]\ntype = "directional"\ndirection = [1e-300, 0, -1e-300]\n'))
    (light,) = config.parse(raw).lights
    assert light.direction == pytest.approx((2 ** -0.5, 0.0, -(2 ** -0.5)), rel=1e-15, abs=0)


# ---------------------------------------------------------------- 20: bench --meshes

def test_bench_with_a_missing_meshes_folder_is_one_line(tmp_path, capsys):
    rc, err = _cli(capsys, "perf", "--meshes", tmp_path / "nonexistent", "--out", tmp_path / "b")
    assert rc == 2
    _one_line(err, "--meshes", str(tmp_path / "nonexistent"), "no such folder")
    assert not (tmp_path / "b").exists()
    (tmp_path / "file").write_text("")
    rc, err = _cli(capsys, "perf", "--meshes", tmp_path / "file", "--out", tmp_path / "b")
    assert rc == 2 and "not a folder" in err[0]


# ---------------------------------------------------------------- report inputs, Results, SIGTERM

def _small_run(tmp_path):
    import dsm
    from conftest import base_config
    return dsm.run(base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [32, 32]},
                               map={"resolution": 32}, scheme=[{"name": "constant"}]), out=tmp_path / "r")


def test_report_refuses_a_metrics_csv_without_a_core_column_or_with_rates_not_its_counts(tmp_path, capsys):
    import csv as csvmod
    from dsm import cli
    res = _small_run(tmp_path)
    path = res.out / "metrics.csv"
    rows = list(csvmod.DictReader(open(path)))
    header = list(rows[0])

    def write(rows, header):
        with open(path, "w", newline="") as fh:
            w = csvmod.DictWriter(fh, header, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)
    write(rows, [h for h in header if h != "n_receivers"])
    capsys.readouterr()
    assert cli.main(["report", str(res.out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "n_receivers" in err[0] and "Traceback" not in err[0]
    edited = [dict(r) for r in rows]
    edited[0]["acne_rate"] = "7.5"
    write(edited, header)
    assert cli.main(["report", str(res.out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "acne_rate 7.5" in err[0] and "n_acne / n_gt_lit" in err[0]
    write(rows, header)                                              # the file as the run wrote it
    assert cli.main(["report", str(res.out)]) == 0


def test_results_name_an_unknown_column_and_a_missing_case(tmp_path):
    res = _small_run(tmp_path)
    with pytest.raises(KeyError, match="no column or scheme parameter schem"):
        res.where(schem="constant")
    assert len(res.where(scheme="constant")) == len(res.rows) == 1
    with pytest.raises(KeyError, match="no image of case 999.*'0001'"):
        res.rgb(999)
    assert res.rgb(res.rows[0]).shape == (32, 32, 3)


# SIGTERM sent from inside metrics.csv's second row write: between the row and its record's entry,
# the point where the sink's three writes once raced (issue 76); no sleep, no timer
SIGTERM_MID_ROW = """
import os, signal, sys
from dsm import cli
from dsm.report import io
write, done = io.CsvWriter.write, []
def write_then_term(self, row):
    write(self, row)
    done.append(row)
    if len(done) == 2:
        os.kill(os.getpid(), signal.SIGTERM)
io.CsvWriter.write = write_then_term
sys.argv = ["dsm", *sys.argv[1:]]
sys.exit(cli.main())
"""


def test_sigterm_leaves_the_run_interrupted_not_running(tmp_path):
    import json as jsonmod
    cfg = tmp_path / "slow.toml"
    cfg.write_text('[experiment]\nname = "slow"\n[camera]\nresolution = [32, 32]\n[[scene]]\nbuiltin = "plane_box"\n'
                   '[map]\nresolution = [32, 48]\n[[scheme]]\nname = "constant"\n'
                   f'bias = {[0.001 * k for k in range(1, 6)]}\n')
    out = tmp_path / "o"
    p = subprocess.run([sys.executable, "-c", SIGTERM_MID_ROW, "run", str(cfg), "--out", str(out)],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 130, p.stderr[-500:]
    run = jsonmod.loads((out / "run.json").read_text())
    assert run["state"] == "interrupted"
    assert "interrupted" in p.stderr and "--resume" in p.stderr
    # the row whose write the signal came in was recorded with it: run.json and metrics.csv agree
    rows = (out / "metrics.csv").read_text().count("\n") - 1
    assert run["n_cases_ok"] == rows == 2
    # and --resume neither loses nor repeats a case
    again = subprocess.run([sys.executable, "-m", "dsm.cli", "run", str(cfg), "--out", str(out), "--resume"],
                           capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr[-500:]
    cases = [line.split(",")[0] for line in (out / "metrics.csv").read_text().splitlines()[1:]]
    assert len(cases) == len(set(cases)) == jsonmod.loads((out / "run.json").read_text())["n_cases_ok"] == 10


def test_an_oracle_bias_pasted_back_gives_the_oracles_counts(tmp_path):
    """oracle.csv's best world bias, read as text and pasted into a config as a constant bias,
    gives the world oracle's acne and peter-panning counts (6 digits gave one more acne receiver)."""
    import dsm
    from conftest import base_config
    raw = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [96, 96]}, map={"resolution": 128},
                      scheme=[{"name": "none"}])
    first = dsm.run(raw, out=tmp_path / "a")
    rows = list(csv.DictReader(open(first.out / "oracle.csv")))
    # every best bias reads back to the oracle's own float (6 digits did not)
    assert [float(r["best_b"]) for r in rows] == [o["best_b"] for o in first.oracle]
    assert [float(r["best_k"]) for r in rows] == [o["best_k"] for o in first.oracle]
    row = rows[0]
    pasted = dsm.run({**raw, "scheme": [{"name": "constant", "bias": float(row["best_b"])}]}, out=tmp_path / "b")
    r = pasted.rows[0]
    assert (r["n_acne"], r["n_peterpan"]) == (int(row["world_n_acne"]), int(row["world_n_peterpan"]))


def test_an_emitter_light_on_a_scene_without_one_is_refused_naming_it(tmp_path, capsys):
    from dsm import cli
    cfg = tmp_path / "e.toml"
    cfg.write_text('[experiment]\nname = "e"\n[camera]\nresolution = [32, 32]\n[[scene]]\nbuiltin = "plane_box"\n'
                   '[[light]]\ntype = "area"\nshape = "emitter"\n[map]\nresolution = 32\n[[scheme]]\nname = "none"\n')
    for cmd in (["plan", str(cfg)], ["run", str(cfg), "--out", str(tmp_path / "o")]):
        capsys.readouterr()
        assert cli.main(cmd) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "light[0].shape" in err[0] and "plane_box" in err[0] and "no area emitter" in err[0]
    assert not (tmp_path / "o").exists()


def test_force_clears_only_what_a_run_wrote_inside_images_and_plots(tmp_path):
    """A user's files inside a run's images/ and plots/ survive --force; the run's own are
    replaced (issue: --force deleted plots/keep.txt, images/mine.txt, images/album/)."""
    import dsm
    from conftest import base_config
    raw = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [32, 32]}, map={"resolution": [16, 32]},
                      scheme=[{"name": "constant"}])
    out = tmp_path / "r"
    dsm.run(raw, out=out)
    (out / "plots" / "keep.txt").write_text("mine")
    (out / "images" / "mine.txt").write_text("mine")
    (out / "images" / "album").mkdir()
    (out / "images" / "album" / "photo.jpg").write_bytes(b"jpg")
    old = sorted(p.name for p in (out / "images").rglob("*_error.png"))
    stale = out / "images" / "plane_box_0_directional" / "0099_error.png"     # a dsm image of no current case
    stale.write_bytes(b"x")
    # a display render and a figure's case points of a scene and view the new run does not have
    (out / "images" / "gone_0_directional").mkdir()
    stale_display = out / "images" / "gone_0_directional" / "display_nl.png"
    stale_points = out / "plots" / "pareto_gone.points.json"
    stale_display.write_bytes(b"x")
    stale_points.write_text("[]")
    assert cli.main(["run", str(_toml(tmp_path, raw)), "--out", str(out), "--force"]) == 0
    assert not stale_display.exists() and not stale_display.parent.exists() and not stale_points.exists()
    assert (out / "images" / "plane_box_0_directional" / "display_nl.png").is_file()
    assert (out / "plots" / "keep.txt").read_text() == "mine" and (out / "images" / "mine.txt").read_text() == "mine"
    assert (out / "images" / "album" / "photo.jpg").read_bytes() == b"jpg"
    assert not stale.exists() and sorted(p.name for p in (out / "images").rglob("*_error.png")) == old


def _toml(tmp_path, raw) -> Path:
    """``raw`` (a config dict of tables and arrays of tables) as tmp_path/cfg.toml."""
    return write_toml(tmp_path / "cfg.toml", raw)


def test_resume_on_a_damaged_metrics_csv(tmp_path, capsys):
    """Random bytes: one line before any work (exit 2); a row cut short: its case runs again
    (was a TypeError after the work had started)."""
    import dsm
    from conftest import base_config
    raw = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [32, 32]}, map={"resolution": [16, 32]},
                      scheme=[{"name": "constant"}])
    cfg = _toml(tmp_path, raw)
    out = tmp_path / "r"
    first = dsm.run(raw, out=out)
    good = (out / "metrics.csv").read_bytes()
    (out / "metrics.csv").write_bytes(os.urandom(3000))
    capsys.readouterr()
    assert cli.main(["run", str(cfg), "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "metrics.csv" in err[0] and "Traceback" not in err[0]
    cut = good[: good.rindex(b"\n", 0, len(good) - 1) + 1] + good[good.rindex(b"\n", 0, len(good) - 1) + 1:][:40]
    (out / "metrics.csv").write_bytes(cut)                             # the last row cut mid-way
    assert cli.main(["run", str(cfg), "--out", str(out), "--resume"]) == 0
    run = json.loads((out / "run.json").read_text())
    assert run["resumed_cases"] == len(first.rows) - 1 and run["n_failed"] == 0
    rows = list(csv.DictReader(open(out / "metrics.csv")))
    assert [(r["n_acne"], r["n_peterpan"]) for r in rows] == [(str(r["n_acne"]), str(r["n_peterpan"])) for r in first.rows]


def test_the_plugins_under_an_unsupported_variant_say_which_are(tmp_path):
    """Under scalar_rgb or a spectral variant a dsm integrator is refused when loaded, one line
    naming the variants dsm supports (it failed with TypeErrors deep in a render)."""
    code = ("import mitsuba as mi, sys; mi.set_variant(sys.argv[1]); import dsm\n"
            "try:\n    mi.load_dict({'type': 'dsm_error'})\n"
            "except Exception as e:\n    print(str(e).strip().splitlines()[-1])\n")
    for v in ("scalar_rgb", "llvm_ad_spectral"):
        p = subprocess.run([sys.executable, "-c", code, v], capture_output=True, text=True, timeout=120)
        assert p.returncode == 0, p.stderr[-800:]
        assert f"variant {v} is not supported" in p.stdout and "llvm_ad_rgb, cuda_ad_rgb" in p.stdout, p.stdout


def test_receivers_do_not_depend_on_the_map_resolution():
    """A directional light's receivers are the same set at R = 1 to 7 as at R = 8 and 64 (at
    R < 8 one receiver on the fitted border fell outside: 620 against 621)."""
    import dsm
    from conftest import base_config
    res = dsm.run(base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [48, 48]},
                              map={"resolution": [1, 2, 3, 5, 7, 8, 64]}, scheme=[{"name": "none"}]))
    counts = {r["resolution"]: (r["n_receivers"], r["n_excluded_outside"]) for r in res.rows}
    assert len(set(counts.values())) == 1, counts
    assert counts[8][1] == 0


def test_resume_sees_a_change_in_a_file_an_xml_includes(tmp_path):
    """A scene XML whose shapes come through <include> and a $name default: editing the included
    file makes --resume run its cases again (they were kept, stale)."""
    import dsm
    from conftest import base_config
    ply = tmp_path / "quad.ply"
    ply.write_text("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                   "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
                   "-2 -2 0\n2 -2 0\n2 2 0\n-2 2 0\n3 0 1 2\n3 0 2 3\n")
    part = tmp_path / "part.xml"
    part.write_text('<scene version="3.0.0"><default name="mesh" value="quad.ply"/>'
                    '<shape type="ply"><string name="filename" value="$mesh"/></shape>'
                    '<shape type="cube"><transform name="to_world"><scale value="0.5"/>'
                    '<translate x="0" y="0" z="0.6"/></transform></shape></scene>')
    main = tmp_path / "scene.xml"
    main.write_text('<scene version="3.0.0"><include filename="part.xml"/>'
                    '<sensor type="perspective"><transform name="to_world"><lookat origin="4,-4,4" target="0,0,0" '
                    'up="0,0,1"/></transform><film type="hdrfilm"><integer name="width" value="32"/>'
                    '<integer name="height" value="32"/></film></sensor></scene>')
    raw = base_config(scene=[{"file": str(main)}], light=[{"type": "directional", "direction": [0.3, 0.2, -1.0]}],
                      map={"resolution": 32}, camera={"resolution": [32, 32]}, scheme=[{"name": "constant"}])
    out = tmp_path / "r"
    dsm.run(raw, out=out)
    assert dsm.run(raw, out=out, resume=True).run["resumed_cases"] == 1           # nothing changed: kept
    part.write_text(part.read_text().replace('z="0.6"', 'z="0.9"'))                # the box moved
    assert dsm.run(raw, out=out, resume=True).run["resumed_cases"] == 0
    ply.write_text(ply.read_text().replace("-2 -2 0", "-2 -2 0.01"))                # the $mesh file changed
    assert dsm.run(raw, out=out, resume=True).run["resumed_cases"] == 0


def test_an_xml_without_an_emitter_says_its_default_light_in_one_readable_line(tmp_path):
    import dsm
    from conftest import base_config
    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><shape type="rectangle"><transform name="to_world"><scale value="3"/>'
                   '</transform></shape><shape type="cube"><transform name="to_world"><scale value="0.3"/>'
                   '<translate z="0.5"/></transform></shape><sensor type="perspective"><transform name="to_world">'
                   '<lookat origin="3,-3,3" target="0,0,0" up="0,0,1"/></transform><film type="hdrfilm">'
                   '<integer name="width" value="32"/><integer name="height" value="32"/></film></sensor></scene>')
    res = dsm.run(base_config(scene=[{"file": str(xml)}], light=[{"type": "scene"}], map={"resolution": 32},
                              camera={"resolution": [32, 32]}), out=tmp_path / "r")
    notes = [s["error"] for s in res.run["status"] if s["status"] == "note"]
    assert len(notes) == 1 and "default directional light shining along (" in notes[0], notes
    assert "LightSpec" not in notes[0] and "\n" not in notes[0]


def test_a_case_set_aside_by_one_resume_and_named_again_by_the_next(tmp_path):
    """run A; --resume with B (A's cases set aside as stale); --resume with A again: A's cases
    come back, kept (this raised KeyError 'status' and left run.json "running"); a stale
    case is listed under the id it had, never None."""
    import dsm
    from conftest import base_config
    a = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [32, 32]}, map={"resolution": 32},
                    scheme=[{"name": "constant", "bias": 0.01}])
    b = {**a, "scheme": [{"name": "constant", "bias": 0.02}]}
    out = tmp_path / "r"
    first = dsm.run(a, out=out)
    second = dsm.run(b, out=out, resume=True)
    assert [s["case"] for s in second.run["stale_cases"]] == ["0001"]
    third = dsm.run(a, out=out, resume=True)
    assert third.run["state"] == "complete" and third.run["resumed_cases"] == 1 and third.run["n_failed"] == 0
    assert [s["case"] for s in third.run["stale_cases"]] == ["0001"]          # B's case, under its id
    assert (third.rows[0]["n_acne"], third.rows[0]["n_peterpan"]) == (first.rows[0]["n_acne"], first.rows[0]["n_peterpan"])
    with pytest.raises(ConfigError, match="force"):
        dsm.run(a, out=out, resume=True, force=True)
    with pytest.raises(KeyError, match="no column 'nope'"):
        third.column("nope")


def test_clip_planes_equal_in_float32_are_one_line(tmp_path, capsys):
    """near = 5, far = 5.0000001: one float32 value, which Mitsuba refused with a traceback."""
    cfg = tmp_path / "c.toml"
    cfg.write_text('[experiment]\nname = "c"\n[camera]\nresolution = [32, 32]\nnear = 5.0\nfar = 5.0000001\n'
                   '[[scene]]\nbuiltin = "plane_box"\n[map]\nresolution = 16\n[[scheme]]\nname = "none"\n')
    capsys.readouterr()
    assert cli.main(["plan", str(cfg)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "camera" in err[0] and "near clip" in err[0] and "Traceback" not in err[0], err


def test_report_says_what_a_damaged_folder_lacks(tmp_path, capsys):
    """A duplicated row is refused; rows lost against run.json, or oracle.csv deleted, are notes
    (the report was silently shorter); run.json's config as a string is no traceback."""
    res = _small_run(tmp_path)
    lines = (res.out / "metrics.csv").read_text().splitlines()
    (res.out / "metrics.csv").write_text("\n".join(lines + [lines[1]]) + "\n")
    capsys.readouterr()
    assert cli.main(["report", str(res.out)]) == 2
    assert "appears twice" in capsys.readouterr().err
    (res.out / "metrics.csv").write_text(lines[0] + "\n")            # the header alone
    (res.out / "oracle.csv").unlink()
    assert cli.main(["report", str(res.out)]) == 0
    err = capsys.readouterr().err
    assert "1 case(s) run.json lists as finished have no row" in err
    (res.out / "metrics.csv").write_text("\n".join(lines) + "\n")
    assert cli.main(["report", str(res.out)]) == 0
    assert "oracle.csv is absent" in capsys.readouterr().err
    run = json.loads((res.out / "run.json").read_text())
    (res.out / "run.json").write_text(json.dumps({**run, "config": "not a table"}))
    assert cli.main(["report", str(res.out)]) == 0


@pytest.mark.parametrize("emitter,what", [
    ('<emitter type="point"><point name="position" x="nan" y="0" z="3"/></emitter>', "position"),
    ('<emitter type="point"><point name="position" x="inf" y="0" z="3"/></emitter>', "position"),
    ('<emitter type="spot"><float name="cutoff_angle" value="nan"/><transform name="to_world">'
     '<lookat origin="0,0,3" target="0,0,0"/></transform></emitter>', "cutoff_angle")])
def test_an_xml_emitter_that_is_not_finite_is_one_line(tmp_path, capsys, emitter, what):
    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><shape type="rectangle"><transform name="to_world"><scale value="3"/>'
                   '</transform></shape>' + emitter + '<sensor type="perspective"><transform name="to_world">'
                   '<lookat origin="3,-3,3" target="0,0,0" up="0,0,1"/></transform><film type="hdrfilm">'
                   '<integer name="width" value="32"/><integer name="height" value="32"/></film></sensor></scene>')
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[experiment]\nname = "c"\n[[scene]]\nfile = "{xml}"\n[map]\nresolution = 16\n'
                   '[[scheme]]\nname = "none"\n')
    capsys.readouterr()
    assert cli.main(["plan", str(cfg)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "scene[0].file" in err[0] and what in err[0] and "not finite" in err[0], err


def test_a_ply_beyond_float32_is_one_line_without_numpy_warnings(tmp_path, capsys):
    """A vertex at 3e38 (its ground beyond float32): the config error alone, no RuntimeWarning lines."""
    import numpy as np
    ply = tmp_path / "big.ply"
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [3e38, 0, 0]], np.float32)
    rec = np.zeros(2, dtype=[("n", "u1"), ("i", "<i4", 3)])
    rec["n"], rec["i"] = 3, [[0, 1, 2], [0, 1, 3]]
    ply.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                    b"property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
                    + v.tobytes() + rec.tobytes())
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[experiment]\nname = "b"\n[[scene]]\nfile = "{ply}"\n[map]\nresolution = 16\n'
                   '[[scheme]]\nname = "none"\n')
    p = subprocess.run([sys.executable, "-m", "dsm.cli", "plan", str(cfg)], capture_output=True, text=True,
                       timeout=120)
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(err) == 1 and "not finite" in err[0], err


def test_a_builtin_moved_beyond_what_float32_holds_names_translate(tmp_path, capsys):
    """translate = [1e30, 0, 0]: float32 steps there are 7.6e22; the error names translate (it
    named the builtin and "degenerate triangles"); 1e5 still runs."""
    for t, rc in ((1e30, 2), (1e5, 0)):
        cfg = tmp_path / f"t{rc}.toml"
        cfg.write_text(f'[experiment]\nname = "t"\n[[scene]]\nbuiltin = "plane_box"\ntranslate = [{t}, 0.0, 0.0]\n'
                       '[map]\nresolution = 16\n[[scheme]]\nname = "none"\n')
        capsys.readouterr()
        assert cli.main(["plan", str(cfg)]) == rc
        if rc:
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and "scene[0].translate" in err[0] and "float32" in err[0], err


def test_an_unknown_variant_argument_is_a_config_error_as_the_toml_key_is(tmp_path):
    import dsm
    from conftest import base_config
    with pytest.raises(ConfigError, match="variant.*bogus.*llvm_ad_rgb"):
        dsm.run(base_config(), out=tmp_path / "r", variant="bogus")
    assert not (tmp_path / "r").exists()


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
