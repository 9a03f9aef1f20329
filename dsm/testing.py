"""What a user's test file needs to hold a shadow scheme to a threshold (pytest or plain asserts).

Each helper filters a run's Results as ``Results.where`` does (a filter that matches nothing raises,
naming what there is: a threshold can never pass on no case), checks every matching case, and on
failure raises AssertionError listing the offending cases with their rates, scene, light, view,
resolution and the path of their error image::

    from dsm.testing import assert_rate, assert_no_worse_than, assert_oracle_gap

    def test_my_scene(dsm_results):                     # the fixture of dsm's pytest plugin
        res = dsm_results("my_scene.toml")              # run once per test session
        assert_rate(res, "acne_rate", below=0.01, scheme="receiver_plane")
        assert_no_worse_than(res, "error_rate", "adaptive", than="constant", than_params="bias=2 texel")
        assert_oracle_gap(res, below=0.005, scheme="adaptive")

A rate whose denominator is empty (no truly lit receiver for acne_rate, ...) is undefined: it fails
a threshold unless ``allow_undefined=True`` (it says nothing about the scheme).
"""
from __future__ import annotations

import math
import numbers

from .core import record
from .core.suggest import did_you_mean, valid_words
from .report import figures

SITUATION = ("scene", "light", "view", "resolution", "filter", "format", "cascade_layout")
ORACLES = ("world", "texel", "per_texel")


def _where_text(r: dict) -> str:
    return (f"{r['scene']}, {r['light']}, {r['view']}, R={r['resolution']}, {r['scheme']} {r['params']}, "
            f"{r['filter']}, {r['format']}")


def _image(res, r: dict) -> str:
    path = res.out / figures.image_paths(r)[0]
    return str(path) if path.is_file() else "no image file"


def _numeric(fn: str, column: str, rows: list):
    """Raise where ``column`` is no numeric column of a run's rows (misspelt, or text such as scheme),
    naming the valid ones: a KeyError or a comparison of text told nothing."""
    __tracebackhide__ = True       # a failure shows the user's test line, not dsm.testing's own
    if not isinstance(column, str):
        raise TypeError(f"{fn}: column must be a column name (text), got {column!r}")
    known = [c for c in record.NAMES if c not in record.TEXT_COLUMNS]
    known.sort(key=lambda c: not c.endswith("_rate"))      # the rates first: what a threshold is usually of
    known += sorted({k for r in rows for k, v in r.items() if k not in record.NAMES and _is_number(v)})
    if column in record.TEXT_COLUMNS:
        raise TypeError(f"{fn}: {column!r} is a text column; give a numeric one ({', '.join(known[:12])}, ...)")
    if column not in known:
        raise ValueError(f"{fn}: no column {column!r} ({did_you_mean(column, known)}numeric columns: "
                         f"{', '.join(known[:10])}, ... every one: dsm.core.record.NAMES)")


