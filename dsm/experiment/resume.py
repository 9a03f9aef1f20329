"""Resumable runs: each case's identity, and what a previous run in the folder already finished.

A case is identified by a hash (:func:`case_keys`) of its full specification (scene spec and
the hashes of its input files, light, view, resolution, culling, scheme instance, filter,
stored format, and what every case of the config shares: camera, seed, variant, oracle
lambdas) and the software's versions (:func:`kit_version`: the kit's git commit, or its installed
version without git, and dsm's, Mitsuba's and Dr.Jit's versions, since results differ bit for bit
between releases; a resume that finds other versions says so in one line, and its cases run again).

``dsm run CONFIG --out DIR --resume`` reads DIR's run.json (each finished case's status entry
carries its ``key``) and metrics.csv (:class:`Previous`). The runner then follows the plan as
usual: it rebuilds the shared stages (G-buffer, reference, maps, oracles: they also give the
oracle rows, trade-off curves and map records of the report) but skips each case whose key
matches a finished case, writing that case's previous row again, under the plan's case id.
A case whose key changed runs again; a case of DIR that the config no longer names is listed
(on stderr and in run.json's ``stale_cases``, its images moved to ``images/stale/``), never
deleted. Since run.json is rewritten atomically (after a case, at most once a second) and a
case's row is written before the run.json that lists it, a run stopped at any point (Ctrl-C,
kill -9, a lost worker) resumes to the same rows: a case finished after the last write runs again.
"""
from __future__ import annotations

import csv
import dataclasses
import hashlib
import json
import math
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from ..report import figures, io as report_io

_FILE_HASHES: dict = {}


def kit_version(versions_: dict | None = None) -> str:
    """What a result depends on of the software: the kit's git commit (``+dirty`` for uncommitted
    edits; else its installed version) and the ENGINE versions (dsm, Mitsuba, Dr.Jit) of
    ``versions_`` (a ``core.env.versions()`` record; read here when None)."""
    from ..core import env
    v = env.versions() if versions_ is None else versions_
    commit = v.get("dsm_git_commit")
    head = "git:" + commit if commit and commit != "unknown" else "version:" + str(v.get("dsm") or "unknown")
    return " ".join([head] + [f"{k} {v.get(k)}" for k in env.ENGINE])


def file_hash(path) -> str:
    """sha256 of a file's bytes (memoised per path, size and modification time)."""
    p = Path(path)
    st = p.stat()
    memo = (str(p.resolve()), st.st_size, st.st_mtime_ns)
    if memo not in _FILE_HASHES:
        h = hashlib.sha256()
        with open(p, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        _FILE_HASHES[memo] = h.hexdigest()
    return _FILE_HASHES[memo]


def input_files(path, seen=None) -> list:
    """A scene file and, for a Mitsuba XML scene, every file it reads that exists: ``filename``
    values and ``<include filename>``s (followed into included XML files), with ``$name``
    replaced by the file's ``<default>`` values as Mitsuba does."""
    p = Path(path)
    seen = set() if seen is None else seen
    if p.resolve() in seen:
        return []
    seen.add(p.resolve())
    out = [p]
    if p.suffix.lower() != ".xml":
        return out
    try:
        root = ET.parse(p).getroot()
    except (ET.ParseError, OSError):
        return out
    defaults = {el.get("name"): el.get("value", "") for el in root.iter("default") if el.get("name")}
    for el in root.iter():
        name = el.get("filename") if el.tag == "include" else (el.get("value") if el.get("name") == "filename" else None)
        if not name:
            continue
        f = p.parent / re.sub(r"\$(\w+)", lambda m: defaults.get(m.group(1), m.group(0)), name)
        if f.is_file():
            out += input_files(f, seen)
    return out


def _plain(x):
    """A JSON-able, order-stable form of a spec (dataclasses, paths, tuples)."""
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return {"@": type(x).__name__, **{f.name: _plain(getattr(x, f.name)) for f in dataclasses.fields(x)
                                          if f.compare}}
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in sorted(x.items(), key=lambda kv: str(kv[0]))}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, Path):
        return str(x)
    if isinstance(x, float) and not math.isfinite(x):
        return repr(x)
    return x


