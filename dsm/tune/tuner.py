"""Bias tuned by gradient: every continuous scheme parameter, and a learned bias map, fitted by
Dr.Jit's AD through the kit's own lookup and judged by the exact (hard) objective.

**Objective** (the oracles'): ``E = (n_acne + lambda n_peterpan) / n_receivers``, pooled over
every training case (scene x light x training camera): the counts summed, then divided by the
summed receivers.

**Relaxation.** A receiver's lit probability is ``s_r = sigmoid(margin_r(theta) / T_r)``, the
margin being the scheme's signed margin (lit when >= 0) and ``T_r = t texel_world(r)`` a
temperature in depth units tied to the texel at the receiver; ``t`` (texels) is annealed from
``temperature[0]`` to ``temperature[1]`` over the steps (``schedule``: geometric or linear).
The relaxed loss is ``(sum over truly lit (1 - s_r) + lambda sum over truly shadowed s_r) /
n_receivers``; an empty class adds 0.

**Gradients.** The parameters are Dr.Jit Floats with gradients; the scheme's own ``shift`` and
``margin`` run on them (``dr.backward``), steps are ``mi.ad.Adam``'s (first-moment decay
``BETA1`` = 0.5: the default 0.9 carries the iterate across the flat optimum of a piecewise
constant objective after the gradient turns) on each parameter divided by one texel's worth in
its unit (the mean texel width over the training receivers for world units, that over the depth
range for range units, over the scene diagonal for adaptive's K; 1 for texel units and slope
factors). ``lr`` is the step in those texels at the first temperature; it shrinks in proportion
to the temperature. After each step a parameter is clipped into its search range
(``[tune.range]``, default ``[valid minimum or 0, start + 16 texels' worth]``). Parameters
that act through the choice of texel (normal offset's ``offset``, combined's
``normal_offset``) have no derivative through z1 under a nearest lookup (a gather at
``floor(u)``): while tuning, schemes with a shift read z1 **bilinearly** between the four
surrounding texel centres (continuous in the lookup point), the slope and z2 layers and the
tangent-plane texel from the nearest texel. The hard objective always uses the kit's nearest
lookup (``pipeline.visibility``).

**Search.** ``steps`` is the budget of exact objective evaluations, the grid search's too: the
start, then a coarse grid over the search box at cell centres (a quarter of the budget), then
Adam from the better of the two, one evaluation per step, then an exact refinement (a quarter):
a compass search on the exact objective and exact line searches along each parameter (the
margins linearised by forward-mode AD, the objective along the line counted at every
receiver's flip). The best evaluation is the result: never worse than the start, nor than any
point the search saw (the relaxed loss only steers; it can rise where the exact objective
falls, so it never picks the result).

**Learned bias map** (``[tune.bias_map]``, ``fit = "adam"``; ``fit = "residual"``: a residual over
the best tuned scheme, dsm.tune.residual_map; ``fit = "edge"``: predicted per receiver from the
map's 3 x 3 texels around it, dsm.tune.edge_map): one bias per block of ``block x block`` texels
of the light's map, the map fitted once to the union of every camera's receivers (training and
held-out) so the grid is the same for all views. Trained on the training cameras (started from
the tuned constant bias when one was tuned in the same unit), judged on the held-out cameras
against the per-texel oracle of the held-out views and against the best tuned global scheme.

**Comparisons.** Constant bias against the exact oracle (world or texel, by the bias's unit)
of the training views; every scheme against a grid search over the same box with at most the
same number of (hard) loss evaluations, both timed (``dr.sync_thread`` before each clock).

This module is the run: what dsm tune refuses of a config (``parse_tune``) and ``run_tune``; ``[tune]``
itself is read with the config (dsm.config.tune), the stages are cases, relax, evaluate, search (with
refine and compare), bias_map (with residual_map) and output.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

from . import resume as tune_resume
from ..report.tables import objective
from .. import pipeline as pl
from ..core.types import ConfigError, Length, describe_params
from .evaluate import NAN, hard_counts, sync_clock, tallying, with_values
from ..config.tune import TuneSpec, tunable, tune_spec
from .cases import pooled_thresholds, prepare_cases
from .compare import exact_scan, gradient_check, grid_search
from . import light_samples, residual_map
from .bias_map import edge_bias_map, heldout_split, map_start, reads_camera, residual_bias_map, tune_bias_map
from .search import start_value, tune_scheme
from .output import TuneResult, moments_toml, tuned_toml, write
from .moment_search import tune_all
from . import blackbox


@dataclass
class TuneConfig:
    """A tune run: the experiment Config, its checked ``[tune]`` spec and the scheme instances to tune."""
    config: object       # the experiment Config (scenes, lights, map)
    spec: TuneSpec
    schemes: tuple       # the SchemeSpecs to tune (the config's [[scheme]] instances)


def parse_tune(cfg) -> TuneConfig:
    """The tune run of an experiment config: its ``[tune]`` spec (read with the config, its defaults
    without one) and what dsm tune refuses of the rest (ConfigError naming file, key and choices),
    checked before any work; the schemes to tune are the config's ``[[scheme]]`` instances."""
    spec = cfg.tune if getattr(cfg, "tune", None) is not None else tune_spec({}, cfg.source, cfg.seed, cfg.schemes)
    if spec.search == "optuna":
        blackbox.require_optuna(cfg.source)
    _check_lights_and_kinds(cfg)
    _check_schemes(cfg, spec)
    _check_map(cfg)
    return TuneConfig(cfg, spec, tuple(cfg.schemes))


