"""A benchmark run's results: the suite run through dsm.run, one JSON per run with its provenance.

From dsm-bench-2 on a case's record carries its offset (label and ``translate``), the exact side's
shadowed count (``n_gt_shadowed``: where the scene sits must not move it), the map's float32 headroom
(``texel_f32_steps``: below 64 the case is precision-limited) and the mean FLIP of its
shadowed render against the exact render (:mod:`dsm.benchmark.render`, :mod:`dsm.benchmark.perceptual`).
From results version 4 on a contender's record also carries its case's costs in counts (``map_bytes``,
``page_table_bytes``, ``map_rays``, ``taps``: :mod:`dsm.case.cost`), which the leaderboard's memory
classes and the frontier read (:mod:`dsm.benchmark.costs`).
From dsm-bench-3 on a case also runs its pre-filtered config (:func:`dsm.benchmark.suite.prefiltered_config`):
those records are named by kind and filter (``vsm box:5``), carry ``map_kind`` and the leak split
(``n_leak``, ``leak_rate``), and add no oracle (the depth config's is the case's floor). A case with a
flicker config (:func:`dsm.benchmark.suite.motion_config`) runs it into ``flicker/<its name>/`` of the
benchmark's folder (frames.csv kept there) and adds one flicker record per light and contender to the
document's ``flicker`` list (not to ``cases``: its counts are a motion's, summed over frames).
From dsm-bench-6 on (results version 5) a case also runs its hybrid config (:func:`dsm.benchmark.suite.hybrid_config`):
a hybrid contender's record counts the error left after its rule's rays (``n_acne``, ``n_peterpan`` and their
rates are the run's ``hybrid_*`` columns), carries ``hybrid_rays`` and ``ray_fraction`` (rays / receivers), and its
``lookup_ms`` adds the rays' time to the map's lookup (the rays are part of the lookup; the frontier counts them).
"""
from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np

from ..core.env import machine
from ..report import figures, io as report_io
from ..truth import metrics
from . import case_images, caselog, perceptual, ranking, render
from .document import RESULTS_VERSION
from .suite import (LATEST, ORIGIN, SUITE_FILES, TIMING_CALLS, cases, hybrid_labels, load_suite, suite_sha256,
                    tuned_labels)

MEASURES = ("n_receivers", "n_gt_shadowed", "n_acne", "n_peterpan", "acne_rate", "peterpan_rate", "error_rate",
            "texel_size", "texel_f32_steps", "build_ms", "lookup_ms")
COST_MEASURES = ("map_bytes", "page_table_bytes", "map_rays", "taps")   # results version 4 on (dsm.case.cost)
LEAK_MEASURES = ("n_leak", "leak_rate")      # a pre-filtered record's: peter-panning far from the occluder
FLICKER_MEASURES = ("frames", "flicker_rate", "flicker_ever", "flicker_magnitude", "flicker_within_rate",
                    "flicker_change_rate")
ORACLE_MEASURES = ("world_objective", "texel_objective", "per_texel_objective")
# a hybrid row's error after its rays (metrics.csv's hybrid_* columns) -> the record's error columns
HYBRID_ERROR = {"n_acne": "hybrid_n_acne", "n_peterpan": "hybrid_n_peterpan", "acne_rate": "hybrid_acne_rate",
                "peterpan_rate": "hybrid_peterpan_rate", "error_rate": "hybrid_error_rate"}
HYBRID_MEASURES = ("hybrid_rays", "ray_fraction")


def light_kind(light_label: str) -> str:
    """``directional``, ``spot`` or ``point`` from a row's light label (``0:directional``)."""
    return light_label.split(":", 1)[-1]


def is_prefiltered(row: dict) -> bool:
    """Whether a metrics row is a pre-filtered map kind's (not the depth map's)."""
    return row.get("map_kind") not in (None, "", "depth")


