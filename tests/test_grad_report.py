"""dsm grad's report.html (dsm.grad.page): every table's rows are its CSV's, the words' winners are
numpy's argmin over the CSV, a tie is said as a tie and an undefined error as undefined, a section is
absent when its file is, an unknown CSV is a link, and grad.json keeps the measuring's and the report's
seconds apart."""
import csv
import json
from html.parser import HTMLParser

import numpy as np
import pytest

from dsm.grad import findings, page
from helpers_grad import TINY, tiny_grad_run  # noqa: F401  (a session fixture, shared with test_browser)

class Tables(HTMLParser):
    """Each table's body rows (by table id) as lists of the cells' data-v values; section ids; images."""

    def __init__(self):
        super().__init__()
        self.tables, self.sections, self.images, self.links, self.answers = {}, [], [], [], []
        self._table = self._row = None
        self._in_answer = False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "table" and a.get("id"):
            self._table = self.tables.setdefault(a["id"], [])
        elif tag == "tr" and self._table is not None:
            self._row = []
        elif tag == "td" and self._row is not None:
            self._row.append(a.get("data-v"))
        elif tag == "section":
            self.sections.append(a.get("id"))
        elif tag == "img" and a.get("src"):
            self.images.append(a["src"])
        elif tag == "a":
            self.links.append(a.get("href"))
        elif tag == "p" and a.get("class") == "answer":
            self._in_answer = True
            self.answers.append("")

    def handle_data(self, data):
        if self._in_answer:
            self.answers[-1] += data

    def handle_endtag(self, tag):
        if tag == "tr" and self._row is not None:
            if self._row:
                self._table.append(self._row)
            self._row = None
        elif tag == "table":
            self._table = None
        elif tag == "p":
            self._in_answer = False


def _parse(path) -> Tables:
    t = Tables()
    t.feed(path.read_text(encoding="utf-8"))
    return t


def _csv_rows(path) -> list:
    with open(path, newline="") as fh:
        return [row for row in csv.reader(fh)][1:]


def _write(path, columns, rows):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        w.writerows(rows)


@pytest.fixture(scope="module")
def run(tiny_grad_run):
    """dsm grad --compare --inverse's out folder on TINY (shared with test_browser's report in Chromium)."""
    return tiny_grad_run


@pytest.mark.slow
def test_every_table_of_a_compare_and_inverse_run_is_its_csv(run):
    doc = _parse(run / "report.html")
    for name, sid, *_ in page.TABLES:
        if (run / name).is_file():
            assert doc.tables[f"table-{sid}"] == _csv_rows(run / name), name
    assert {"compare", "projective", "inverse", "selfcheck", "figures", "run"} <= set(doc.sections)
    assert "equal-error" not in doc.sections and "other" not in doc.sections
    assert doc.images == ["relative_error.png", "gradients.png", "inverse.png"]
    assert all((run / src).is_file() for src in doc.images)
    # the inverse summary's k/n: successes counted by hand from inverse.csv
    inv = list(csv.DictReader(open(run / "inverse.csv")))
    for row in doc.tables["inverse-summary"]:
        for p, cell in zip(("occluder_z", "light_height"), row[1:]):
            mine = [r for r in inv if r["technique"] == row[0] and r["param"] == p]
            assert cell == f"{sum(r['success'] == 'True' for r in mine)}/{len(mine)}"


@pytest.mark.slow
def test_grad_json_keeps_the_measuring_and_the_report_apart(run):
    rec = json.loads((run / "grad.json").read_text())
    t = rec["timing"]
    assert t["measure_s"] == pytest.approx(t["selfcheck_s"] + t["compare_s"] + t["inverse_s"])
    parts = t["report_parts"]
    assert set(parts) == {"gradients.png", "relative_error.png", "inverse.png", "report.html"}
    assert t["report_s"] >= sum(parts.values()) > 0
    assert rec["options"] == ["--compare", "--inverse"] and rec["gradient"]["techniques"] == [
        "pcf_bilinear", "pcf_bilinear aa", "vsm blur 3", "vsm blur 3 aa"]


