"""A sweep on a local two-worker Ray cluster writes the rows of a local run, count for count."""
import csv
import json

import pytest

from conftest import VARYING

ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'dsm[cluster]')")



def _rows(path):
    with open(path, newline="") as fh:
        return [{k: v for k, v in r.items() if k not in VARYING} for r in csv.DictReader(fh)]


def _cfg():
    # two scenes, two resolutions and two cullings: 8 map groups (Ray tasks) of 3 cases each
    return {"experiment": {"name": "cluster"}, "camera": {"resolution": [32, 32]},
            "scene": [{"builtin": "plane_box"}, {"builtin": "plane"}],
            "light": [{"type": "directional", "direction": [-0.4, -0.3, -1.0]}],
            "map": {"resolution": [24, 32]},
            "scheme": [{"name": "constant", "bias": [0.01]}, {"name": "midpoint", "culling": ["none", "back"]},
                       {"name": "slope_scaled"}],
            "timing": {"repeats": 1}}


@pytest.mark.slow
def test_a_local_two_worker_cluster_writes_the_rows_of_a_local_run(tmp_path):
    from dsm.experiment import cluster
    from dsm import pipeline
    from dsm.experiment.runner import Runner
    cfg = pipeline.prepare(_cfg())
    local = Runner(cfg, tmp_path / "local", progress=False).run()
    expected = cluster.local_resources(2)         # read before Ray starts (dsm run's early refusal)
    try:
        cluster.run(cfg, tmp_path / "ray", "local", progress=False, local_cpus=2)
        started = ray.cluster_resources()
    finally:
        ray.shutdown()
    assert expected == {"CPU": started.get("CPU", 0.0), "GPU": started.get("GPU", 0.0)} and expected["CPU"] == 2
    assert len(local.rows) == 16
    assert _rows(tmp_path / "ray" / "metrics.csv") == _rows(tmp_path / "local" / "metrics.csv")
    run = json.loads((tmp_path / "ray" / "run.json").read_text())
    assert run["state"] == "complete" and run["n_failed"] == 0 and run["backend"]["name"] == "ray"
    # the plan's work, as a local run counts it (each scene's G-buffer and each light's reference once)
    assert run["rays"] == local.run["rays"]
    cases = [s for s in run["status"] if s["what"].startswith("case ")]
    assert len(cases) == 16 and all(s["node"] in run["nodes"] for s in cases)
    assert sum(n["cases"] for n in run["nodes"].values()) == 16
    assert sum(n["groups"] for n in run["nodes"].values()) == len(run["plan"]["maps"]) == 8
    files = lambda run: sorted(str(p.relative_to(run / "images")) for p in (run / "images").rglob("*") if p.is_file())
    # two images a case, and two display renders a scene and light (two scenes, one light each)
    assert files(tmp_path / "ray") == files(tmp_path / "local") and len(files(tmp_path / "local")) == 2 * 16 + 2 * 2
    assert (tmp_path / "ray" / "oracle.csv").read_text().count("\n") == \
        (tmp_path / "local" / "oracle.csv").read_text().count("\n")
    # what accuracy costs in time survives the tasks: every time the local run measured, the tasks measured
    import csv
    with open(tmp_path / "ray" / "metrics.csv", newline="") as fh:
        ray_rows = {r["case"]: r for r in csv.DictReader(fh)}
    for r in local.rows:
        for col in ("build_ms", "build_first_ms", "lookup_ms", "reference_ms"):
            if r[col] > 0:
                assert float(ray_rows[r["case"]][col]) > 0, (r["case"], col)


def test_the_execution_table_is_checked():
    from dsm.config import read as cfgmod
    raw = _cfg()
    raw["execution"] = {"backend": "slurm"}
    with pytest.raises(cfgmod.ConfigError, match="execution.backend.*ray"):
        cfgmod.coerce(raw)
    raw["execution"] = {"backend": "local", "address": "auto"}
    with pytest.raises(cfgmod.ConfigError, match="execution.address"):
        cfgmod.coerce(raw)
    raw["execution"] = {"backend": "ray", "address": "auto", "cpus_per_task": 2, "gpus_per_task": 0.25}
    ex = cfgmod.coerce(raw).execution
    assert (ex.backend, ex.address, ex.cpus_per_task, ex.gpus_per_task) == ("ray", "auto", 2.0, 0.25)


def test_a_cluster_nobody_answers_at_is_refused_before_the_folder_is_touched(tmp_path, capsys):
    """--cluster and [execution] address: knocked on before any work (Ray itself would retry for
    minutes, then raise a traceback after writing run.json): exit 2, one line naming the key."""
    from dsm.cli import main
    cfg = tmp_path / "c.toml"
    cfg.write_text('[[scene]]\nbuiltin = "plane"\n[[scheme]]\nname = "none"\n[map]\nresolution = 16\n'
                   '[camera]\nresolution = [8, 8]\n')
    for address in ("127.0.0.1:1", "ray://127.0.0.1:1", "no-port-here"):   # port 1: nothing listens
        assert main(["run", str(cfg), "--out", str(tmp_path / "o"), "--cluster", address]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("dsm: --cluster: ") and "ray://host:port" in err and len(err.splitlines()) == 1
        assert "Traceback" not in err and not (tmp_path / "o").exists()
    cfg.write_text(cfg.read_text() + '[execution]\nbackend = "ray"\naddress = "127.0.0.1:1"\n')
    assert main(["run", str(cfg), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{cfg}: execution.address: nothing answers at 127.0.0.1:1" in err and not (tmp_path / "o").exists()


@pytest.mark.slow
@pytest.mark.parametrize("table,key", [({"gpus_per_task": 1}, "gpus_per_task"), ({"cpus_per_task": 64}, "cpus_per_task")])
def test_a_task_bigger_than_the_cluster_is_refused_and_leaves_no_ray(tmp_path, capsys, monkeypatch, table, key):
    """gpus_per_task on a machine without a GPU, or more CPUs per task than it has: one line,
    exit 3 (a set-up the cluster lacks), before any work, Ray shut down (it hung for minutes); the local
    instance's size is read before it starts (dsm.experiment.cluster.local_resources), so Ray never starts."""
    import drjit as dr
    from dsm import cli
    if key == "gpus_per_task" and dr.has_backend(dr.JitBackend.CUDA):
        pytest.skip("this machine has a GPU")

    def no_start(*args, **kwargs):
        raise AssertionError("Ray was started for a task the local instance cannot hold")
    monkeypatch.setattr(ray, "init", no_start)
    cfg = tmp_path / "c.toml"
    cfg.write_text('[experiment]\nname = "c"\n[camera]\nresolution = [32, 32]\n[[scene]]\nbuiltin = "plane"\n'
                   '[map]\nresolution = 16\n[[scheme]]\nname = "none"\n[execution]\nbackend = "ray"\n'
                   + "".join(f"{k} = {v}\n" for k, v in table.items()))
    capsys.readouterr()
    try:
        rc = cli.main(["run", str(cfg), "--out", str(tmp_path / "o")])
    finally:
        initialized = ray.is_initialized()
        ray.shutdown()
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 3 and len(err) == 1 and f"execution.{key}" in err[0] and "cluster has" in err[0], err
    assert not initialized and not (tmp_path / "o").exists()