def contender_of(row: dict, tuned: dict | None = None, hybrid: dict | None = None) -> str:
    """The contender a metrics row belongs to: a pre-filtered kind and its filter (``vsm box:5``), else its
    preset's name, else a tuned contender's (``tuned``: :func:`dsm.benchmark.suite.tuned_labels`), else its scheme's;
    a virtual shadow map's row (dsm-bench-5 on) is its preset's, ``virtual ue5`` (a key its layout label adds
    beside the preset, as the suite's unit_cm, is the same contender's); a hybrid row (dsm-bench-6 on) is its
    hybrid contender's (``hybrid``: :func:`dsm.benchmark.suite.hybrid_labels`)."""
    if row.get("hybrid_rule"):
        return hybrid[(row["hybrid_rule"], row["hybrid_params"])]
    if (row.get("cascade_layout") or "").startswith("vsm "):
        return "virtual " + row["cascade_layout"].split()[1]
    if is_prefiltered(row):           # an engine's preset of the kind (dsm-bench-4 on) between them
        return " ".join(x for x in (row["scheme"], row.get("preset") or "", row["filter"]) if x)
    if not row["preset"] and tuned and (row["scheme"], row["params"]) in tuned:
        return tuned[(row["scheme"], row["params"])]
    return row["preset"] or row["scheme"]


def case_records(case, results, flips=None, oracle=True, tuned=None, hybrid=None) -> list:
    """The suite's records of one (scene, unit, offset) run: one per light and contender (with its
    FLIP from ``flips``, case id -> mean FLIP, where given; ``tuned``, ``hybrid``: the suite's tuned and
    hybrid labels), plus its oracle floor (if ``oracle``)."""
    out = []
    where = {"offset": case.offset, "translate": list(case.translate)}
    for row in results.rows:
        rec = {"scene": case.scene, "unit": case.unit, **where, "light": light_kind(row["light"]),
               "contender": contender_of(row, tuned, hybrid), "params": row["params"]}
        rec.update({k: row[k] for k in MEASURES + COST_MEASURES})
        if row.get("hybrid_rule"):
            rec.update(hybrid_measures(row))
        if is_prefiltered(row):
            rec.update({"map_kind": row["map_kind"], **{k: row[k] for k in LEAK_MEASURES}})
        if flips is not None:
            rec["flip"] = flips[row["case"]]
        out.append(rec)
    for light in sorted({light_kind(o["light"]) for o in results.oracle} if oracle else ()):
        rows = [o for o in results.oracle if light_kind(o["light"]) == light]
        best = min(rows, key=lambda o: o["per_texel_objective"])     # the floor over the cullings run
        rec = {"scene": case.scene, "unit": case.unit, **where, "light": light, "contender": "oracle",
               "n_receivers": best["n_receivers"]}
        rec.update({k: float(min(o[k] for o in rows)) for k in ORACLE_MEASURES})
        out.append(rec)
    return out


def hybrid_measures(row: dict) -> dict:
    """A hybrid row's record columns: the error left after its rays, the rays, their fraction of the receivers,
    and the lookup's time with the rays' added."""
    return {**{k: row[h] for k, h in HYBRID_ERROR.items()}, **{k: row[k] for k in HYBRID_MEASURES},
            "lookup_ms": float(row["lookup_ms"]) + float(row["hybrid_ms"])}


def case_flips(case, res, ppd: float, variant: str | None = None, setups=None, known: dict | None = None,
               maps: dict | None = None) -> dict:
    """Case id -> mean FLIP of each row's shadowed render against the exact render, at ``ppd`` (``setups``:
    the case's :func:`dsm.benchmark.render.light_setups`, traced here when not given). ``known``: FLIP by
    the two renders' bytes, filled here: rows whose renders are the same pixels (a third of a suite's
    rows: contenders that classify every pixel alike) share one evaluation, the same value. ``maps``:
    filled here with each row's per-pixel FLIP map (case id -> (H, W) float32), where given."""
    setups = render.light_setups(case.config, variant) if setups is None else setups
    known = {} if known is None else known
    out = {}
    for row in res.rows:
        shadowed, exact = render.case_renders(setups, row, res.images[row["case"]])
        key = (_pixels_key(exact), _pixels_key(shadowed))
        if key not in known:
            known[key] = perceptual.flip(exact, shadowed, ppd)
        error, out[row["case"]] = known[key]
        if maps is not None:
            maps[row["case"]] = error
    return out


def _pixels_key(image: np.ndarray) -> tuple:
    """An image's shape, type and the SHA-256 of its pixels: equal keys, equal images."""
    a = np.ascontiguousarray(image)
    return a.shape, a.dtype.str, hashlib.sha256(a.tobytes()).hexdigest()


def flicker_records(case, res, folder: str, tuned=None) -> list:
    """The flicker records of a case's motion run: one per light and contender, its frames.csv's folder
    ``folder`` (relative to the benchmark's) and case id with it."""
    return [{"scene": case.scene, "unit": case.unit, "offset": case.offset, "light": light_kind(row["light"]),
             "contender": contender_of(row, tuned), "params": row["params"], "frames_csv": f"{folder}/frames.csv",
             "case": row["case"], **{k: row[k] for k in FLICKER_MEASURES}} for row in res.rows]