def _check_lights_and_kinds(cfg):
    """The objective and oracles count a hard V*, one ray per receiver (pre-filtered kinds too:
    dsm.tune.moments)."""
    from .. import lights as light_types
    src = cfg.source
    for i, light in enumerate(cfg.lights):
        if light.type in light_types.REGISTRY and light_types.is_soft(light):
            raise ConfigError(src, f"light[{i}].type", "dsm tune's objective and oracles are those of a hard V* "
                              "(one ray per receiver); an area light's reference is a fraction: remove it (dsm run "
                              "measures it)", tuple(t for t in light_types.REGISTRY if t != light.type))


def _check_schemes(cfg, spec: TuneSpec):
    """Every [[scheme]] a shadow-map scheme with a continuous parameter, no preset, each tuned one from a finite start."""
    from ..schemes import get
    src = cfg.source
    for i, s in enumerate(cfg.schemes):
        if s.preset is not None:
            raise ConfigError(src, f"scheme[{i}].preset", "dsm tune tunes scheme parameters, not presets: give "
                              "the combined scheme with the preset's values (dsm schemes lists them)")
        if get(s.name).VIEWS is not None:      # a VSV lookup (dsm.maps.vsv): no depth map to tune on
            raise ConfigError(src, f"scheme[{i}].name", f"{s.name} reads a voxelized shadow volume; dsm tune tunes "
                              "shadow-map schemes", _tunable_names())
        if not tunable(get(s.name)):
            raise ConfigError(src, f"scheme[{i}].name", f"{s.name} has no continuous parameter to tune",
                              _tunable_names())
    for i, s in enumerate(cfg.schemes):
        for p in spec.params[s.name]:
            v = getattr(s.params, p)
            if not math.isfinite(v.value if isinstance(v, Length) else v):
                raise ConfigError(src, f"scheme[{i}].{p}", f"{s.name}.{p} starts at {v}: give a finite start to tune "
                                  f"it, or leave it out of tune.params.{s.name}", spec.params[s.name])