def scene_identity(spec) -> dict:
    """A scene spec and the hashes of its input files (an absent optional file: its name only)."""
    ident = {"spec": _plain(spec)}
    if spec.file is not None and Path(spec.file).is_file():
        ident["files"] = {f.name: file_hash(f) for f in input_files(spec.file)}
        ident["spec"].pop("file", None)          # where the file lies does not change its cases
    return ident


def hybrids(cfg) -> tuple:
    """The hybrid instances every depth case runs with (``(None,)``: the map alone, no [hybrid])."""
    return tuple(getattr(cfg, "hybrid", ())) or (None,)


def case_keys(cfg, plan, version: str | None = None) -> list:
    """(case id, key) for every case of the plan, in the runner's order (case ids from the plan:
    the n-th case of the plan is case n, whatever fails before it)."""
    version = kit_version() if version is None else version
    shared = {"camera": _plain(cfg.camera_resolution), "pose": _plain(getattr(cfg, "camera", None)),
              "seed": cfg.seed, "variant": cfg.variant,
              "lambdas": _plain(cfg.oracle.lambdas), "version": version}
    if cfg.map.leak_split:                # the leak split's distance changes every row (only when asked for)
        shared["leak_texels"] = cfg.map.leak_texels
    for opt in ("contact", "shrink"):     # opt-in steps enter a case's identity only when asked (old keys stay)
        if getattr(cfg, opt, None) is not None:
            shared[opt] = _plain(getattr(cfg, opt))
    if getattr(cfg, "timing_builds", "alone") != "alone":     # build_ms is then a share of a stack's
        shared["builds"] = cfg.timing_builds
    scenes = [scene_identity(s) for s in cfg.scenes]
    out = []
    n = 0
    for m in plan.maps:
        light = _plain(cfg.lights[m.light_index]) if cfg.lights and m.light_index < len(cfg.lights) else None
        group = {"scene": scenes[m.scene_index], "light": m.light, "light_spec": light, "view": m.view,
                 "resolution": m.resolution, "culling": m.culling, "cascade": _plain(getattr(m, "cascade", None))}
        for spec in m.specs:
            for filt in cfg.map.filter:
                for fmt in cfg.map.format:
                    for hybrid in hybrids(cfg):
                        n += 1
                        extra = {"hybrid": _plain(hybrid)} if hybrid is not None else {}   # old keys stay
                        text = json.dumps({**shared, **group, "scheme": _plain(spec), "filter": filt, "format": fmt,
                                           **extra}, sort_keys=True, default=str)
                        out.append((f"{n:04d}", hashlib.sha256(text.encode()).hexdigest()[:24]))
        for spec in m.moments:            # pre-filtered instances, after the map's schemes (the runner's order)
            for fmt in cfg.map.format:
                n += 1
                text = json.dumps({**shared, **group, "map_kind": _plain(spec), "format": fmt}, sort_keys=True,
                                  default=str)
                out.append((f"{n:04d}", hashlib.sha256(text.encode()).hexdigest()[:24]))
    return out


def parse_row(row: dict) -> dict:
    """A metrics.csv row read back with its numbers as numbers (an empty number cell: NaN)."""
    out = {}
    for k, v in row.items():
        if k in report_io.TEXT_COLUMNS or k is None:     # the columns read back as text
            out[k] = v
            continue
        if v == "":
            out[k] = float("nan")
            continue
        try:
            out[k] = int(v)
        except ValueError:
            try:
                out[k] = float(v)
            except ValueError:
                out[k] = v
    return out


def metrics_problem(path: Path) -> str | None:
    """Why ``path`` cannot be read back as a run's metrics.csv (None if it can, or is absent)."""
    if not path.is_file():
        return None
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            header = next(csv.reader(fh), [])
            for _ in csv.reader(fh):
                pass
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        return f"{path} cannot be read as a dsm metrics.csv ({type(e).__name__})"
    if header[:1] != ["case"]:
        return f"{path} is not a dsm metrics.csv (its first column is not case)"
    return None