def _closest(ad, ref, err) -> np.ndarray:
    """numpy's closest set: argmin |ad - ref| and every deviation within twice the truth's error of it."""
    dev = np.abs(np.asarray(ad, np.float64) - ref)
    return np.flatnonzero(dev - dev.min() <= 2.0 * err)


def test_the_answer_names_numpys_argmin_per_parameter(run):
    """compare.csv's closest technique per parameter (or the tie the truth's error leaves) as the page says it."""
    doc = _parse(run / "report.html")
    rows = list(csv.DictReader(open(run / "compare.csv")))
    words = next(a for a in doc.answers if a.startswith("Closest to the truth"))
    for p in ("occluder_z", "light_height"):
        rs = [r for r in rows if r["param"] == p]
        near = _closest([float(r["ad"]) for r in rs], float(rs[0]["reference"]), float(rs[0]["reference_error"]))
        who = [rs[i]["technique"] for i in near]
        if len(who) == 1:
            assert f"{p}: {who[0]} (" in words
        else:
            assert f"{p}: a tie" in words and findings.names(who) in words
    proj = list(csv.DictReader(open(run / "projective.csv")))
    # a truth of exactly 0 +- 0 over the seen pixels (the mask hides the shadow at 16^2) is no agreement
    blind = [float(r["reference"]) == 0.0 and float(r["reference_error"]) == 0.0 for r in proj]
    agreeing = sum(r["agrees"] == "True" and not b for r, b in zip(proj, blind))
    said = next(a for a in doc.answers if a.startswith("Mitsuba's projective integrators"))
    assert said.startswith(f"Mitsuba's projective integrators agreed with the truth in {agreeing} of {len(proj)} ")
    assert ("measured nothing" in said) == any(blind)


def _compare_rows(param, ads, ref, err):
    return [{"technique": f"t{j}", "param": param, "ad": repr(float(a)), "reference": repr(ref),
             "reference_error": repr(err), "rel_error": repr(abs(float(a) - ref) / abs(ref)) if ref else "",
             "sign": "agrees", "cosine": "0.5"} for j, a in enumerate(ads)]


def test_the_winner_is_numpys_argmin_over_random_errors():
    rng = np.random.default_rng(59)
    singles = 0
    for _ in range(40):
        ads = rng.normal(0.6, 0.05, size=6)
        ref, err = 0.6, float(rng.choice([1e-5, 4e-3]))
        words = findings.compare_words(_compare_rows("a", ads, ref, err))
        near = _closest(ads, ref, err)
        if len(near) == 1:
            singles += 1
            assert f"a: t{near[0]} (" in words
        else:
            assert "a: a tie within the truth's own error between " + findings.names([f"t{i}" for i in near]) in words
    assert 0 < singles < 40                      # both kinds of answer were drawn


def test_a_tie_is_a_tie_and_an_undefined_error_is_undefined():
    rows = (_compare_rows("h", [0.0, 0.0, 1.25], 0.5, 0.001) + _compare_rows("x", [0.3, 0.0], 0.0, 0.001)
            + _compare_rows("k", [0.56, 0.5605, 0.58], 0.5, 0.001))
    words = findings.compare_words(rows)
    assert "h: a tie between t0 and t1 (100 % each)" in words
    assert "x: undefined (every relative error is undefined: the truth is 0)" in words
    assert "k: a tie within the truth's own error between t0 and t1 (12 % to 12.1 %)" in words
    inv = [{"technique": t, "param": "h", "success": s} for t, s in
           (("a", "True"), ("a", "True"), ("b", "True"), ("b", "True"), ("c", "False"), ("c", "True"))]
    assert "h: a tie between a and b (2/2 each)" in findings.inverse_words(inv)
    none = [{"technique": t, "param": "h", "success": "False"} for t in "ab"]
    assert "h: no technique succeeded (0/1 each)" in findings.inverse_words(none)