def _check_map(cfg):
    """One map per scene and light, fixed across views, read by the nearest lookup (the oracles')."""
    src, m = cfg.source, cfg.map
    for key, vals in (("map.resolution", m.resolutions_for(1)), ("map.format", m.format)):
        if len(vals) != 1:
            raise ConfigError(src, key, f"dsm tune fits one map per scene and light: give one value, got {list(vals)}")
    if getattr(m, "cascade", ()):
        raise ConfigError(src, "map.cascades", "dsm tune fits one map per scene and light fixed across views; "
                          "a cascaded view follows its camera: remove the cascades")
    if getattr(m, "virtual", ()):
        raise ConfigError(src, "map.virtual", "dsm tune fits one map per scene and light fixed across views; "
                          "a virtual shadow map's levels and pages follow its camera: remove [map.virtual]")
    if any(s.samples > 1 for s in m.moments):
        raise ConfigError(src, "map.moment_samples", "dsm tune builds each moment map from its one map of one ray "
                          "a texel: remove it (dsm run measures supersampled moments)")
    if m.filter != ("nearest",):
        raise ConfigError(src, "map.filter", "dsm tune measures the nearest lookup (the oracles' lookup)",
                          ("nearest",))


def _tunable_names():
    """The registered schemes dsm tune can tune (the choices its refusals name)."""
    from ..schemes import REGISTRY
    return [s.NAME for s in REGISTRY if tunable(s)]


# ---------------------------------------------------------------- the whole run

def tune(config, out=None, progress: bool = False, variant: str | None = None, resume: bool = False,
         force: bool = False) -> TuneResult:
    """Tune every ``[[scheme]]`` of ``config`` (a Config, dict or TOML path with a ``[tune]``
    table) on its training views; write the results into ``out`` when given, under dsm tune's
    rules for ``--out`` (locked; a non-empty folder refused unless ``resume`` goes on with the
    tune there, keeping its finished schemes, or ``force`` replaces a previous tune)."""
    from ..config.read import coerce
    from ..experiment.lock import api_words, claim
    from .folder import tune_folder
    if force and resume:
        raise ConfigError("dsm.tune", "force", "force=True replaces a tune and resume=True goes on with it: give one")
    config = coerce(config)
    tc = parse_tune(config)                   # the [tune] table checked before any scene loads
    tc.config = pl.prepare(config, variant)
    if out is None:
        return run_tune(tc, None, progress)
    out = Path(out)
    held, problem = claim(out)
    if problem:
        raise ConfigError("dsm.tune", "out", api_words(problem))
    with held:
        problem, resuming = tune_folder(out, tc.config.name, force, resume)
        if problem:
            raise ConfigError("dsm.tune", "out", api_words(problem))
        return run_tune(tc, out, progress, resuming)


