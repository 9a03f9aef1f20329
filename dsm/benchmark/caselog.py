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
import shutil
from pathlib import Path

from ..core import env
from ..report import io as report_io
from . import document

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
    by hand (n_acne above its lit receivers, a rate of other counts) is no finished case (the rule
    results.json's reader applies too: document.counts_problem)."""
    return document.counts_problem(rec, whole=True) is None


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
