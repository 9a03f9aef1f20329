"""Resumable ``dsm tune``: each tuned scheme's identity, and the schemes a previous tune in the
folder already finished.

``dsm tune CONFIG --out DIR`` rewrites ``DIR/tune_state.json`` atomically after each scheme:
per finished scheme its key and its whole result (the entry of tune.json and its rows of
steps.csv). ``--resume`` reads it back: a scheme whose key matches is not tuned again (its
result and rows are kept, times included), the others are tuned; the scenes, maps and oracles
are always rebuilt (the bias map and held-out evaluation need them), and the learned bias map
is trained again (it starts from the tuned results). A scheme's key hashes everything its
result depends on: the kit's version, the scenes (with their input files' hashes), lights,
map (but its pre-filtered kinds and their instances, which no depth scheme reads), camera and pose,
variant, the ``[tune]`` table but its ``bias_map`` and the other schemes' ``params`` and ``range``
entries, and the scheme instance (not its position), so a changed config tunes again what it
changes and keeps the rest: a scheme added, removed or moved leaves the others' results.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

from ..report.io import atomic
from ..experiment.resume import kit_version, scene_identity

STATE = "tune_state.json"
KIND = "dsm tune state"


def shared_identity(tc, version: str | None = None) -> dict:
    """What every tuned scheme's result depends on: kit, scenes, lights, map, cameras, [tune]."""
    cfg = tc.config
    # the pre-filtered kinds and their instances ([map] kind, [map.<kind>]) are no depth scheme's input
    # (and are tuned again on every run): a changed [map.vsm] keeps the finished depth schemes
    depth_map = dataclasses.replace(cfg.map, kind=(), moments=())
    return {"version": kit_version() if version is None else version,
            "scenes": [scene_identity(s) for s in cfg.scenes], "lights": repr(cfg.lights), "map": repr(depth_map),
            "camera": repr(cfg.camera_resolution), "pose": repr(getattr(cfg, "camera", None)),
            "variant": cfg.variant, "seed": cfg.seed}


def _tune_identity(spec, name: str) -> str:
    """The [tune] settings one scheme's result depends on: all but the learned map and the other
    schemes' [tune.params] and [tune.range] entries (adding, removing or changing another scheme
    keeps this one's result)."""
    return repr(dataclasses.replace(spec, bias_map=None, params={k: v for k, v in spec.params.items() if k == name},
                                    ranges={k: v for k, v in spec.ranges.items() if k[0] == name}))


def scheme_keys(tc, version: str | None = None) -> list:
    """One key per tuned scheme instance of ``tc``, in order. The position does not count: the
    search of an instance depends on its own values and the shared settings alone (the seed is
    the same for every scheme), so two equal instances share one result."""
    shared = shared_identity(tc, version)
    return [hashlib.sha256(json.dumps({**shared, "tune": _tune_identity(tc.spec, s.name), "scheme": repr(s)},
                                      sort_keys=True, default=str).encode()).hexdigest()[:24] for s in tc.schemes]


def read_state(out: Path) -> dict:
    """The finished schemes of a previous tune in ``out``: key -> {"entry", "steps"} (none: {})."""
    p = Path(out) / STATE
    if not p.is_file():
        return {}
    try:
        doc = json.loads(p.read_text())
    except (OSError, ValueError):
        return {}
    if not isinstance(doc, dict) or doc.get("kind") != KIND:
        return {}
    return {s["key"]: s for s in doc.get("schemes", []) if _whole(s)}


def _whole(s) -> bool:
    """A state entry with what --resume reads from it (a hand-edited or foreign one is tuned again)."""
    if not isinstance(s, dict):
        return False
    e = s.get("entry")
    return (isinstance(s.get("key"), str) and isinstance(s.get("steps"), list)
            and isinstance(e, dict) and isinstance(e.get("values"), dict)
            and all(isinstance(e.get(k), str) for k in ("scheme", "start", "params"))
            and all(isinstance(e.get(k), dict) and isinstance(e[k].get("objective"), (int, float))
                    for k in ("train", "grid")))


def state_problem(out: Path, name: str) -> str | None:
    """Why ``--resume`` cannot go on with the tune in ``out`` (None if it can)."""
    p = Path(out) / STATE
    if not p.is_file():
        return f"--resume: {out} holds no previous dsm tune ({STATE}); choose another --out"
    try:
        doc = json.loads(p.read_text())
    except (OSError, ValueError):
        doc = None
    if not isinstance(doc, dict) or doc.get("kind") != KIND:
        return f"--resume: {p} is not a dsm tune state; choose another --out, or --force to replace the tune"
    if doc.get("experiment") != name:
        return (f"--resume: {out} holds experiment {doc.get('experiment')!r}, not {name!r}; resume it with its own "
                "config or choose another --out")
    return None


def write_state(out: Path, name: str, finished: list):
    """Rewrite ``out``/tune_state.json with the finished schemes: [{"key", "entry", "steps"}]."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    with atomic(out / STATE) as tmp:
        tmp.write_text(json.dumps({"kind": KIND, "experiment": name, "schemes": finished}, default=_plain))


def _plain(o):
    """numpy scalars as numbers, anything else (a spec) as its text."""
    if hasattr(o, "item"):
        return o.item()
    return str(o)
