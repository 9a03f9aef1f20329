"""docs/papers.md is what scripts/papers.py makes of the committed runs, and its verdicts follow the numbers."""
import importlib.util
import math
import sys

import pytest

from conftest import ROOT


@pytest.fixture(scope="module")
def papers():
    spec = importlib.util.spec_from_file_location("papers", ROOT / "scripts" / "papers.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["papers"] = mod            # its dataclasses look their module up there
    spec.loader.exec_module(mod)
    yield mod
    sys.modules.pop("papers", None)


def test_the_page_is_the_committed_runs(papers):
    """Regenerated from docs/papers/runs/, the page is the committed one (python scripts/papers.py)."""
    assert papers.page() == (ROOT / "docs" / "papers.md").read_text()


def test_every_claims_run_and_the_mesh_are_recorded(papers):
    prov = papers.provenance(papers.RUNS)
    assert {c.experiment for c in papers.CLAIMS} <= set(prov["runs"])
    assert len(prov["mesh"]["sha256"]) == 64 and all(len(r["commit"]) == 40 for r in prov["runs"].values())
    assert {c.source for c in papers.CLAIMS} == {papers.WE, papers.BR, papers.MS, papers.SA, papers.DO}


def _vsv_rows(adaptive_error: float) -> list:
    rows = [{"view": "vsv", "resolution": 256.0, "scheme": "vsv_epsilon", "error_rate": e, "params": f"K={k}"}
            for e, k in ((0.03, 0.001), (0.02, 0.003))]
    return rows + [{"view": "vsv", "resolution": 256.0, "scheme": "vsv_adaptive", "error_rate": adaptive_error,
                    "params": "K=0.0001"}]


def test_a_verdict_follows_the_numbers(papers):
    """The VSV claim agrees only below the best epsilon's error (0.02); Figure 6's tie is said, and is no
    agreement; an empty rate prints as undefined."""
    claim = {c.where: c for c in papers.CLAIMS}
    vsv, figure6 = claim["Section 3.3, Figure 8"].measure, claim["Figure 6"].measure
    assert vsv(_vsv_rows(0.019))[1] is True
    assert vsv(_vsv_rows(0.02))[1] is False
    same = {"acne_rate": 0.01, "peterpan_rate": 0.02, "n_acne": 5.0, "n_peterpan": 7.0}
    text, ok = figure6([{**same, "scheme": s} for s in ("constant", "slope_scaled", "adaptive", "dual")])
    assert "a tie" in text and ok is False
    assert papers.pct(math.nan) == "undefined" and papers.pct(0.00135179) == "0.135 %"
    assert [papers.verdict(v) for v in (True, False, None)] == ["agrees", "does not agree", "not measurable"]


def test_vsv_memory_is_equal_at_twice_the_resolution(papers):
    """A VSV of R^2 rays x 256 alpha bits holds as many bits as a dual paraboloid map of (2R)^2 x 2 float32."""
    vsv = {"view": "vsv", "resolution": 256.0, "params": "alpha=256 occupancy=centre"}
    dp = {"view": "dual_paraboloid", "resolution": 512.0, "params": "K=0.0001"}
    assert papers.vsv_memory_bits(vsv) == papers.vsv_memory_bits(dp) == 256 * 256 * 256
