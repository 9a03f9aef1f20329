"""The leak column of table.md's first summary table (dsm.report.summary): only in runs with
[map] kind, pooled as sum n_leak / sum n_gt_shadowed, and nothing else of the table moved."""

COMMON = {"preset": "", "format": "float32", "cascade_layout": "", "scene": "stacked_plates", "light": "sun",
          "view": "orthographic", "resolution": 64, "build_ms": 1.0, "lookup_ms": 0.5, "n_acne": 2, "n_gt_lit": 200}


def _row(scheme, params, filt, kind, shadowed, peterpan, leak):
    """A result row with the counts the summary reads; its rates from those counts."""
    r = {**COMMON, "scheme": scheme, "params": params, "filter": filt, "map_kind": kind, "n_gt_shadowed": shadowed,
         "n_peterpan": peterpan, "n_peterpan_edge": peterpan - leak, "n_leak": leak, "mean_abs_error": 0.01,
         "moments_ms": 2.0 if kind != "depth" else float("nan"), "n_receivers": 200 + shadowed}
    r.update(acne_rate=r["n_acne"] / r["n_gt_lit"], peterpan_rate=peterpan / shadowed,
             error_rate=(r["n_acne"] + peterpan) / r["n_receivers"])
    return r


ROWS = [_row("vsm", "min_variance=0.0001", "box:3", "vsm", 100, 10, 6),
        _row("vsm", "min_variance=0.0001", "box:3", "vsm", 300, 2, 0),
        _row("constant", "bias=1 texel", "nearest", "depth", 50, 1, 1)]


def _first_table(lines):
    """The lines of the summary's first table (its header to its last row)."""
    start = next(i for i, x in enumerate(lines) if x.startswith("| scheme |"))
    end = next(i for i in range(start, len(lines)) if not lines[i].startswith("|"))
    return lines[start:end]


def test_the_first_table_pools_the_leaks_per_instance_in_a_kind_run():
    from dsm.report import summary
    table = _first_table(summary.summary_md(ROWS))
    col = table[0].split(" | ").index("leak pooled")
    cells = {tuple(x.split(" | ")[:2]): x.split(" | ")[col] for x in table[2:]}
    # vsm: (6 + 0) / (100 + 300) = 0.015; constant: 1 / 50 = 0.02
    assert cells == {("| vsm", "min_variance=0.0001"): "0.015", ("| constant", "bias=1 texel"): "0.02"}
    assert all(x.count("|") == table[0].count("|") for x in table)


def test_without_map_kind_the_first_table_is_the_one_without_the_column():
    """Rows without map_kind (a run without [map] kind): no leak column; and the kind run's table
    with its leak cells taken out is that table, cell for cell."""
    from dsm.report import summary
    plain = summary.summary_md([{k: v for k, v in r.items() if k != "map_kind"} for r in ROWS])
    assert not any("leak" in x.lower() for x in plain)
    with_leak = _first_table(summary.summary_md(ROWS))
    col = with_leak[0].split(" | ").index("leak pooled")
    dropped = [" | ".join(c for i, c in enumerate(x.split(" | ")) if i != col) for x in with_leak]
    dropped[1] = "|---" * (with_leak[1].count("|") - 2) + "|"
    assert dropped == _first_table(plain)


def test_report_html_s_summary_shows_the_leak_column_in_a_kind_run_only():
    """The same pooled values in report.html's per-instance table (its value attribute, exact), and
    no leak column where the rows carry no map kind."""
    import re
    from dsm.report import html
    page = html.summary_section(ROWS)
    heads = re.findall(r"<th[^>]*>([^<]*)</th>", page)
    assert "leak pooled" in heads
    col = heads.index("leak pooled")
    rows = re.findall(r"<tr[^>]*>(.*?)</tr>", page)[1:]
    cells = [re.findall(r"<td([^>]*)>([^<]*)</td>", r) for r in rows]
    got = {c[0][1]: c[col][1] for c in cells}
    assert got == {"vsm": "0.015", "constant": "0.02"}
    plain = [{k: v for k, v in r.items() if k != "map_kind"} for r in ROWS]
    assert "leak pooled" not in html.summary_section(plain)