def _is_number(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def _threshold(fn: str, name: str, value):
    """Raise where a threshold is no finite number: text would compare as a TypeError, NaN would pass
    every comparison written ``not a > b``."""
    __tracebackhide__ = True       # a failure shows the user's test line, not dsm.testing's own
    if value is None:
        return
    if not _is_number(value):
        raise TypeError(f"{fn}: {name} must be a number, got {value!r} ({type(value).__name__})")
    if not math.isfinite(value):
        raise ValueError(f"{fn}: {name} = {value!r}; give a finite number")


def _fail(title: str, lines: list, most: int = 20):
    __tracebackhide__ = True       # a failure shows the user's test line, not dsm.testing's own
    more = [f"  ... and {len(lines) - most} more"] if len(lines) > most else []
    raise AssertionError("\n".join([title] + lines[:most] + more))


def assert_rate(res, column: str, below: float | None = None, above: float | None = None, *,
                allow_undefined: bool = False, **where):
    """Every case ``where`` selects has ``column`` below ``below`` (strictly) and/or at least ``above``."""
    __tracebackhide__ = True       # a failure shows the user's test line, not dsm.testing's own
    if below is None and above is None:
        raise TypeError("assert_rate: give below=, above= or both")
    for name, value in (("below", below), ("above", above)):
        _threshold("assert_rate", name, value)
    if not res.rows:
        raise ValueError("assert_rate: the Results hold no case; a threshold cannot pass on no case")
    rows = res.where(**where).rows
    _numeric("assert_rate", column, rows)
    bad = []
    for r in rows:
        v = r[column]
        if v != v:
            if not allow_undefined:
                bad.append(f"  case {r['case']}: {column} undefined (empty denominator) ({_where_text(r)}) "
                           f"image {_image(res, r)}")
            continue
        if (below is not None and not v < below) or (above is not None and not v >= above):
            bad.append(f"  case {r['case']}: {column} = {v:.6g} ({_where_text(r)}) image {_image(res, r)}")
    if bad:
        bounds = " and ".join(b for b in (f"< {below:g}" if below is not None else "",
                                          f">= {above:g}" if above is not None else "") if b)
        _fail(f"{column} {bounds} fails in {len(bad)} of {len(rows)} cases ({where or 'every case'}):", bad)


def assert_no_worse_than(res, column: str, scheme: str, than: str, *, params: str | None = None,
                         than_params: str | None = None, tolerance: float = 0.0, **where):
    """In every situation (scene, light, view, resolution, filter, format, cascade layout) ``where``
    selects, ``scheme``'s ``column`` is at most ``than``'s plus ``tolerance`` (one instance each:
    ``params`` / ``than_params`` pick it where the scheme is swept)."""
    __tracebackhide__ = True       # a failure shows the user's test line, not dsm.testing's own
    if tolerance is None:
        raise TypeError("assert_no_worse_than: tolerance must be a number (0: no worse at all), got None")
    _threshold("assert_no_worse_than", "tolerance", tolerance)
    pick = lambda name, prm: res.where(scheme=name, **({"params": prm} if prm else {}), **where).rows
    mine, theirs = pick(scheme, params), pick(than, than_params)
    _numeric("assert_no_worse_than", column, mine)
    ref = {}
    for r in theirs:
        key = tuple(r.get(k) for k in SITUATION)
        if key in ref:
            raise ValueError(f"assert_no_worse_than: {than} has several instances in one situation; give "
                             "than_params= to pick one")
        ref[key] = r
    bad, compared = [], 0
    for r in mine:
        o = ref.get(tuple(r.get(k) for k in SITUATION))
        if o is None:
            continue
        compared += 1
        a, b = r[column], o[column]
        if a != a or b != b or a > b + tolerance:
            bad.append(f"  case {r['case']} against {o['case']}: {column} {a:.6g} > {b:.6g} + {tolerance:g} "
                       f"({_where_text(r)}) image {_image(res, r)}")
    if not compared:
        raise ValueError(f"assert_no_worse_than: {scheme} and {than} share no situation among the selected cases")
    if bad:
        _fail(f"{scheme} is worse than {than} on {column} in {len(bad)} of {compared} situations:", bad)


def assert_oracle_gap(res, below: float, *, oracle: str = "world", **where):
    """Every nearest-filter case ``where`` selects errs at most ``below`` above the ``oracle``
    (world: the best single bias of its map; texel: the best single texel bias; per_texel: the
    best bias per texel) of its map and stored format, both as E = (acne + peter-panning) /
    receivers at lambda 1."""
    __tracebackhide__ = True       # a failure shows the user's test line, not dsm.testing's own
    if oracle not in ORACLES:
        raise ValueError(f"assert_oracle_gap: oracle={oracle!r} ({valid_words(oracle, ORACLES)})")
    _threshold("assert_oracle_gap", "below", below)
    keys = ("scene", "light", "view", "resolution", "culling", "format")
    floors = {tuple(o[k] for k in keys): o[f"{oracle}_objective"] for o in res.oracle if o.get("lambda", 1.0) == 1.0}
    rows = [r for r in res.where(filter="nearest", **where).rows if tuple(r[k] for k in keys) in floors]
    if not rows:
        raise ValueError("assert_oracle_gap: no selected case has an oracle (nearest filter, a depth map's "
                         "hard shadow)")
    bad = []
    for r in rows:
        e = (r["n_acne"] + r["n_peterpan"]) / r["n_receivers"] if r["n_receivers"] else math.nan
        floor = floors[tuple(r[k] for k in keys)]
        if not e - floor <= below:
            bad.append(f"  case {r['case']}: E = {e:.6g}, {oracle} oracle {floor:.6g}, gap {e - floor:.6g} "
                       f"({_where_text(r)}) image {_image(res, r)}")
    if bad:
        _fail(f"the gap to the {oracle} oracle exceeds {below:g} in {len(bad)} of {len(rows)} cases:", bad)
