"""A benchmark run in progress: each finished suite case kept as it finishes, so that Ctrl-C or
kill -9 loses at most the case that was running, and ``dsm benchmark --resume`` goes on.

``<out>/cases/run.json`` says what the run measures (suite, its hash, size, variant, backend, the
number of cases, and the dsm, Mitsuba and Dr.Jit versions it runs on); ``<out>/cases/<index>.json`` holds one finished case (its records, flicker
records and the variant it ran on), each written atomically. A resumed run takes a case from its
file only where the file names the same case of the same run; results.json, written at the end
from every case, makes the folder complete.
"""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

from ..core import env
from ..report import io as report_io

FOLDER = "cases"


class Mismatch(ValueError):
    """The folder's run in progress measures something else than the run asked for."""


def case_key(case) -> list:
    """What names a suite case: [scene, unit, offset]."""
    return [case.scene, case.unit, case.offset]


class CaseLog:
    """The finished cases of one run under ``out/cases/``."""

    def __init__(self, out: Path, header: dict):
        self.folder = Path(out) / FOLDER
        self.header = header

    def start(self, resume: bool) -> dict:
        """Begin the run; with ``resume``, the finished cases kept by the folder's run ({index: entry}),
        Mismatch where that run measured something else. Without, the folder's run is replaced."""
        done = self.finished() if resume else {}
        if not resume and self.folder.exists():
            shutil.rmtree(self.folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        report_io.write_json(self.folder / "run.json", self.header, 1)
        return done

    def finished(self) -> dict:
        """{index: entry} of the folder's finished cases (none without a run in progress)."""
        try:
            held = json.loads((self.folder / "run.json").read_text())
        except (OSError, ValueError):
            return {}
        # in the header's order: suite, hash and size before the number of cases that follows from them
        differs = [k for k in self.header if held.get(k) != self.header[k]]
        if "versions" in differs:        # the one to name first: every other key may agree
            change = env.engine_change(held.get("versions"), self.header["versions"])
            raise Mismatch(f"its run in progress was measured with other versions ({change}); results differ bit "
                           "for bit between versions")
        if differs:
            k = differs[0]
            raise Mismatch(f"its run in progress has {k} = {held.get(k)!r}, this run {self.header[k]!r}")
        out = {}
        for path in sorted(self.folder.glob("[0-9]*.json")):
            try:
                entry = json.loads(path.read_text())
                if all(consistent(r) for r in entry["records"]):
                    out[int(entry["index"])] = entry
            except (OSError, ValueError, KeyError, TypeError, AttributeError):
                continue            # not one of ours, or damaged by hand: that case runs again
        return out

    def keep(self, index: int, case, records: list, flicker: list, variant):
        """One finished case, written atomically."""
        entry = {"index": index, "case": case_key(case), "records": records, "flicker": flicker, "variant": variant}
        report_io.write_json(self.folder / f"{index:04d}.json", entry)



def consistent(rec: dict) -> bool:
    """Whether a kept record's counts can be a measurement and its rates are its counts': one edited
    by hand (n_acne above its lit receivers, a rate of other counts) is no finished case."""
    counts = [rec.get(k) for k in ("n_receivers", "n_gt_shadowed", "n_acne", "n_peterpan")]
    if "n_acne" not in rec:
        return True                 # an oracle's floor: objectives, no counts to agree
    if not all(isinstance(c, int) and not isinstance(c, bool) and c >= 0 for c in counts):
        return False
    n, shadowed, acne, peter = counts
    if shadowed > n or acne > n - shadowed or peter > shadowed:
        return False
    return all(_same_rate(rec.get(k), num, den) for k, num, den in
               (("acne_rate", acne, n - shadowed), ("peterpan_rate", peter, shadowed), ("error_rate", acne + peter, n)))


def _same_rate(rate, num: int, den: int) -> bool:
    """Whether a kept rate is num / den as the metrics compute it (NaN over no receiver)."""
    if not isinstance(rate, (int, float)) or isinstance(rate, bool):
        return False
    return rate != rate if den == 0 else math.isclose(rate, num / den, rel_tol=1e-12, abs_tol=0.0)


def clear(out: Path):
    """The run in ``out`` is complete (results.json holds every case): its case files go."""
    shutil.rmtree(Path(out) / FOLDER, ignore_errors=True)


def progress(out: Path) -> tuple | None:
    """(finished cases, cases) of the run in progress in ``out``, None without one."""
    folder = Path(out) / FOLDER
    try:
        total = json.loads((folder / "run.json").read_text())["cases"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return len(list(folder.glob("[0-9]*.json"))), total
