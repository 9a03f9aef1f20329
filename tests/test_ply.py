"""PLY files (dsm/scenes/ply.py): face indices out of range and coordinates beyond float32 are one line
before Mitsuba reads the file; a good file passes."""
import os
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import cli_run as _cli, one_line as _one_line, tiny_toml


ROOT = Path(__file__).resolve().parent.parent


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
    cfg.write_text(tiny_toml(scene='file = "m.ply"'))
    for cmd in (["plan", cfg], ["run", cfg, "--out", tmp_path / "o"]):
        rc, err = _cli(capsys, *cmd)
        assert rc == 2
        _one_line(err, "scene[0].file", f"refers to vertex {bad} of 8")
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_a_ply_face_out_of_range_does_not_crash_a_process(tmp_path):
    """In a process of its own (a segfault would show as a negative status), plan then run: one interpreter
    for both calls, each call's status printed, its one line on stderr."""
    _ply(tmp_path / "m.ply", "binary_little_endian", [(0, 1, 2), (1, 99, 3)])
    cfg = tmp_path / "c.toml"
    cfg.write_text(tiny_toml(scene='file = "m.ply"'))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), str(ROOT / "plugins"),
                                                       os.environ.get("PYTHONPATH", "")]))
    calls = [["plan", str(cfg)], ["run", str(cfg), "--out", str(tmp_path / "o")]]
    code = f"from dsm.cli import main\nfor cmd in {calls!r}:\n    print(main(cmd))\n"
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stdout.split() == ["2", "2"], p.stdout
    assert p.stderr.count("vertex 99 of 8") == 2, p.stderr


def test_a_ply_with_faces_in_range_passes(tmp_path, capsys):
    for fmt in ("binary_little_endian", "ascii"):
        _ply(tmp_path / "m.ply", fmt, [(0, 1, 3), (0, 3, 2)])
        cfg = tmp_path / "c.toml"
        cfg.write_text(tiny_toml(scene='file = "m.ply"'))
        rc, err = _cli(capsys, "plan", cfg)
        assert rc == 0, err


def test_a_ply_beyond_float32_is_one_line_without_numpy_warnings(tmp_path, capfd):
    """A vertex at 3e38 (its ground beyond float32): the config error alone, no RuntimeWarning lines. In
    process (no crash is at stake here): every warning recorded, and stderr read at the file descriptor, so a
    line written by numpy or by Mitsuba's C++ shows as it would in a terminal."""
    import warnings

    import numpy as np
    from dsm import cli
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
    capfd.readouterr()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rc = cli.main(["plan", str(cfg)])
    err = capfd.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "not finite" in err[0], err
    assert not caught, [str(w.message) for w in caught]
