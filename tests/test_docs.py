"""The documentation: the config reference's keys are the reader's keys, the site builds offline with
warnings as errors, its internal links resolve, its how-to configs load, README's commands exist."""
import importlib
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from dsm.config import keys as keymod, read

ROOT = Path(__file__).resolve().parents[1]

# a config that reaches every hand-read table, beside the shipped experiments
EVERY_TABLE = """
[experiment]
name = "every_table"
seed = 3
variant = "llvm_ad_rgb"
[camera]
resolution = [32, 32]
position = [3.0, -3.0, 2.0]
target = [0.0, 0.0, 0.0]
up = [0.0, 0.0, 1.0]
fov = 40
near = 0.01
far = 100.0
[[scene]]
builtin = "plane_box"
[[light]]
type = "spot"
position = [-2.0, 2.5, 2.6]
target = [0.0, 0.0, 0.0]
[[light]]
type = "point"
position = [0.6, -0.8, 2.2]
[map]
resolution = 64
[memory]
budget_mb = 512
[timing]
repeats = 1
[oracle]
lambda = 1.0
[report]
images = "none"
[execution]
backend = "ray"
address = "local"
[[motion]]
frames = 2
camera = "keyframes"
keys = [{position = [3.0, -3.0, 2.0], target = [0.0, 0.0, 0.0]}, {position = [3.0, -2.0, 2.0], target = [0.0, 0.0, 0.0]}]
light = "keyframes"
light_keys = [{position = [-2.0, 2.5, 2.6]}, {position = [-2.0, 2.0, 2.6]}]
[[scheme]]
name = "constant"
[tune]
steps = 2
[[tune.camera]]
position = [3.0, -3.0, 2.0]
target = [0.0, 0.0, 0.0]
[[tune.camera]]
position = [-3.0, -3.0, 2.0]
target = [0.0, 0.0, 0.0]
role = "heldout"
[tune.bias_map]
fit = "edge"
"""


def _table_of(where: str) -> str:
    """The reference's table name of a reader's ``where`` ('light[2]' -> 'light', 'motion[0].keys[1]' ->
    'motion.keys', '' -> the top level)."""
    return re.sub(r"\[\d+\]", "", where)


def accepted_keys(monkeypatch) -> dict:
    """{table: keys the reader accepts there}, recorded from its own check_keys calls over every
    shipped experiment and EVERY_TABLE (a table read by several light types: their union)."""
    seen = {}
    real = read.check_keys

    def recording(table, allowed, source, where):
        seen.setdefault(_table_of(where), set()).update(allowed)
        return real(table, allowed, source, where)
    for name in ("dsm.config.read", "dsm.config.tune", "dsm.core.types", "dsm.lights.spot", "dsm.lights.scene",
                 "dsm.lights.directional", "dsm.lights.point", "dsm.lights.area"):
        monkeypatch.setattr(importlib.import_module(name), "check_keys", recording)
    for path in sorted((ROOT / "experiments").glob("*.toml")):
        read.load(path)
    read.parse(tomllib.loads(EVERY_TABLE), "<every table>")
    return seen


def test_config_reference_is_the_readers_keys(monkeypatch):
    """Every key the reader accepts in a hand-read table is declared in dsm.config.keys, and every
    declared key is one the reader accepts (tables read into dataclasses are documented from them)."""
    seen = accepted_keys(monkeypatch)
    top = seen.pop("")
    assert set(top) == set(read.TOP_KEYS)
    for table in keymod.TABLES:
        declared = {k.name for k in keymod.keys_of(table)}
        if table in ("scene", "scheme", "contact"):     # their other keys are a dataclass's fields
            continue
        assert table in seen, f"no config reached [{table}]"
        assert seen[table] == declared, (table, sorted(seen[table] ^ declared))


def test_config_reference_defaults_are_the_readers():
    """The declared defaults of [timing], [report], [oracle], [map] and [experiment] are what the reader
    gives a config that leaves them out."""
    cfg = read.parse({"scene": [{"builtin": "plane"}], "scheme": [{"name": "none"}]}, "<min>")
    want = {("timing", "repeats"): str(cfg.timing_repeats), ("timing", "lookups"): cfg.timing_lookups,
            ("timing", "builds"): cfg.timing_builds, ("report", "images"): cfg.report_images,
            ("oracle", "lambda"): f"{cfg.oracle.lambdas[0]:g}", ("experiment", "seed"): str(cfg.seed),
            ("map", "resolution"): str(cfg.map.resolution[0]), ("map", "filter"): cfg.map.filter[0],
            ("map", "format"): cfg.map.format[0], ("map", "view"): cfg.map.view[0],
            ("map", "kind"): cfg.map.kind[0], ("map", "leak_texels"): f"{cfg.map.leak_texels:g}"}
    declared = {(k.table, k.name): k.default for k in keymod.KEYS}
    assert {key: declared[key] for key in want} == want