def run_tune(tc, out=None, progress: bool = False, resume: bool = False) -> TuneResult:
    """Tune and grid-search each scheme of a prepared ``tc``, then the bias map; write into ``out``
    if given, with the state ``--resume`` reads after each scheme (``resume``: keep its finished ones)."""
    ts = tc.spec
    bar = _progress_bar(tc) if progress else None
    tick = (lambda *a: bar.update(1)) if bar else None
    if ts.bias_map and ts.bias_map.fit in ("residual", "edge") and not tc.schemes:
        # its base is the best tuned depth scheme: pre-filtered instances alone have none
        raise ConfigError(tc.config.source, "tune.bias_map.fit", f"{ts.bias_map.fit} learns a map over the best tuned "
                          "depth scheme and this tune has none ([[scheme]] or [tune.params] of a depth scheme): add "
                          "one, or give fit = \"adam\"", ("adam",))
    groups, cases, notes = prepare_cases(tc, tick)
    if not tc.spec.cameras:
        notes.insert(0, "no [[tune.camera]]: the scene's own camera is the one training view, nothing is held out")
    train = [c for c in cases if c.role == "train"]
    held = [c for c in cases if c.role == "heldout"]
    if ts.bias_map and ts.bias_map.fit == "edge" and ts.bias_map.samples and held:
        light_samples.check_budget(groups, ts.bias_map.samples, tc.config.source)
    if not train:
        raise ConfigError(tc.config.source, "tune.camera", "no training view has a receiver")
    n_train, n_held = sum(c.n for c in train), sum(c.n for c in held)
    if ts.bias_map and ts.bias_map.fit == "residual":
        residual_map.check_budget(n_train, ts.bias_map.radii, tc.config.source)
    if ts.batch * n_train < 1.0:            # every Adam step would draw no receiver: a gradient of 0
        raise ConfigError(tc.config.source, "tune.batch", f"{ts.batch:g} of the {n_train} training receivers is "
                          f"less than one a step: at least {1.0 / n_train:.3g} (1 draws them all)")
    th_train, vs_train = pooled_thresholds(train, groups)
    orc_train = pl.oracles(th_train, vs_train, ts.lam)["row"]
    orc_held = pl.oracles(*pooled_thresholds(held, groups), ts.lam)["row"] if held else None
    results, steps, comparison, kept = _tune_schemes(tc, train, held, groups, orc_train, out, resume, tick)
    notes += [f"{e['scheme']} {e['start']}: the start of {', '.join(e['start_outside_box'])} lies outside its "
              "[tune.range] box, so the search began from it clipped into the box and may end worse than the start"
              for e in results if e.get("start_outside_box")]
    notes += _against_references(results)
    if out is not None and not tc.schemes:     # a tune of pre-filtered instances alone: --resume finds it
        tune_resume.write_state(out, tc.config.name, [])
    moments, moment_steps, moment_notes = tune_all(tc, train, held, groups, orc_train, tick)
    steps += moment_steps
    notes += moment_notes
    bmap = None
    if ts.bias_map and held:
        bmap = _learned_map(tc, train, held, groups, results, orc_train, orc_held, bar)
        steps += bmap["steps"]
    elif ts.bias_map:
        notes.append("no held-out view has a receiver: the learned bias map was not trained")
    if bar:
        bar.close()
    res = TuneResult(results, steps, comparison, bmap, notes, n_train, n_held,
                     tuned_toml(results) + moments_toml(moments), ts, kept, moments)
    if out is not None:
        write(res, Path(out), orc_train, orc_held)
    return res


def _against_references(results) -> list:
    """A note for each scheme whose tuned values end above its grid on the training views, or above
    its start on the held-out views (the search is local; held-out views are not what it minimises)."""
    notes = []
    for e in results:
        grid, held, start = e["grid"]["objective"], e.get("heldout"), e.get("start_heldout")
        if e["train"]["objective"] > grid:
            notes.append(f"{e['scheme']} {e['start']}: tuned {e['train']['objective']:.5f} on the training views, "
                         f"above its grid's {grid:.5f}")
        if held and start is not None and held["objective"] > start:
            notes.append(f"{e['scheme']} {e['start']}: tuned {held['objective']:.5f} on the held-out views, above "
                         f"its start's {start:.5f} (fitted to the training views)")
    return notes


def _progress_bar(tc):
    """A tqdm bar over the run's steps: a scene each, ``steps`` per scheme, an Adam bias map's steps."""
    from tqdm import tqdm
    ts = tc.spec
    studies = ts.objectives if ts.search == "optuna" else 0        # Optuna's trials: as many as the steps made
    total = len(tc.config.scenes) + ts.steps * ((1 + studies) * len(tc.schemes) + len(tc.config.map.moments)) + (
        ts.bias_map.steps if ts.bias_map and ts.bias_map.fit == "adam" else 0)
    return tqdm(total=total, desc="dsm tune", unit="step", leave=False)


