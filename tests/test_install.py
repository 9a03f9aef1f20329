"""The install: each dependency once, Ray only in the `cluster` extra, the Mitsuba and Dr.Jit ranges
stated in docs/install.md and holding the installed versions; and (slow) the plain route, `pip install .`
into a fresh virtual environment, whose first run counts as this one."""
import csv
import json
import os
import re
import shutil
import subprocess
import sys
import time
import tomllib
from importlib.metadata import version
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.specifiers import SpecifierSet

from conftest import VARYING

ROOT = Path(__file__).resolve().parent.parent
FIRST_RUN = """
[experiment]
name = "first"
[camera]
resolution = [32, 32]
[[scene]]
builtin = "plane_box"
[[light]]
type = "directional"
direction = [-0.4, -0.3, -1.0]
[map]
resolution = 32
[timing]
repeats = 1
[[scheme]]
name = "none"
[[scheme]]
name = "constant"
bias = [0.01, 0.05]
"""


def _project() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def test_each_dependency_is_listed_once_and_ray_only_in_the_cluster_extra():
    proj = _project()
    names = [Requirement(r).name.lower() for r in proj["dependencies"]]
    assert len(names) == len(set(names)), names
    assert "ray" not in names
    extras = proj["optional-dependencies"]
    assert [e for e, reqs in extras.items() if any(Requirement(r).name == "ray" for r in reqs)] == ["cluster"]


def test_mitsuba_and_drjit_ranges_hold_the_installed_versions_and_are_the_documented_ones():
    reqs = {Requirement(r).name: Requirement(r) for r in _project()["dependencies"]}
    install = (ROOT / "docs" / "install.md").read_text()
    for name in ("mitsuba", "drjit"):
        spec = reqs[name].specifier
        assert len(spec) == 2, f"{name}: a range with both bounds, not {spec}"
        assert spec.contains(version(name)), (name, version(name), str(spec))
        stated = [SpecifierSet(m) for m in re.findall(rf"`{name}\s*([<>=!~][^`]*)`", install)]
        assert stated and all(s == spec for s in stated), f"docs/install.md states {stated}, pyproject {spec}"


@pytest.mark.slow
def test_a_libllvm_dr_jit_cannot_load_is_one_line_naming_drjit_libllvm_path(tmp_path):
    """DRJIT_LIBLLVM_PATH pointing at no library: dsm run stops before any work, exit 3, in one line that
    names the variable's value and what to install (Dr.Jit's own notice aside)."""
    (tmp_path / "first.toml").write_text(FIRST_RUN)
    lib = tmp_path / "nowhere" / "libLLVM.so"
    env = {**os.environ, "DRJIT_LIBLLVM_PATH": str(lib)}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(ROOT / "plugins"), env.get("PYTHONPATH", "")])
    p = subprocess.run([sys.executable, "-m", "dsm", "run", "first.toml", "--out", "o"], capture_output=True,
                       text=True, timeout=300, env=env, cwd=tmp_path)
    ours = [line for line in p.stderr.splitlines() if line.startswith("dsm")]
    assert p.returncode == 3 and len(ours) == 1, p.stderr
    assert ours[0].startswith("dsm: setup error: Dr.Jit's LLVM backend needs libLLVM 16 or newer")
    assert f"(found: none found, DRJIT_LIBLLVM_PATH={lib})" in ours[0] and "libllvm19" in ours[0]
    assert not (tmp_path / "o" / "metrics.csv").exists()


def _copy_project(dest: Path) -> Path:
    """What `pip install .` builds from (the package, its plugins and pyproject.toml), outside the worktree."""
    dest.mkdir()
    for name in ("dsm", "plugins", "data"):        # data: the real meshes the wheel ships (package dsm_meshes)
        shutil.copytree(ROOT / name, dest / name, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    shutil.copy(ROOT / "pyproject.toml", dest / "pyproject.toml")
    return dest


def fresh_venv(path: Path) -> Path:
    """A new virtual environment at ``path`` without pip of its own: ensurepip would copy in a pip
    (about 5 CPU seconds a venv) that pip_into's, this environment's, does the work of."""
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(path)], check=True, timeout=120)
    return path


