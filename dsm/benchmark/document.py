"""A benchmark result document (results.json) read back and checked before any use.

``results_version`` 5 is what this dsm writes: version 4's fields, and a hybrid contender's record (dsm-bench-6
on) carries ``hybrid_rays`` (a whole number, at most its receivers) and ``ray_fraction`` (``hybrid_rays /
n_receivers``; NaN without receivers), its counts the error left after the rays. Version 4 is version 3's
fields, and every contender's record (not the oracle's) carries its case's costs in counts (``map_bytes``,
``page_table_bytes`` and ``map_rays`` whole numbers >= 0, ``taps`` a number: :mod:`dsm.case.cost`). Version 3 is
version 2's fields, and
``versions`` must name the dsm, Mitsuba and Dr.Jit versions the results were measured with (results
differ bit for bit between releases; ``dsm benchmark --compare`` says when two documents' differ). Versions 3 and 2,
and a document without ``results_version`` (version 1, written by dsm 0.2.0 and earlier, the same fields), are read
the same, their versions as recorded (dsm's own unrecorded). A newer version, and anything that is
not a results document, is refused in one line naming the file and what is wrong with it.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

from ..core.env import ENGINE        # version 3: versions.<these> are text
from .suite import SIZES, SUITE_FILES

RESULTS_VERSION = 5
READS = (1, 2, 3, 4, 5)           # the versions this dsm reads
NAMES = ("scene", "unit", "light", "contender")          # a record's identity (offset: optional, "0")
COUNTS = ("n_receivers", "n_gt_shadowed", "n_acne", "n_peterpan")   # integers where present (an oracle's: receivers)
COST_COUNTS = ("map_bytes", "page_table_bytes", "map_rays")   # version 4: every contender record's, whole
LIGHTS = ("directional", "spot", "point")                 # the suites' lights (every version's)


class NotResults(ValueError):
    """A file that is not a readable dsm benchmark results.json: the message names it and the problem."""


def read(path) -> dict:
    """The checked result document in file ``path`` (NotResults, one line, where it is not one)."""
    path = Path(path)
    if path.is_dir():
        raise NotResults(f"{path}: is a folder; give its results.json")
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise NotResults(f"{path}: no such file") from None
    except OSError as e:
        raise NotResults(f"{path}: cannot be read ({e.strerror or e})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise NotResults(f"{path}: is not UTF-8 text (a binary file, or another encoding such as UTF-16); "
                         "dsm benchmark writes results.json as UTF-8 JSON") from None
    if not text.strip():
        raise NotResults(f"{path}: is empty")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise NotResults(f"{path}: is not JSON (line {e.lineno}, column {e.colno}: {e.msg}); a truncated or "
                         "damaged file?") from None
    return check(doc, path)


def check(doc, path="<document>") -> dict:
    """``doc`` unchanged when it is a result document this dsm reads, else NotResults."""
    where = str(path)
    if not isinstance(doc, dict):
        raise NotResults(f"{where}: holds {_kind(doc)}, not a dsm benchmark results document (a JSON object)")
    if "suite" not in doc or "cases" not in doc:
        hint = " (it looks like a dsm run's run.json)" if "scheme_instances" in doc or "plan" in doc else ""
        raise NotResults(f"{where}: is not a dsm benchmark results.json: it has no "
                         f"{'suite' if 'suite' not in doc else 'cases'}{hint}")
    version = doc.get("results_version", 1)
    if version not in READS:
        raise NotResults(f"{where}: results_version {version!r}; this dsm reads versions "
                         f"{', '.join(map(str, READS))} (a newer dsm wrote it: upgrade to compare)")
    if not isinstance(doc["suite"], str):
        raise NotResults(f"{where}: suite is {_kind(doc['suite'])}, not a suite's name")
    if doc["suite"] not in SUITE_FILES:     # the page and --compare name it and its cases
        raise NotResults(f"{where}: suite {doc['suite']!r} is not a suite this dsm knows (one of "
                         f"{', '.join(SUITE_FILES)})")
    if "size" in doc and doc["size"] not in SIZES:       # (version 1 may have none: --page says so)
        raise NotResults(f"{where}: size {doc['size']!r} is not a size (one of {', '.join(SIZES)})")
    if version >= 3:
        _engine(doc.get("versions"), where)
    elif "versions" in doc and not isinstance(doc["versions"], dict):      # older: optional, but an object
        raise NotResults(f"{where}: versions is {_kind(doc['versions'])}, not an object of versions")
    _records(doc.get("cases"), where, "cases", COUNTS)
    if not doc["cases"]:
        raise NotResults(f"{where}: cases is empty: a results document holds a record per case and contender")
    if version >= 4:
        _costs(doc["cases"], where)
    _rays(doc["cases"], where)
    _records(doc.get("flicker", []), where, "flicker", ())
    for i, rec in enumerate(doc.get("flicker", [])):
        if "flicker_rate" not in rec:
            raise NotResults(f"{where}: flicker[{i}] has no flicker_rate")
        _number(rec["flicker_rate"], where, f"flicker[{i}].flicker_rate")
    return doc


def _records(recs, where: str, key: str, counts: tuple):
    """Every record of list ``key`` names its case and holds whole counts."""
    if not isinstance(recs, list):
        raise NotResults(f"{where}: {key} is {_kind(recs)}, not a list of records")
    seen = {}
    for i, rec in enumerate(recs):
        if not isinstance(rec, dict):
            raise NotResults(f"{where}: {key}[{i}] is {_kind(rec)}, not a record (an object)")
        missing = [n for n in NAMES if not isinstance(rec.get(n), str)]
        if missing:
            raise NotResults(f"{where}: {key}[{i}] has no text {missing[0]} (a record names scene, unit, light and "
                             "contender)")
        if not isinstance(rec.get("offset", "0"), str):
            raise NotResults(f"{where}: {key}[{i}].offset is {_kind(rec['offset'])}, not an offset's label (\"0\", "
                             "\"1e4\")")
        _once(seen, rec, where, f"{key}[{i}]")
        if rec["light"] not in LIGHTS:
            raise NotResults(f"{where}: {key}[{i}].light is {rec['light']!r}, not a suite's light (one of "
                             f"{', '.join(LIGHTS)})")
        if key == "cases" and "n_receivers" not in rec:
            raise NotResults(f"{where}: {key}[{i}] has no n_receivers (every case record counts its receivers)")
        for c in counts:
            if c in rec and not (isinstance(rec[c], int) and not isinstance(rec[c], bool) and rec[c] >= 0):
                raise NotResults(f"{where}: {key}[{i}].{c} is {rec[c]!r}, not a count (a whole number >= 0)")
        for name in [k for k in rec if k == "flip" or k.endswith("_rate")]:
            _rate(rec[name], where, f"{key}[{i}].{name}")
        problem = counts_problem(rec) if key == "cases" else None
        if problem:
            raise NotResults(f"{where}: {key}[{i}]: {problem}: an edited record")


def counts_problem(rec: dict, whole: bool = False) -> str | None:
    """Why a case record's counts cannot be a measurement or its rates are not its counts' (None if
    they can and are): the counts and rates it holds (``whole``: all four counts and three rates, as a
    kept case's); an oracle's record (objectives, no counts) has none."""
    if "n_acne" not in rec:
        return None
    if whole and not all(k in rec for k in COUNTS + ("acne_rate", "peterpan_rate", "error_rate")):
        return "a count or rate is missing"
    got = {k: rec.get(k, 0) for k in COUNTS}
    if not all(isinstance(c, int) and not isinstance(c, bool) and c >= 0 for c in got.values()):
        return f"{', '.join(COUNTS)} are not all counts"
    n, acne, peter = got["n_receivers"], got["n_acne"], got["n_peterpan"]
    shadowed = rec.get("n_gt_shadowed")
    fits = acne + peter <= n if shadowed is None else shadowed <= n and acne <= n - shadowed and peter <= shadowed
    if not fits:
        return (f"n_acne {acne} and n_peterpan {peter} do not fit n_receivers {n}"
                + ("" if shadowed is None else f" with n_gt_shadowed {shadowed}")
                + " (acne <= lit receivers, peter-panning <= shadowed ones)")
    rates = [("error_rate", acne + peter, n)]
    if shadowed is not None:
        rates += [("acne_rate", acne, n - shadowed), ("peterpan_rate", peter, shadowed)]
    for k, num, den in rates:
        if k in rec and not _same_rate(rec[k], num, den):
            return f"{k} {rec[k]!r} is not {num} / {den}" + (" (undefined: NaN)" if den == 0 else "")
    return None


def _same_rate(rate, num: int, den: int) -> bool:
    """Whether a recorded rate is num / den as the metrics compute it (NaN over no receiver)."""
    if not isinstance(rate, (int, float)) or isinstance(rate, bool):
        return False
    return rate != rate if den == 0 else math.isclose(rate, num / den, rel_tol=1e-12, abs_tol=0.0)


def _once(seen: dict, rec: dict, where: str, name: str):
    """A record's case and contender not given before (``seen``: identity -> name): --compare and the
    ranking would keep one of the two silently."""
    ident = (*(rec[n] for n in NAMES), str(rec.get("offset", "0")))
    if ident in seen:
        raise NotResults(f"{where}: {name} repeats {seen[ident]} ({', '.join(ident)}): one record per case and "
                         "contender")
    seen[ident] = name


def _costs(recs: list, where: str):
    """A version 4 document: every contender record carries its costs (whole counts, and taps a number)."""
    for i, rec in enumerate(recs):
        if rec["contender"] == "oracle":
            continue
        for c in COST_COUNTS + ("taps",):
            if c not in rec:
                raise NotResults(f"{where}: cases[{i}] has no {c} (results_version 4 records each contender's "
                                 f"costs: {', '.join(COST_COUNTS)}, taps)")
        for c in COST_COUNTS:
            if not (isinstance(rec[c], int) and not isinstance(rec[c], bool) and rec[c] >= 0):
                raise NotResults(f"{where}: cases[{i}].{c} is {rec[c]!r}, not a count (a whole number >= 0)")
        _number(rec["taps"], where, f"cases[{i}].taps")
        if rec["taps"] is not None and not (rec["taps"] != rec["taps"] or 0 <= rec["taps"] < math.inf):
            raise NotResults(f"{where}: cases[{i}].taps is {rec['taps']!r}, not texels read per lookup (a number "
                             ">= 0, NaN where no receiver)")


def _rays(recs: list, where: str):
    """A hybrid record's rays (version 5): a whole number of at most its receivers, and ray_fraction their share."""
    for i, rec in enumerate(recs):
        if "hybrid_rays" not in rec and "ray_fraction" not in rec:
            continue
        n, rays = rec["n_receivers"], rec.get("hybrid_rays")
        if not (isinstance(rays, int) and not isinstance(rays, bool) and 0 <= rays <= n):
            raise NotResults(f"{where}: cases[{i}].hybrid_rays is {rays!r}, not a count of at most its {n} receivers")
        fraction = rec.get("ray_fraction")
        _number(fraction, where, f"cases[{i}].ray_fraction")
        want = rays / n if n else math.nan
        if fraction is None or not (fraction == want or (fraction != fraction and want != want)):
            raise NotResults(f"{where}: cases[{i}].ray_fraction is {fraction!r}, not its hybrid_rays / n_receivers "
                             f"({rays} / {n})")


def _engine(versions, where: str):
    """A version 3 document names the dsm, Mitsuba and Dr.Jit versions it was measured with."""
    if not isinstance(versions, dict):
        raise NotResults(f"{where}: versions is {_kind(versions)}, not an object naming the dsm, mitsuba and "
                         "drjit versions (results_version 3)")
    for k in ENGINE:
        if not isinstance(versions.get(k), str) or not versions[k]:
            raise NotResults(f"{where}: versions.{k} is {versions.get(k)!r}, not a version (results_version 3 "
                             f"records {', '.join(ENGINE)})")


def _number(x, where: str, name: str):
    """A rate: a number (NaN, written for an undefined one, included) or null."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        raise NotResults(f"{where}: {name} is {x!r}, not a number")


def _rate(x, where: str, name: str):
    """A rate or FLIP: a number in [0, 1], NaN (undefined) or null."""
    _number(x, where, name)
    if x is not None and x == x and not 0.0 <= x <= 1.0:
        raise NotResults(f"{where}: {name} is {x!r}, not a rate (from 0 to 1, or NaN where undefined)")


def _kind(x) -> str:
    """What a JSON value is, in words."""
    if x is None:
        return "null"
    return {bool: "a boolean", int: "a number", float: "a number", str: "a string", list: "a list",
            dict: "an object"}.get(type(x), type(x).__name__)