def _tune_schemes(tc, train, held, groups, orc_train, out, resume, tick) -> tuple:
    """Each scheme tuned (or kept from the state in ``out`` when ``resume``), the state written after
    each one: (result entries, step rows, comparison rows, number kept)."""
    ts = tc.spec
    results, steps, comparison = [], [], []
    keys = tune_resume.scheme_keys(tc)
    previous = tune_resume.read_state(out) if (resume and out is not None) else {}
    finished, kept = [], 0
    if out is not None and not resume:      # a tune stopped within its first scheme resumes too (its Optuna study)
        tune_resume.write_state(out, tc.config.name, [])
    store = blackbox.storage(out) if ts.search == "optuna" else None
    for i, (spec, key) in enumerate(zip(tc.schemes, keys)):
        # steps.csv's instance column: two instances of one scheme (texel and world constants) apart
        tag = lambda rows: [{"instance": f"{i}: {spec.name} {describe_params(spec.params)}".strip(), **r}
                            for r in rows]
        if key in previous:                 # finished by the tune in ``out`` with this very input
            entry = {**previous[key]["entry"], "spec": with_values(spec, previous[key]["entry"]["values"])}
            results.append(entry)
            steps += tag(previous[key]["steps"])
            comparison.append(_comparison_row(entry))
            finished.append(previous[key])
            kept += 1
            if out is not None:             # the state lists every finished scheme, kept ones too
                tune_resume.write_state(out, tc.config.name, finished)
            if tick:
                for _ in range(ts.steps):
                    tick()
            continue
        entry, rows = _scheme_entry(tc, spec, train, held, groups, orc_train, tick)
        if store is not None:
            entry.update(_blackbox_entries(tc, spec, entry, train, held, groups, store, key, tick))
        results.append(entry)
        steps += tag(rows)
        comparison.append(_comparison_row(entry))
        if out is not None:                 # after each scheme, so a stopped tune resumes from here
            finished.append({"key": key, "entry": {k: v for k, v in entry.items() if k != "spec"},
                             "steps": rows})
            tune_resume.write_state(out, tc.config.name, finished)
    return results, steps, comparison, kept


def _scheme_entry(tc, spec, train, held, groups, orc_train, tick) -> tuple:
    """One scheme tuned, grid-searched, scanned (and gradient-checked) with its counts on the training
    and held-out views and (constant) the exact oracle: (its result entry, its step rows)."""
    ts = tc.spec
    wall0, cpu0 = sync_clock(), time.process_time()
    with tallying() as ad_count:
        r = tune_scheme(tc, spec, train, groups, tick, {"world": orc_train["best_b"], "texel": orc_train["best_k"]})
    ad_cost = {"evaluations": ad_count.as_dict(), "wall_ms": (sync_clock() - wall0) * 1e3,
               "cpu_ms": (time.process_time() - cpu0) * 1e3}
    tuned = with_values(spec, r["values"])
    with tallying() as grid_count:
        g = grid_search(tc, spec, r["box"], train, groups, ts.steps)
    grid_spec = with_values(spec, g["values"])
    scan = exact_scan(tc, spec, r["box"], train, groups, ts.scan)
    check = gradient_check(tc, spec, r["box"], train, groups) if ts.gradcheck else None
    entry = {"scheme": spec.name, "start": describe_params(spec.params), "params": describe_params(tuned.params),
             "values": r["values"], "units": {p.name: p.unit for p in r["box"]},
             "box": {p.name: [p.lo, p.hi] for p in r["box"]}, "relaxed_lookup": r["relaxed_lookup"],
             "spec": tuned, "train": _with_obj(hard_counts(tuned, train, groups), ts.lam),
             "heldout": _with_obj(hard_counts(tuned, held, groups), ts.lam) if held else None,
             "start_train": _with_obj(hard_counts(spec, train, groups), ts.lam),
             "start_heldout": _with_obj(hard_counts(spec, held, groups), ts.lam)["objective"] if held else NAN,
             "gradcheck": check, "start_outside_box": _outside_box(spec, r["box"]),
             "scan": None if scan is None else {**scan, "params": describe_params(with_values(spec, scan["values"]).params)},
             "first_step_ms": r["first_step_ms"], "step_ms": r["step_ms"], "tune_ms": r["total_ms"],
             "ad": ad_cost, "grid_evaluations": grid_count.as_dict(),
             "grid": {**g, "params": describe_params(grid_spec.params),
                      "heldout": _with_obj(hard_counts(grid_spec, held, groups), ts.lam)["objective"]
                      if held else float("nan")}}
    if spec.name == "constant":
        unit = getattr(spec.params, "bias").unit
        tag = "texel" if unit == "texel" else "world" if unit == "world" else None
        if tag:
            entry["oracle"] = {"kind": tag, "objective": orc_train[f"{tag}_objective"],
                               "bias": orc_train["best_k" if tag == "texel" else "best_b"]}
    return entry, r["steps"]