class Previous:
    """What a previous run in ``out`` finished: per case key, its row, status entry and old id."""

    def __init__(self, out: Path):
        self.out = Path(out)
        self.done = {}          # key -> (old case id, metrics.csv row as text, status entry)
        self.cascade_rows = {}  # old case id -> its cascades.csv rows (cascaded maps)
        self.versions = None    # the previous run's versions record (None: no previous run.json)
        run_json = self.out / "run.json"
        if not run_json.is_file():
            return
        run = json.loads(run_json.read_text())
        self.versions = run.get("versions") or {}
        rows = {}
        if (self.out / "metrics.csv").is_file():
            # a row cut short (a run killed while writing it) is not kept: its case runs again
            rows = {r["case"]: r for r in report_io.whole_rows(report_io.read_csv(self.out / "metrics.csv"))}
        if (self.out / "cascades.csv").is_file():
            for r in report_io.read_csv(self.out / "cascades.csv"):
                self.cascade_rows.setdefault(r.get("case"), []).append(r)
        for s in run.get("status", []):
            if s.get("key") and s.get("status") in ("ok", "empty") and s["what"].startswith("case "):
                case = s["what"].split()[1]
                if case in rows:
                    self.done[s["key"]] = (case, rows[case], s)
        for s in run.get("stale_cases", []):      # listed by an earlier resume: listed again
            self.done.setdefault(s["key"], (None, s.get("row", {}), s))

    def __len__(self):
        return len(self.done)

    def arrange(self, keys: list) -> tuple:
        """Before a resumed run: move the kept cases' images to their new case ids and the stale
        ones' to images/stale/. Returns (kept: key -> (row, status entry, cascades.csv rows) under
        the new id, stale: [{key, case, ...}])."""
        images = self.out / "images"
        new_id = {k: c for c, k in keys}
        kept, stale, moves = {}, [], []
        for key, (old, row, status) in self.done.items():
            if key in new_id:
                new = new_id[key]
                if "status" not in status:      # a case set aside by an earlier resume, named again
                    status = {**{k: status.get(k) for k in ("scene", "light", "view", "scheme", "params",
                                                            "resolution")}, "key": key,
                              "status": "ok" if str(row.get("n_receivers", "0")) not in ("", "0") else "empty"}
                kept[key] = ({**row, "case": new}, {**status, "what": f"case {new}"},
                             [parse_row({**r, "case": new}) for r in self.cascade_rows.get(old, [])])
                if old is not None and old != new:
                    moves.append((old, images / new))
            else:
                # a case already stale keeps the id it had when it was set aside
                stale.append({"key": key, "case": old if old is not None else status.get("case"),
                              **{k: status.get(k) for k in ("scene", "light", "view",
                                                                                     "scheme", "params",
                                                                                     "resolution")},
                              "row": row})
                if old is not None:
                    moves.append((old, images / "stale" / old))
        # two steps, through temporary names, so that ids swapping places never overwrite each other
        # a case's files: images/<scene>_<light>/<case>_<kind> (or images/<case>_<kind> of older runs)
        staged = []
        for old, dest in moves:
            for kind in figures.CASE_IMAGE_KINDS:
                for src in [images / f"{old}_{kind}", *images.glob(f"*/{old}_{kind}")]:
                    if not src.is_file() or src.parent.name == "stale":
                        continue
                    sub = src.parent.relative_to(images)
                    tmp = src.parent / f".resume.{old}_{kind}"
                    os.replace(src, tmp)
                    target = dest.parent / sub if dest.parent.name == "stale" else images / sub
                    staged.append((tmp, target / f"{dest.name}_{kind}"))
        for tmp, dst in staged:
            dst.parent.mkdir(parents=True, exist_ok=True)
            os.replace(tmp, dst)
        return kept, stale