def test_the_self_check_words_and_the_equal_error_words():
    rows = [{"technique": t, "param": p, "closed_form": cf, "ad_vs_closed": g, "ad_vs_fd": fd}
            for t, p, cf, g, fd in (("a", "h", "0.59", "0.05", "1e-05"), ("b", "h", "0.59", "0.008", "0.3"),
                                    ("a", "k", "", "", ""), ("b", "k", "", "", "0.001"))]
    words = findings.selfcheck_words(rows)
    assert "h: b (0.8 %)" in words and "k: no closed form" in words
    assert "at most 30 % off (b, h); undefined in 1 row (a central difference of 0)" in words
    from dsm.grad.equal_error import BELOW, NEVER, REACHED
    eq = [{"technique": t, "param": "h", "integrator": "direct", "time_ratio": x, "status": st}
          for t, x, st in (("pcf aa", "12.5", REACHED), ("vsm aa", "3.0", BELOW), ("nearest", "", NEVER))]
    words = findings.equal_error_words(eq)
    assert "direct, d/d h: 3 (vsm aa) to 12.5 (pcf aa)" in words
    assert "errs less than 1 of 3 techniques" in words
    assert "; undefined for nearest (path tracing never reached its error within the spp range)" in words
    assert findings.equal_error_words([{"technique": "a", "ms": "1"}]) is None


def test_a_section_is_absent_when_its_file_is_and_an_unknown_csv_is_a_link(tmp_path):
    """A plain dsm grad folder (selfcheck.csv alone): the self-check, no other table, no figure; a CSV
    another version writes (equal_error.csv) gets its section from its columns; an unknown one a link."""
    cols = ["technique", "param", "unit", "loss", "ad", "fd", "fd_step", "changed_texels", "changed_pixels",
            "changed_pairs", "ad_vs_fd", "closed_form", "ad_vs_closed", "edge_pairs"]
    _write(tmp_path / "selfcheck.csv", cols, [["vsm aa", "occluder_z", "world", "0.25", "0.6", "0.6", "0.001", "0",
                                               "0", "0", "1e-06", "0.5925925925925926", "0.0125", "10"],
                                              ["nearest", "occluder_z", "world", "0.25", "0.0", "0.0", "0.001", "0",
                                               "0", "0", "", "0.5925925925925926", "1.0", "0"]])
    page.write_report(tmp_path, {})
    doc = _parse(tmp_path / "report.html")
    assert [s for s in doc.sections if s not in ("answer", "run")] == ["selfcheck"]
    assert doc.images == [] and not (tmp_path / "relative_error.png").exists()
    assert doc.tables["table-selfcheck"] == _csv_rows(tmp_path / "selfcheck.csv")
    assert doc.answers[0].startswith("Closest to the closed form, per parameter: occluder_z: vsm aa (1.25 %)")
    text = (tmp_path / "report.html").read_text()
    assert ">undefined</td>" in text and 'title="exact: 0.5925925925925926">0.5926</td>' in text
    _write(tmp_path / "equal_error.csv", ["technique", "param", "integrator", "rel_error", "ms_per_gradient",
                                          "pt_spp", "pt_ms_per_gradient", "time_ratio", "status"],
           [["vsm aa", "occluder_z", "prb", "0.02", "13.5", "256", "400.0", "29.6", "reached"],
            ["nearest", "occluder_z", "prb", "1.0", "2.0", "", "", "", "never within the range"]])
    _write(tmp_path / "mine.csv", ["a"], [["1"]])
    (tmp_path / "mine.png").write_bytes(b"")
    page.write_report(tmp_path, {})
    doc = _parse(tmp_path / "report.html")
    assert doc.tables["table-equal-error"] == _csv_rows(tmp_path / "equal_error.csv")
    assert "other" in doc.sections and {"mine.csv", "mine.png"} <= set(doc.links) and doc.images == []
    assert ("Cost at equal gradient error, path tracing's time over the technique's: prb, d/d occluder_z: "
            "29.6 (vsm aa); undefined for nearest (path tracing never reached its error within the spp "
            "range).") in doc.answers