def _outside_box(spec, box) -> list:
    """The tuned parameters whose start lies outside their search box ([tune.range]): the search
    starts from the start clipped into the box, so the result may be worse than the start."""
    return [p.name for p in box if not p.lo <= start_value(spec, p.name) <= p.hi]


def _learned_map(tc, train, held, groups, results, orc_train, orc_held, bar) -> dict:
    """The learned bias map (a residual over the best tuned scheme, or Adam from the best tuned
    constant) with its counts, the held-out split and the oracles and best global scheme it is judged by;
    ``bar``: the run's progress bar or None (a step per Adam step, or per chunk of light samples)."""
    ts = tc.spec
    tick = (lambda *a: bar.update(1)) if bar else None
    const = [e for e in results if e["scheme"] == "constant"]
    best_const = min(const, key=lambda e: e["train"]["objective"]) if const else None
    best = min(results, key=lambda e: e["train"]["objective"]) if results else None
    if bar and best is not None and ts.bias_map.fit == "edge" and ts.bias_map.samples and \
            not reads_camera(best["spec"]):
        bar.total += sum(len(light_samples.chunks(g, ts.bias_map.samples)) for g in groups)
        bar.refresh()
    if ts.bias_map.fit in ("residual", "edge") and best is not None:
        bmap = (residual_bias_map(tc, train, held, groups, best) if ts.bias_map.fit == "residual"
                else edge_bias_map(tc, train, held, groups, best, tick))
        bmap["init_from"] = bmap["base"]
    else:
        init = map_start(tc, train, groups, best_const)
        bmap = tune_bias_map(tc, train, held, groups, init, tick)
        bmap["init_from"] = best_const["params"] if best_const else str(ts.bias_map.init)
    bmap["train"] = _with_obj(bmap["train"], ts.lam)
    bmap["heldout"] = _with_obj(bmap["heldout"], ts.lam)
    lit, covered = bmap.pop("heldout_lit"), bmap.pop("heldout_covered")
    if "train_shared" in bmap:
        bmap["train_shared"] = _with_obj(bmap["train_shared"], ts.lam)
        bmap["heldout_shared"] = _with_obj(bmap["heldout_shared"], ts.lam)
    if best is not None:
        bmap["heldout_split"] = heldout_split(held, groups, lit, covered, best["spec"], ts.lam, bmap.pop("refits", None),
                                              bmap.pop("heldout_lit_shared", None))
    bmap["per_texel_oracle_heldout"] = orc_held["per_texel_objective"]
    bmap["per_texel_oracle_train"] = orc_train["per_texel_objective"]
    bmap["best_global"] = ({"scheme": best["scheme"], "params": best["params"],
                            "heldout": best["heldout"]["objective"], "train": best["train"]["objective"]}
                           if best else None)
    return bmap