def measured(config, variant: str | None = None, cluster: str | None = None):
    """The Results of one of a case's configs: run here in a temporary folder, removed after, with no
    file but metrics.csv and run.json (the classes stay in memory for FLIP), or with ``cluster`` (a Ray
    address, already connected by the command) its map groups as Ray tasks (dsm.experiment.cluster), in
    a temporary folder too, without the report (the records read the rows and the cases' error PNGs)."""
    import tempfile
    from .. import pipeline
    cfg = pipeline.prepare(config, variant)
    if cluster is None:
        from ..experiment.runner import Runner
        with tempfile.TemporaryDirectory(prefix=f"dsm-{cfg.name}-") as tmp:
            return Runner(cfg, Path(tmp), variant, progress=False, files=False).run()
    from ..experiment import cluster as ray_run
    with tempfile.TemporaryDirectory(prefix=f"dsm-{cfg.name}-") as tmp:
        res = ray_run.run(cfg, Path(tmp), cluster, variant, progress=False, report=False)
        for row in res.rows:      # the tasks keep no class image in memory: read back from its PNG (FLIP's V)
            res.images.setdefault(row["case"], class_image(Path(tmp) / figures.image_paths(row)[0]))
    return res


def class_image(path: Path) -> np.ndarray:
    """The per-pixel classes of a case's error PNG (metrics.CLASS_COLORS, one colour each)."""
    from PIL import Image
    rgb = np.asarray(Image.open(path).convert("RGB"))
    code = lambda c: (c[..., 0].astype(np.int64) << 16) | (c[..., 1].astype(np.int64) << 8) | c[..., 2]
    palette = code(metrics.CLASS_COLORS)
    order = np.argsort(palette)
    idx = order[np.searchsorted(palette[order], code(rgb))]
    if not (palette[idx] == code(rgb)).all():
        raise ValueError(f"{path}: a pixel of no class colour")
    return idx.astype(np.uint8)


def config_records(case, res, ppd, variant, setups, known, oracle=False, tuned=None, hybrid=None) -> tuple:
    """(records, images) of one of a case's configs run (``res``): its records, with their FLIP where
    ``ppd`` is given, and per row (class image, FLIP map or None) for dsm.benchmark.case_images."""
    maps = None if ppd is None else {}
    flips = None if ppd is None else case_flips(case, res, ppd, variant, setups, known, maps)
    images = [(res.images[row["case"]], None if maps is None else maps[row["case"]]) for row in res.rows]
    return case_records(case, res, flips, oracle=oracle, tuned=tuned, hybrid=hybrid), images


def run_case(case, ppd, variant: str | None = None, tuned=None, out: Path | None = None,
             cluster: str | None = None, hybrid: dict | None = None) -> tuple:
    """(records, flicker records, the variant run) of one case: its depth config's records (with the
    oracle), then its pre-filtered config's if any (both on ``cluster`` when given); its motion
    config's flicker, run here into ``out`` (a motion run's frames are one sequence: not split in tasks); its
    hybrid config's where it has one (``hybrid``: the suite's hybrid labels).
    Its records' class images and FLIP maps go under ``out`` (dsm.benchmark.case_images) where given."""
    import dsm
    res = measured(case.config, variant, cluster)
    setups = None if ppd is None else render.light_setups(case.config, variant)    # shared: same scene and lights
    known = {}                                                                       # FLIP by renders, both configs'
    records, images = config_records(case, res, ppd, variant, setups, known, oracle=True, tuned=tuned)
    if case.prefiltered is not None:
        pre = measured(case.prefiltered, variant, cluster)
        more = config_records(case, pre, ppd, variant, setups, known)
        records, images = records + more[0], images + more[1]
    if getattr(case, "virtual", None) is not None:      # dsm-bench-5 on; its light labelled as the depth config's
        vsm = measured(case.virtual, variant, cluster)
        more = config_records(case, vsm, ppd, variant, setups, None)
        records, images = records + more[0], images + more[1]
    if case.hybrid is not None:         # dsm-bench-6 on: the depth config's scene and lights, V after the rays
        hyb = measured(case.hybrid, variant, cluster)
        more = config_records(case, hyb, ppd, variant, setups, known, hybrid=hybrid)
        records, images = records + more[0], images + more[1]
    if out is not None:                 # the oracles' records have no image: the rest pair with the rows, in order
        case_images.keep(out, [r for r in records if r["contender"] != "oracle"], images)
    flicker = []
    for motion in (m for m in (case.motion, case.prefiltered_motion) if m is not None):
        folder = f"flicker/{motion['experiment']['name']}"
        # force: the folder is the benchmark's, which holds its lock and refused an earlier run's results;
        # no report: the records are frames.csv's (`dsm report` draws a motion run's figures from its folder)
        mo = dsm.run(motion, variant=variant, out=Path(out) / folder, force=True, report=False)
        flicker += flicker_records(case, mo, folder, tuned)
    return records, flicker, res.run.get("variant")