@pytest.mark.slow
def test_the_words_are_the_same_in_a_second_identical_run(run, tmp_path):
    """The answer reads no timing column: a second run of the same config says the same words."""
    from dsm.cli import main
    (tmp_path / "g.toml").write_text(TINY)
    assert main(["grad", str(tmp_path / "g.toml"), "--compare", "--inverse", "--out", str(tmp_path / "again")]) == 0
    assert _parse(tmp_path / "again" / "report.html").answers == _parse(run / "report.html").answers


def test_a_truth_of_zero_over_the_seen_pixels_is_said_as_measuring_nothing():
    """projective.csv's 0 against a truth of exactly 0 +- 0 (the mask hid the whole shadow) is no agreement;
    equal_error.csv's undefined ratios say why once, not 'undefined where undefined'."""
    from dsm.grad.equal_error import UNDEFINED
    proj = [{"integrator": "direct_projective", "param": "occluder_z", "reference": "0.0", "reference_error": "0.0",
             "rel_error": "", "agrees": "True"},
            {"integrator": "prb_projective", "param": "occluder_z", "reference": "0.33", "reference_error": "0.01",
             "rel_error": "0.02", "agrees": "True"}]
    words = findings.projective_words(proj)
    assert words.startswith("Mitsuba's projective integrators agreed with the truth in 1 of 2 cases: prb_projective ")
    assert "measured nothing (the truth over the pixels it sees is 0: the mask hides the whole shadow): " \
           "direct_projective on occluder_z." in words
    eq = [{"technique": t, "param": "occluder_z", "integrator": "direct_projective", "time_ratio": "",
           "status": UNDEFINED} for t in ("nearest", "pcss")]
    words = findings.equal_error_words(eq)
    assert words.endswith("direct_projective, d/d occluder_z: undefined for every technique (the technique's "
                          "relative error is undefined: the truth over the pixels the integrator sees is 0).")
    assert "where undefined" not in words


@pytest.mark.parametrize("damage", ["empty", "header", "nan", "short"])
def test_a_damaged_csv_still_gives_a_report_whose_words_say_undefined(tmp_path, damage):
    """An empty compare.csv, one with its header only, nan and inf cells (no measured value) or a short row
    (cells missing): report.html is written, its table holds the file's rows, no number comes from a nan."""
    cols = ["technique", "param", "unit", "ad", "reference", "reference_error", "reference_step", "reference_samples",
            "rel_error", "sign", "cosine", "ms_per_gradient", "compile_ms"]
    rows = {"empty": None, "header": [],
            "nan": [["vsm", "h", "world", "nan", "0.5", "0.01", "0.02", "4", "nan", "", "inf", "1.5", "0.1"],
                    ["pcss", "h", "world", "0.25", "0.5", "0.01", "0.02", "4", "0.5", "True", "0.9", "2.0", "0.1"]],
            "short": [["vsm", "h", "world", "0.25"],
                      ["pcss", "h", "world", "0.25", "0.5", "0.01", "0.02", "4", "0.5", "True", "0.9", "2.0", "0.1"]]}
    if rows[damage] is None:
        (tmp_path / "compare.csv").write_text("")
    else:
        _write(tmp_path / "compare.csv", cols, rows[damage])
    page.write_report(tmp_path, {})
    doc = _parse(tmp_path / "report.html")
    assert "compare" in doc.sections
    padded = [r + [""] * (len(cols) - len(r)) for r in rows[damage] or []]      # a missing cell: undefined
    assert doc.tables.get("table-compare", []) == padded
    if rows[damage]:
        # the one defined relative error is pcss's: the only answer that the numbers support
        assert "h: pcss (50 %), sign True, per-pixel cosine 0.9" in doc.answers[0]
        assert "nan" not in " ".join(doc.answers)
