"""Every notebook in notebooks/ runs to the end (at small sizes; its own asserts check its story)."""
import ast

import pytest

from conftest import ROOT

NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def test_the_notebooks_are_there():
    assert [p.stem[:2] for p in NOTEBOOKS] == ["01", "02", "03", "04", "05", "06", "07", "08", "09", "10", "11"]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_each_notebook_asserts_its_headline_not_finiteness(path):
    """A notebook's asserts are its story told as numbers: several of them, and none that only
    says a number is finite (true of almost any number, whatever the story)."""
    nbformat = pytest.importorskip("nbformat", reason="nbformat is part of the test extra (pip install -e .[test])")
    book = nbformat.read(path, as_version=4)
    asserts = [node for c in book.cells if c.cell_type == "code"
               for node in ast.walk(ast.parse(c.source)) if isinstance(node, ast.Assert)]
    assert len(asserts) >= 2, path.stem
    finite = [ast.unparse(a.test) for a in asserts if "isfinite" in ast.unparse(a.test)]
    assert not finite, (path.stem, finite)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_to_the_end(path, monkeypatch):
    nbformat = pytest.importorskip("nbformat", reason="nbformat is part of the test extra (pip install -e .[test])")
    from nbclient import NotebookClient
    monkeypatch.setenv("DSM_NOTEBOOK_SMALL", "1")
    monkeypatch.setenv("PYTHONPATH", str(ROOT))     # the kernel imports this checkout's dsm, not an installed one
    book = nbformat.read(path, as_version=4)
    NotebookClient(book, timeout=600, kernel_name="python3",
                   resources={"metadata": {"path": str(path.parent)}}).execute()
    outputs = [o for c in book.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    assert any("image/png" in o.get("data", {}) for o in outputs) or path.stem.startswith("00")