def run_suite(size: str = "default", variant: str | None = None, progress=print, version: str = LATEST,
              out: Path | None = None, cluster: str | None = None, resume: bool = False) -> dict:
    """Run suite ``version`` at ``size`` and return its result document (see :func:`write`); each
    finished case is kept under ``out/cases/`` as it finishes (dsm.benchmark.caselog), and the
    flicker runs' folders go under ``out`` (a temporary folder, removed, when None); ``resume``:
    the cases the folder's run in progress finished are taken from there (caselog.Mismatch where
    it measured another suite, size, variant or backend, or ran on other dsm, Mitsuba or Dr.Jit versions); ``cluster``: a connected Ray address
    the cases' map groups run on (dsm benchmark --cluster)."""
    if out is None:
        import tempfile
        with tempfile.TemporaryDirectory() as tmp:
            return run_suite(size, variant, progress, version, Path(tmp), cluster)
    from ..core.env import engine, versions
    suite = load_suite(SUITE_FILES[version])
    ppd = suite.get("flip", {}).get("ppd")          # dsm-bench-1 has no FLIP
    todo, tuned, hybrid = cases(suite, size), tuned_labels(suite), hybrid_labels(suite)
    header = {"suite": suite["suite"]["name"], "suite_sha256": suite_sha256(SUITE_FILES[version]), "size": size,
              "variant": variant, "cluster": cluster, "cases": len(todo), "versions": engine(versions()),
              "timing_calls": TIMING_CALLS}
    log = caselog.CaseLog(out, header)
    done = log.start(resume)
    if not resume:                      # a fresh run's images alone: none of an earlier run's stays beside them
        shutil.rmtree(out / case_images.FOLDER, ignore_errors=True)
    entries = []
    for i, case in enumerate(todo):
        kept = done.get(i)
        if kept is not None and kept["case"] == caselog.case_key(case):
            entries.append(kept)
            continue
        if progress:
            where = "" if case.offset == ORIGIN else f" at {case.offset}"
            progress(f"dsm benchmark: {i + 1}/{len(todo)} {case.scene} in {case.unit}{where} (scale {case.scale:g})")
        recs, flick, run_variant = run_case(case, ppd, variant, tuned, out, cluster, hybrid)
        log.keep(i, case, recs, flick, run_variant)
        entries.append({"records": recs, "flicker": flick, "variant": run_variant})
    return document(suite, version, size, entries, cluster)


def document(suite: dict, version: str, size: str, entries: list, cluster: str | None) -> dict:
    """The result document of a run from its cases' entries (records, flicker records, variant), in the suite's order."""
    import dsm
    from ..core.env import versions
    s = suite["suite"]
    return {"results_version": RESULTS_VERSION, "suite": s["name"], "suite_sha256": suite_sha256(SUITE_FILES[version]),
            "size": size, "dsm_version": dsm.__version__, "versions": versions(),
            "variant": entries[-1]["variant"] if entries else None,
            "machine": machine(), "far_unit": s.get("far_unit"), "flip_ppd": suite.get("flip", {}).get("ppd"),
            "tuned": suite["contenders"].get("tuned", {}), "flicker": [f for e in entries for f in e["flicker"]],
            "cases": [r for e in entries for r in e["records"]],
            "flicker_motion": suite.get("flicker", {}).get("motion"),
            "backend": {"name": "ray", "address": cluster} if cluster else {"name": "local"},
            "ranking": ranking.RULE, "timing_calls": TIMING_CALLS}


def write(doc: dict, out: Path) -> Path:
    """Write the result document as ``results.json`` in ``out``; returns its path."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "results.json"
    with report_io.atomic(path) as tmp:          # a Ctrl-C while writing leaves the file whole or absent
        tmp.write_text(json.dumps(doc, indent=1))
    return path