def _blackbox_entries(tc, spec, entry, train, held, groups, store, key, tick=None) -> dict:
    """Optuna's studies of one scheme over the AD tuner's box, at the number of exact evaluations the AD
    tuner made: TPE on the objective, and (two objectives) NSGA-II's Pareto front with the AD tuner's point."""
    ts, box = tc.spec, _box_of(entry, spec)
    trials = entry["ad"]["evaluations"]["exact"]
    on_trial = (lambda n: tick()) if tick else None
    tpe = blackbox.study(tc, spec, box, train, groups, trials, store, f"{key}-tpe", on_trial=on_trial)
    best = blackbox.best_trial(tpe)
    found = with_values(spec, best["values"])
    out = {"optuna": {"sampler": "TPE", "trials": trials, "values": best["values"], "trial": best["number"],
                      "params": describe_params(found.params),
                      "train": _with_obj(hard_counts(found, train, groups), ts.lam),
                      "heldout": _with_obj(hard_counts(found, held, groups), ts.lam) if held else None,
                      "evaluations": tpe["evaluations"], "wall_ms": tpe["wall_ms"], "cpu_ms": tpe["cpu_ms"]}}
    if ts.objectives == 2:
        nsga = blackbox.study(tc, spec, box, train, groups, trials, store, f"{key}-nsga2", objectives=2,
                              on_trial=on_trial)
        n = max(entry["train"]["n_receivers"], 1)
        ad_point = [entry["train"]["n_acne"] / n, entry["train"]["n_peterpan"] / n]
        front = blackbox.pareto_front(nsga)
        out["optuna_front"] = {"sampler": "NSGA-II", "trials": trials,
                               "population": blackbox.population_size(trials),
                               "front": [{"values": t["values"], "acne_per_receiver": t["objectives"][0],
                                          "peterpan_per_receiver": t["objectives"][1]} for t in front],
                               "ad_point": {"lambda": ts.lam, "acne_per_receiver": ad_point[0],
                                            "peterpan_per_receiver": ad_point[1],
                                            "dominated": any(t["objectives"][0] <= ad_point[0] and
                                                             t["objectives"][1] <= ad_point[1] and
                                                             t["objectives"] != ad_point for t in front)},
                               "evaluations": nsga["evaluations"], "wall_ms": nsga["wall_ms"],
                               "cpu_ms": nsga["cpu_ms"]}
    return out


def _box_of(entry, spec) -> list:
    """The AD tuner's search box of a result entry, as Params (names, units, ranges and the start clipped
    into them, as it searched)."""
    from .search import Param
    return [Param(n, entry["units"][n], min(max(start_value(spec, n), lo), hi), 1.0, lo, hi)
            for n, (lo, hi) in entry["box"].items()]


def _with_obj(counts, lam):
    return {**counts, "objective": objective(counts, lam)}


def _comparison_row(e):
    g = e["grid"]
    ad = e.get("ad") or {}
    row = {"scheme": e["scheme"], "tuned_params": e["params"], "tuned_train": e["train"]["objective"],
           "tuned_heldout": e["heldout"]["objective"] if e["heldout"] else float("nan"),
           "tuned_ms": e["tune_ms"], "tuned_evaluations": (ad.get("evaluations") or {}).get("exact", NAN),
           "tuned_relaxed_evaluations": (ad.get("evaluations") or {}).get("relaxed", NAN),
           "tuned_line_searches": (ad.get("evaluations") or {}).get("line", NAN),
           "tuned_wall_ms": ad.get("wall_ms", NAN), "tuned_cpu_ms": ad.get("cpu_ms", NAN),
           "first_step_ms": e["first_step_ms"],
           "step_ms": e["step_ms"],
           "grid_params": g["params"], "grid_train": g["objective"], "grid_heldout": g["heldout"],
           "grid_ms": g["total_ms"], "grid_evaluations": g["evaluations"],
           "oracle": e.get("oracle", {}).get("objective", float("nan")),
           "start_train": e["start_train"]["objective"], "start_heldout": e["start_heldout"],
           "scan_params": e["scan"]["params"] if e["scan"] else "-",
           "scan_train": e["scan"]["objective"] if e["scan"] else NAN,
           "scan_evaluations": e["scan"]["evaluations"] if e["scan"] else 0}
    if e.get("optuna"):
        o = e["optuna"]
        row.update({"optuna_params": o["params"], "optuna_train": o["train"]["objective"],
                    "optuna_heldout": o["heldout"]["objective"] if o["heldout"] else NAN,
                    "optuna_evaluations": o["evaluations"]["exact"], "optuna_wall_ms": o["wall_ms"],
                    "optuna_cpu_ms": o["cpu_ms"]})
    return row
