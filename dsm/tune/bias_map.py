"""The learned bias map: one bias per block of map texels, by Adam or as a residual over the best scheme, or
predicted per receiver from the map around it (dsm.tune.edge_map)."""
from __future__ import annotations

import dataclasses
import math

import drjit as dr
import mitsuba as mi
import numpy as np

from ..maps import lookup
from ..report.tables import objective
from .. import pipeline as pl
from ..schemes import get as get_scheme
from ..core.types import SchemeSpec
from .evaluate import NAN, counts, sync_clock
from .relax import margins, relaxed_sum
from .cases import pooled_thresholds
from .search import BETA1, BETA2, temperature_at, texel_sizes


# ---------------------------------------------------------------- learned bias map

def _blocks(cases, groups, block):
    """Per case the block index (unique across maps) of each receiver's nearest texel; the
    number of blocks."""
    offs, total = [], 0
    for g in groups:
        R = g.view.resolution
        nb = -(-R // block)
        offs.append((total, R, nb))
        total += g.view.faces * nb * nb
    out = []
    for c in cases:
        base, R, nb = offs[c.group]
        t = c.th.texel
        face, rest = t // (R * R), t % (R * R)
        i, j = rest % R, rest // R
        out.append(base + (face * nb + j // block) * nb + i // block)
    return out, total


def _map_margin(c, groups, bias_world):
    smap = groups[c.group].maps["none"]
    tap = lookup.nearest_tap(c.rx, smap)
    return tap.z1 + bias_world - c.rx.depth


def map_start(tc, train, groups, const=None) -> np.ndarray:
    """The bias map's start per map (group), in the map's unit: the best tuned constant bias
    (``const``, a result entry) converted with the group's mean texel width over its training
    receivers, so a block no training view sees keeps the tuned global bias; without one,
    ``[tune.bias_map] init``."""
    bm = tc.spec.bias_map
    out = np.full(len(groups), bm.init.value, np.float64)
    if const is None:
        return out
    b = const["spec"].params.bias
    for g in range(len(groups)):
        tws = [c.th.texel_world for c in train if c.group == g]
        tw = float(np.mean(np.concatenate(tws))) if tws else float(texel_sizes(train, groups)["world"])
        world = b.value * {"world": 1.0, "texel": tw, "range": groups[g].view.depth_range}[b.unit]
        out[g] = world if bm.unit == "world" else world / tw
    return out


def tune_bias_map(tc, train, held, groups, init_values, progress=None) -> dict:
    """Adam on one bias per block (started per map at ``init_values``, in the map's unit)."""
    bm, ts = tc.spec.bias_map, tc.spec
    blk_train, nblocks = _blocks(train, groups, bm.block)
    blk_held, _ = _blocks(held, groups, bm.block)
    scale = texel_sizes(train, groups)[bm.unit]      # steps in texels' worth, as the schemes'
    opt = mi.ad.Adam(lr=bm.lr, beta_1=BETA1, beta_2=BETA2)
    per_group = [g.view.faces * (-(-g.view.resolution // bm.block)) ** 2 for g in groups]
    start = np.repeat(np.asarray(init_values, np.float64), per_group)
    opt["b"] = mi.Float((start / scale).astype(np.float32))
    idx_train = [mi.UInt32(b.astype(np.uint32)) for b in blk_train]
    tex = bm.unit == "texel"
    rows = []

    def bias(c, idx, b):
        """Case ``c``'s bias in world units: block values ``b`` at ``idx`` (a texel map's times texel_world)."""
        val = dr.gather(mi.Float, b, idx) * scale
        return val * c.rx.texel_world if tex else val

    lo = min(0.0, float(start.min()))                # a bias map never goes below 0 unless started there
    for step in range(bm.steps):
        t_texels = temperature_at(ts, step, bm.steps)
        opt.set_learning_rate(bm.lr * t_texels / ts.temperature[0])
        t0 = sync_clock()
        b = opt["b"]
        total = 0.0
        tt = dr.opaque(mi.Float, t_texels)
        for c, idx in zip(train, idx_train):
            total = total + relaxed_sum(_map_margin(c, groups, bias(c, idx, b)), c.rx, c.v_star_dr, tt, ts.lam)
        loss = total / max(sum(c.n for c in train), 1)
        dr.backward(loss)
        opt.step()
        opt["b"] = dr.maximum(opt["b"], lo / scale)
        dr.eval(opt["b"])
        ms = (sync_clock() - t0) * 1e3
        hard = objective(_map_counts(train, idx_train, groups, opt["b"], scale, tex), ts.lam)
        rows.append({"scheme": "bias_map", "step": step, "temperature_texel": t_texels,
                     "loss": float(loss.numpy().ravel()[0]), "hard_objective": hard, "time_ms": ms})
        if progress:
            progress()
    b = opt["b"]
    seen = np.zeros(nblocks, bool)
    for x in blk_train:
        seen[x] = True
    idx_held = [mi.UInt32(x.astype(np.uint32)) for x in blk_held]
    cov_n = sum(int(seen[x].sum()) for x in blk_held)
    n_held = sum(c.n for c in held)
    times = [r["time_ms"] for r in rows]
    return {"values": np.asarray(b.numpy(), np.float64) * scale, "blocks": nblocks, "block": bm.block,
            "unit": bm.unit, "init": [float(x) for x in init_values], "steps": rows,
            "train": _map_counts(train, idx_train, groups, b, scale, tex),
            "heldout": _map_counts(held, idx_held, groups, b, scale, tex),
            "heldout_lit": _map_lit(held, idx_held, groups, b, scale, tex),
            "heldout_covered": [seen[x] for x in blk_held],
            "heldout_covered_fraction": cov_n / n_held if n_held else float("nan"),
            "blocks_trained": int(seen.sum()),
            "first_step_ms": times[0], "step_ms": float(np.median(times[1:])) if len(times) > 1 else times[0],
            "total_ms": float(sum(times))}


def _map_lit(cases, idxs, groups, b, scale, tex) -> list:
    """Per case whether each receiver is lit under the bias map ``b``."""
    out = []
    for c, idx in zip(cases, idxs):
        val = dr.gather(mi.Float, dr.detach(b), idx) * scale
        out.append((_map_margin(c, groups, val * c.rx.texel_world if tex else val) >= 0).numpy())
    return out


def _map_counts(cases, idxs, groups, b, scale, tex) -> dict:
    acne = pp = n = lit = 0
    for c, on in zip(cases, _map_lit(cases, idxs, groups, b, scale, tex)):
        acne += int((c.v_star & ~on).sum())
        pp += int((~c.v_star & on).sum())
        n += c.n
        lit += int(c.v_star.sum())
    return counts(acne, pp, n, lit)


def margin_arrays(spec: SchemeSpec, cases, groups) -> dict:
    """A scheme instance's exact margins and what a residual map reads, per receiver over ``cases``
    (numpy: m, v_star, unit = texel_world, texel, group, resolution)."""
    mod, culling = get_scheme(spec.name), pl.culling_of(spec.params)
    ms = [np.asarray(margins(mod, spec.params, {}, c.rx, groups[c.group].maps[culling], False).numpy(), np.float64)
          for c in cases]
    cat = lambda xs: np.concatenate(xs) if xs else np.zeros(0)
    return {"m": cat(ms), "v_star": cat([c.v_star for c in cases]).astype(bool),
            "unit": cat([c.th.texel_world for c in cases]).astype(np.float64),
            "texel": cat([c.th.texel for c in cases]).astype(np.int64),
            "group": cat([np.full(c.n, c.group, np.int64) for c in cases]).astype(np.int64),
            "resolution": cat([np.full(c.n, groups[c.group].view.resolution, np.int64) for c in cases]).astype(np.int64)}


def residual_bias_map(tc, train, held, groups, base) -> dict:
    """The residual map over the best global scheme (``base``, a result entry): candidates
    validated leaving one training camera out, the chosen one fitted to every training view
    (dsm.tune.residual_map); its counts on the training and held-out views."""
    from . import residual_map as rm
    bm, lam = tc.spec.bias_map, tc.spec.lam
    t0 = sync_clock()
    rx_tr, rx_he = margin_arrays(base["spec"], train, groups), margin_arrays(base["spec"], held, groups)
    cams = np.concatenate([np.full(c.n, c.camera) for c in train])
    ch = rm.choose(rx_tr, cams, bm.blocks, bm.radii, bm.gains, lam, bm.margin)
    block, radius, gain = ch["chosen"] or (bm.blocks[0], 0, math.inf)      # none: coverage by the first block
    fit = rm.smoothed_fit(rx_tr, block, radius, lam, bm.margin)
    m_tr, _ = rm.apply(fit, gain, rx_tr, block)
    m_he, covered = rm.apply(fit, gain, rx_he, block)
    moved = rm.residuals(fit, gain)
    counted = lambda m, v: counts(int(((m < 0) & v).sum()), int(((m >= 0) & ~v).sum()), int(v.size), int(v.sum()))
    return {"fit": "residual", "base": f"{base['scheme']} {base['params']}", "block": block, "radius": radius,
            "min_gain": gain if ch["chosen"] else None, "chosen": ch["chosen"] is not None,
            "validation": {"none": ch["none"], "scores": ch["scores"]}, "unit": "texel",
            "values": np.stack([fit["keys"].astype(np.float64), moved]), "blocks": int(fit["keys"].size),
            "blocks_trained": int(fit["keys"].size), "blocks_moved": int((moved != 0).sum()), "steps": [],
            "train": counted(m_tr, rx_tr["v_star"]), "heldout": counted(m_he, rx_he["v_star"]),
            **_heldout_fields(m_he >= 0, covered, held, t0)}


def neighbour_margins(spec: SchemeSpec, cases, groups) -> dict:
    """What the edge map reads, per receiver over ``cases`` (numpy): the scheme's margin with the z1
    of each of the 3 x 3 texels around its (shifted) lookup point (``m9``, world units, columns in
    edge_map.OFFSETS order), that point from its texel's centre (``fx, fy``, texels), ``unit`` =
    texel_world, ``cos`` (normal to light), ``v_star``, and block keys' inputs (texel, group, resolution)."""
    from .edge_map import OFFSETS
    mod, culling = get_scheme(spec.name), pl.culling_of(spec.params)
    acc = {k: [] for k in ("m9", "fx", "fy", "cos")}
    for c in cases:
        smap = groups[c.group].maps[culling]
        prm = lookup.resolve(spec.params, c.rx)
        rx2 = mod.shift(c.rx, prm)
        i0, j0 = dr.floor(rx2.u_map), dr.floor(rx2.v_map)
        taps = [lookup.tap_at(rx2, smap, i0 + 0.5 + a, j0 + 0.5 + b) for a, b in OFFSETS]
        acc["m9"].append(np.stack([np.asarray(mod.margin(rx2, t, prm).numpy(), np.float64) for t in taps], 1))
        acc["fx"].append(np.asarray((rx2.u_map - i0).numpy(), np.float64) - 0.5)
        acc["fy"].append(np.asarray((rx2.v_map - j0).numpy(), np.float64) - 0.5)
        n, l = c.rx.n_world, c.rx.to_light
        acc["cos"].append(np.asarray(dr.dot(n, l).numpy(), np.float64))
    out = {k: np.concatenate(v) if v else np.zeros((0, 9) if k == "m9" else 0) for k, v in acc.items()}
    base = margin_arrays(spec, cases, groups)
    return {**out, **{k: base[k] for k in ("unit", "v_star", "texel", "group", "resolution")}}


def edge_bias_map(tc, train, held, groups, base, tick=None) -> dict:
    """The edge map over the best global scheme (``base``, a result entry): its shape parameters
    and threshold fitted exactly to the training receivers (dsm.tune.edge_map), then per texel an
    offset fitted to the light's own samples (``samples`` > 0); its counts on the training and
    held-out views with and without the offsets, held-out receivers counted as covered where their
    ``block`` block saw training receivers (the other fits' split, so the three compare); ``tick`` after
    each chunk of light samples."""
    from . import edge_map as em
    from . import residual_map as rm
    bm, lam = tc.spec.bias_map, tc.spec.lam
    t0 = sync_clock()
    rx_tr, rx_he = neighbour_margins(base["spec"], train, groups), neighbour_margins(base["spec"], held, groups)
    model = em.fit(rx_tr, bm.widths, bm.clips, bm.grazings, lam)
    x_tr, x_he = em.over_threshold(rx_tr, model), em.over_threshold(rx_he, model)
    offsets = light_offsets(tc, groups, base, model, tick) if bm.samples else None
    fitted_keys, fitted = (offsets["keys"], offsets["offsets"]) if offsets else (np.zeros(0, np.int64), np.zeros(0))
    offset_of = lambda rx: em.offset_at(fitted_keys, fitted, rm.block_keys(rx["texel"], rx["group"], rx["resolution"], 1))
    lit_tr, lit_he = x_tr + offset_of(rx_tr) >= 0, x_he + offset_of(rx_he) >= 0
    keys = lambda rx: rm.block_keys(rx["texel"], rx["group"], rx["resolution"], bm.block)
    covered = np.isin(keys(rx_he), keys(rx_tr))
    counted = lambda on, v: counts(int((~on & v).sum()), int((on & ~v).sum()), int(v.size), int(v.sum()))
    params = {k: model[k] for k in ("width", "clip", "grazing", "threshold")}
    judged = _heldout_fields(lit_he, covered, held, t0)      # its time before the refits
    split = np.cumsum([c.n for c in held])[:-1]
    return {"fit": "edge", "base": f"{base['scheme']} {base['params']}", "block": bm.block, "model": params,
            "refits": edge_refits(rx_he, covered, bm, lam),
            "candidates": model["scores"], "unit": "score",
            "values": np.array([params[k] for k in ("width", "clip", "grazing", "threshold")]),
            "blocks": 0, "blocks_trained": 0, "steps": [],
            "offsets": None if offsets is None else {k: v for k, v in offsets.items() if k not in ("keys", "offsets")},
            "texel_offsets": np.stack([fitted_keys.astype(np.float64), fitted]) if fitted_keys.size else None,
            "train": counted(lit_tr, rx_tr["v_star"]), "heldout": counted(lit_he, rx_he["v_star"]),
            "train_shared": counted(x_tr >= 0, rx_tr["v_star"]), "heldout_shared": counted(x_he >= 0, rx_he["v_star"]),
            "heldout_lit_shared": np.split(x_he >= 0, split) if fitted_keys.size else None, **judged}


def light_offsets(tc, groups, base, model, tick=None) -> dict:
    """The edge map's per-texel offsets fitted to every group's light samples (dsm.tune.light_samples; dsm
    tune's lights are hard, so a sample's V* is one exact ray): sorted texel keys (residual_map.block_keys,
    block 1), offsets, and what was sampled, with a note where nothing could be; ``tick`` after each chunk."""
    from . import edge_map as em
    from . import light_samples
    from . import residual_map as rm
    bm = tc.spec.bias_map
    t0 = sync_clock()
    if reads_camera(base["spec"]):
        return _offsets_record(bm, np.zeros(0), np.zeros(0, bool), np.zeros(0, np.int64), t0, tc.spec.lam,
                               f"{base['scheme']} reads the camera that sees each receiver, which light samples lack")
    xs, vs, ks = [], [], []
    for g, grp in enumerate(groups):
        for c in light_samples.sample_cases(grp, g, bm.samples, bm.layers, tick):
            rx = neighbour_margins(base["spec"], [c], groups)
            xs.append(em.over_threshold(rx, model))
            vs.append(rx["v_star"])
            ks.append(rm.block_keys(rx["texel"], rx["group"], rx["resolution"], 1))
    cat = lambda a, t: np.concatenate(a) if a else np.zeros(0, t)
    return _offsets_record(bm, cat(xs, np.float64), cat(vs, bool), cat(ks, np.int64), t0, tc.spec.lam, "")


def reads_camera(spec: SchemeSpec) -> bool:
    """Whether a scheme instance reads the camera that sees each receiver (distance_normal), which light samples lack."""
    return get_scheme(spec.name).READS_CAMERA


def _offsets_record(bm, x, v, k, t0, lam: float, note: str) -> dict:
    """The offsets fitted to light samples (``x`` over the threshold, ``v`` V*, ``k`` texel keys; none: no
    offset anywhere) and what was sampled, timed since ``t0``."""
    from . import edge_map as em
    keys, off = em.fit_offsets(x, v, k, lam) if x.size else (np.zeros(0, np.int64), np.zeros(0))
    return {"keys": keys, "offsets": off, "note": note, "samples": bm.samples, "layers": bm.layers,
            "n_samples": int(x.size), "n_shadowed": int((~v).sum()), "texels": int(keys.size),
            "texels_moved": int((off != 0).sum()), "ms": (sync_clock() - t0) * 1e3}


REFIT_KEYS = ("width", "clip", "grazing", "threshold")
CROSSFIT_SPLITS = 4          # hashed halvings averaged: one halving's count moves by a few receivers


def edge_refits(rx_he: dict, covered, bm, lam: float) -> dict:
    """Per held-out subset (covered: in trained blocks; uncovered) the edge map's family fitted to
    those very receivers: ``refit``, fitted and counted on all of them (in-sample, so optimistic:
    the fewest errors any model of the family makes there), and ``crossfit``, fitted on the
    receivers of half the texels and counted on the other half, both ways, averaged over
    CROSSFIT_SPLITS halvings (what the family reaches with data from the judged views themselves).
    Objectives; NaN for an empty subset or fold."""
    from . import edge_map as em
    out = {}
    for name, sel in (("covered", covered), ("uncovered", ~covered)):
        n = int(sel.sum())
        if not n:
            out[name] = {"refit": NAN, "refit_model": None, "crossfit": NAN}
            continue
        sub = _rows(rx_he, sel)
        tents = em.tent_scores(sub, bm.widths, bm.clips)     # shared by the refit and every fold's fit
        fit = em.fit(sub, bm.widths, bm.clips, bm.grazings, lam, tents)
        out[name] = {"refit": fit["errors"] / n, "refit_model": {k: fit[k] for k in REFIT_KEYS},
                     "crossfit": _crossfit_errors(sub, tents, bm, lam) / n}
    return out


def _rows(rx: dict, sel) -> dict:
    """The receivers ``sel`` (a mask) of per-receiver arrays ``rx``."""
    return {k: np.asarray(v)[sel] for k, v in rx.items()}


def texel_fold(texel, group, split: int = 0) -> np.ndarray:
    """0 or 1 per receiver from its (map, texel) pair: halving ``split`` of the texels, a fixed
    pseudo-random one (a mixing hash's top bit), so receivers of one texel fall in one fold."""
    with np.errstate(over="ignore"):
        k = (np.asarray(texel).astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
             + np.asarray(group).astype(np.uint64) * np.uint64(0xBF58476D1CE4E5B9)
             + np.uint64(split) * np.uint64(0x94D049BB133111EB))
        k = k ^ (k >> np.uint64(31))
        k = k * np.uint64(0xD6E8FEB86659FD93)
    return (k >> np.uint64(63)).astype(np.int64)


def _crossfit_errors(rx: dict, tents: dict, bm, lam: float) -> float:
    """Errors of the family fitted on one fold of ``rx``'s texels and counted on the other, summed
    both ways, averaged over CROSSFIT_SPLITS halvings (NaN when a fold is empty); ``tents``: the
    candidates' tent scores of ``rx``'s receivers (edge_map.tent_scores)."""
    from . import edge_map as em
    totals = []
    for split in range(CROSSFIT_SPLITS):
        fold = texel_fold(rx["texel"], rx["group"], split)
        total = 0.0
        for f in (0, 1):
            on_fold = fold == f
            if on_fold.all() or not on_fold.any():
                return NAN
            model = em.fit(_rows(rx, on_fold), bm.widths, bm.clips, bm.grazings, lam,
                           {k: t[on_fold] for k, t in tents.items()})
            judge = _rows(rx, ~on_fold)
            on, v = em.lit(judge, model), judge["v_star"]
            total += float((v & ~on).sum() + lam * (~v & on).sum())
        totals.append(total)
    return float(np.mean(totals))


def _heldout_fields(lit_he, covered, held, t0) -> dict:
    """An exactly fitted map's held-out verdicts and coverage per held-out case (split as ``held``), the
    covered share, and its time since ``t0`` (no Adam start: ``init`` empty)."""
    split = np.cumsum([c.n for c in held])[:-1]
    return {"heldout_lit": np.split(lit_he, split), "heldout_covered": np.split(covered, split),
            "heldout_covered_fraction": float(covered.mean()) if covered.size else NAN,
            "init": [], "total_ms": (sync_clock() - t0) * 1e3}


def heldout_split(held, groups, lit_map, covered, best_spec, lam, refits=None, lit_shared=None) -> dict:
    """The learned map against the best global scheme and the per-texel oracle over the held-out
    receivers whose block saw training receivers (``covered``) and over the rest, with the share
    of the gap to the oracle the map closes: (global - map) / (global - oracle); with an edge map's
    ``refits`` (edge_refits), the shares its family refitted to those receivers closes beside it, and with
    ``lit_shared`` (its verdicts without per-texel offsets) that map's."""
    v = np.concatenate([c.v_star for c in held])
    lit_map, covered = np.concatenate(lit_map), np.concatenate(covered).astype(bool)
    lit_shared = None if lit_shared is None else np.concatenate(lit_shared)
    culling = pl.culling_of(best_spec.params)
    lit_best = np.concatenate([pl.visibility(best_spec, c.rx, groups[c.group].maps[culling])[0].numpy() >= 0.5
                               for c in held])
    th, vs = pooled_thresholds(held, groups)          # th.texel: texel ids unique over the maps
    out = {}
    for name, sel in (("covered", covered), ("uncovered", ~covered)):
        n = int(sel.sum())
        obj = lambda lit: float(((~lit & v)[sel].sum() + lam * (lit & ~v)[sel].sum()) / n) if n else NAN
        sub = pl.Thresholds(**{f.name: getattr(th, f.name)[sel] for f in dataclasses.fields(th)})
        orc = pl.oracles(sub, vs[sel], lam)["row"]["per_texel_objective"] if n else NAN
        g, m = obj(lit_best), obj(lit_map)
        closed = lambda x: (g - x) / (g - orc) if n and g > orc else NAN
        out[name] = {"n_receivers": n, "map": m, "best_global": g, "per_texel_oracle": orc,
                     "receivers_per_texel": n / np.unique(th.texel[sel]).size if n else NAN,
                     "gap_closed": closed(m)}
        if lit_shared is not None:
            out[name].update(shared_map=obj(lit_shared), shared_gap_closed=closed(obj(lit_shared)))
        if refits is not None:
            r = refits[name]
            out[name].update(refit=r["refit"], refit_gap_closed=closed(r["refit"]), refit_model=r["refit_model"],
                             crossfit=r["crossfit"], crossfit_gap_closed=closed(r["crossfit"]))
    return out