def pip_into(python: Path) -> list:
    """The command line of this environment's pip installing into ``python``'s environment (pip --python),
    without byte-compiling: compiling every installed module (numpy, matplotlib, fontTools...) took about
    8 CPU seconds, and no test here is about .pyc files (Python writes those of the modules it imports)."""
    return [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-compile"]


def no_compile_env() -> dict:
    """This environment's variables without this checkout on the path, pip told not to byte-compile (the
    pips an isolated build runs for its build environment read PIP_NO_COMPILE, not our arguments)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    return {**env, "PIP_NO_COMPILE": "1"}


@pytest.fixture(scope="session")
def built_wheel(tmp_path_factory) -> tuple:
    """The kit's wheel, built once for the session's install tests as `pip install .` builds it (an
    isolated build, setuptools from the index or pip's cache) from a copy of the project outside the
    worktree: (its path, "") or (None, pip's last lines) where it cannot be built here."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = _copy_project(tmp / "src")
    env = no_compile_env()
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--disable-pip-version-check",
                            "-w", str(tmp / "dist"), str(src)], capture_output=True, text=True, timeout=600, env=env)
    if built.returncode != 0:
        return None, built.stderr[-3000:]
    (wheel,) = (tmp / "dist").glob("dsm-*.whl")
    return wheel, ""


def _rows(path: Path) -> list:
    with open(path, newline="") as fh:
        return [{k: v for k, v in r.items() if k not in VARYING} for r in csv.DictReader(fh)]


@pytest.mark.slow
def test_pip_install_into_a_fresh_venv_then_a_first_run_counts_as_here(tmp_path, built_wheel):
    """The plain route (docs/install.md) as a user runs it: a fresh venv, `pip install .` (from PyPI:
    mitsuba, drjit and the rest, no Ray), `dsm run`; its rows are this environment's, bit for bit.
    The wheel `pip install .` builds is the session's (built_wheel: the same isolated build); pip
    installs it into the fresh venv (fresh_venv) and resolves every dependency from the index."""
    wheel, why = built_wheel
    assert wheel is not None, f"pip could not build the kit's wheel: {why}"
    venv = fresh_venv(tmp_path / "venv")
    py = venv / "bin" / "python"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    t0 = time.perf_counter()
    pip = subprocess.run([*pip_into(py), "-q", "--disable-pip-version-check", str(wheel)],
                         capture_output=True, text=True, timeout=1500, env=env, cwd=tmp_path)
    assert pip.returncode == 0, pip.stderr[-3000:]
    install_s = time.perf_counter() - t0
    check = subprocess.run([str(py), "-c", "import importlib.util as u; print(u.find_spec('ray') is None)"],
                           capture_output=True, text=True, timeout=60, env=env, cwd=tmp_path)
    assert check.stdout.strip() == "True", "the plain route installed Ray"
    (tmp_path / "first.toml").write_text(FIRST_RUN)
    t0 = time.perf_counter()
    run = subprocess.run([str(venv / "bin" / "dsm"), "run", "first.toml", "--out", "fresh"], capture_output=True,
                         text=True, timeout=600, env=env, cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-3000:]
    first_run_s = time.perf_counter() - t0
    from dsm import pipeline
    from dsm.experiment.runner import Runner
    Runner(pipeline.prepare(tomllib.loads(FIRST_RUN)), tmp_path / "here", progress=False, report=False).run()
    fresh, here = _rows(tmp_path / "fresh" / "metrics.csv"), _rows(tmp_path / "here" / "metrics.csv")
    same_engine = all(version(n) == subprocess.run(
        [str(py), "-c", f"from importlib.metadata import version; print(version('{n}'))"], capture_output=True,
        text=True, timeout=60, env=env).stdout.strip() for n in ("mitsuba", "drjit"))
    ident = lambda rows: [(r["case"], r["scene"], r["scheme"], r["params"]) for r in rows]
    assert ident(fresh) == ident(here) and len(here) == 3
    if same_engine:          # the same Mitsuba and Dr.Jit: the same bits (another release may round otherwise)
        assert fresh == here
    print(f"plain route: pip install {install_s:.0f} s, first run {first_run_s:.0f} s")


WHEEL_CASE = ("bunny", "m", "0")
# in the installed kit's Python: where its meshes are (two lines), then tests/helpers_benchmark_cases.py
# (argv[1]) with the arguments after it, as `python helpers_benchmark_cases.py ARGS` runs it
WHERE_THEN_RUN = """import runpy, sys
import dsm.perf.bench as b, dsm.benchmark.suite as s
print(b.MESHES)
print(s.MESHES == b.MESHES, (b.MESHES / 'mitsuba_bunny.ply').is_file(), flush=True)
sys.argv = sys.argv[1:]
runpy.run_path(sys.argv[0], run_name="__main__")
"""


@pytest.mark.slow
def test_the_wheel_ships_the_meshes_and_runs_the_benchmark_from_another_folder(tmp_path, built_wheel):
    """Issue 76: a pip-installed kit had no data/meshes (dsm benchmark's traceback, dsm perf's rows
    silently skipped). The wheel (the session's, built_wheel), installed with --no-deps into a fresh
    venv that sees this environment's packages (offline), runs the benchmark at its test size from
    another folder, on the bunny's case (WHEEL_CASE)."""
    wheel, why = built_wheel
    if wheel is None:               # the isolated build needs setuptools from an index or pip's cache
        pytest.skip(f"cannot build the wheel here: {why.strip().splitlines()[-1:]}")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    assert wheel.stat().st_size < 12 * 2 ** 20          # the meshes are 6.7 MB, about 4 MB compressed
    venv = fresh_venv(tmp_path / "venv")
    py = venv / "bin" / "python"
    site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    here = [p for p in sys.path if p.endswith("site-packages")]
    Path(site, "here.pth").write_text("\n".join(here) + "\n")     # mitsuba, drjit, numpy: not this checkout
    pip = subprocess.run([*pip_into(py), "-q", "--no-deps", "--no-index",
                          "--disable-pip-version-check", str(wheel)], capture_output=True, text=True, timeout=600, env=env)
    assert pip.returncode == 0, pip.stderr[-2000:]
    # one process of the venv's Python: where the installed kit finds its meshes, then the installed kit's
    # dsm benchmark on one case of the test size, the bunny's (its mesh read from the wheel's meshes): the
    # other cases add time, not another file (the venv's dsm command: the plain route's test)
    run = subprocess.run([str(py), "-c", WHERE_THEN_RUN, str(ROOT / "tests" / "helpers_benchmark_cases.py"), "0",
                          "none", json.dumps([WHEEL_CASE]), "benchmark", "--out", "b", "--size", "test"],
                         capture_output=True, text=True, timeout=900, env=env, cwd=tmp_path)
    meshes, same = (run.stdout.split("\n") + ["", ""])[:2]
    assert meshes.startswith(site) and same == "True True", run.stdout[-3000:] + run.stderr[-3000:]
    assert run.returncode == 0, run.stderr[-3000:]
    cases = json.loads((tmp_path / "b" / "results.json").read_text())["cases"]
    assert {(r["scene"], r["unit"], r["offset"]) for r in cases} == {WHEEL_CASE} and len(cases) == 13
