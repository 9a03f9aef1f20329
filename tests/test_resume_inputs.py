"""--resume on damaged or changed inputs (dsm/experiment/resume.py): a damaged metrics.csv, a changed file an
XML includes, a case set aside and named again."""
import csv
import json
import os

import pytest

from conftest import write_cfg
from dsm import cli
from dsm.config.read import ConfigError


@pytest.mark.slow
def test_resume_on_a_damaged_metrics_csv(tmp_path, capsys):
    """Random bytes: one line before any work (exit 2); a row cut short: its case runs again
    (was a TypeError after the work had started)."""
    import dsm
    from conftest import base_config
    raw = base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [32, 32]}, map={"resolution": [16, 32]},
                      scheme=[{"name": "constant"}])
    cfg = write_cfg(tmp_path, raw)
    out = tmp_path / "r"
    first = dsm.run(raw, out=out, report=False)
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


@pytest.mark.slow
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
    dsm.run(raw, out=out, report=False)
    assert dsm.run(raw, out=out, resume=True, report=False).run["resumed_cases"] == 1           # nothing changed: kept
    part.write_text(part.read_text().replace('z="0.6"', 'z="0.9"'))                # the box moved
    assert dsm.run(raw, out=out, resume=True, report=False).run["resumed_cases"] == 0
    ply.write_text(ply.read_text().replace("-2 -2 0", "-2 -2 0.01"))                # the $mesh file changed
    assert dsm.run(raw, out=out, resume=True, report=False).run["resumed_cases"] == 0


@pytest.mark.slow
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
    first = dsm.run(a, out=out, report=False)
    second = dsm.run(b, out=out, resume=True, report=False)
    assert [s["case"] for s in second.run["stale_cases"]] == ["0001"]
    third = dsm.run(a, out=out, resume=True, report=False)
    assert third.run["state"] == "complete" and third.run["resumed_cases"] == 1 and third.run["n_failed"] == 0
    assert [s["case"] for s in third.run["stale_cases"]] == ["0001"]          # B's case, under its id
    assert (third.rows[0]["n_acne"], third.rows[0]["n_peterpan"]) == (first.rows[0]["n_acne"], first.rows[0]["n_peterpan"])
    with pytest.raises(ConfigError, match="force"):
        dsm.run(a, out=out, resume=True, force=True, report=False)
    with pytest.raises(KeyError, match="no column 'nope'"):
        third.column("nope")
