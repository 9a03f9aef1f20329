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


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_to_the_end(path, monkeypatch, tmp_path):
    nbformat = pytest.importorskip("nbformat", reason="nbformat is part of the test extra (pip install -e .[test])")
    from nbclient import NotebookClient
    monkeypatch.setenv("DSM_NOTEBOOK_SMALL", "1")
    monkeypatch.setenv("PYTHONPATH", str(ROOT))     # the kernel imports this checkout's dsm, not an installed one
    monkeypatch.setenv("TMPDIR", str(tmp_path))     # dsm.run's own results folders (out=None) land under tmp_path
    book = nbformat.read(path, as_version=4)
    # no cell timeout: a wall-clock limit fails a sound notebook on a loaded machine (notebook 11 passed
    # 600 s at load 7); a hang is CI's to stop, as for every other test. A fresh kernel per notebook (one
    # that used a name or a state left by another passes nowhere else), stopped at once once the last cell
    # has answered: a polite shutdown only waited (about a second a notebook) for a kernel whose work is done
    NotebookClient(book, timeout=None, kernel_name="python3", shutdown_kernel="immediate",
                   resources={"metadata": {"path": str(path.parent)}}).execute()
    outputs = [o for c in book.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    assert any("image/png" in o.get("data", {}) for o in outputs) or path.stem.startswith("00")


# Issue 57's standard for a figure, in every notebook: text at 9 points and more at the size shown.
# The inline backend draws at 100 dpi and a notebook (or the docs site) shows the PNG at its pixel
# size only while it fits the page: wider, the viewer shrinks it and its text with it.
MIN_POINTS = 9
MIN_DPI = 100
MAX_WIDTH_PX = 1000
SIZE_KEYWORDS = ("fontsize", "labelsize", "title_fontsize")
TEXT_CALLS = ("set_title", "suptitle", "set_xlabel", "set_ylabel", "set", "text", "annotate")


def _number(node):
    """A literal number (int or float), else None: a relative size ('small') or a name is not checked here."""
    return node.value if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) else None


def _figure_faults(source: str) -> list:
    """Every font size under MIN_POINTS, dpi under MIN_DPI and cut text ([:n] in a title or label) in a cell."""
    faults = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.keyword) and node.arg in SIZE_KEYWORDS + ("dpi",):
            least = MIN_DPI if node.arg == "dpi" else MIN_POINTS
            if _number(node.value) is None or _number(node.value) < least:
                faults.append(f"{node.arg}={ast.unparse(node.value)}")
        if isinstance(node, ast.Assign) and any("rcParams" in ast.unparse(t) for t in node.targets):
            key = ast.unparse(node.targets[0])
            least = MIN_DPI if "dpi" in key else MIN_POINTS if "size" in key and "figsize" not in key else None
            if least is not None and (_number(node.value) is None or _number(node.value) < least):
                faults.append(f"{key} = {ast.unparse(node.value)}")
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in TEXT_CALLS:
            if any(isinstance(n, ast.Slice) for a in node.args + node.keywords for n in ast.walk(a)):
                faults.append(f"cut text: {ast.unparse(node)[:60]}")
    return faults


def _png_widths(book) -> list:
    """The pixel width of every stored PNG output (its IHDR chunk)."""
    import base64
    import struct
    return [struct.unpack(">I", base64.b64decode(o["data"]["image/png"])[16:20])[0]
            for c in book.cells if c.cell_type == "code" for o in c.get("outputs", [])
            if "image/png" in o.get("data", {})]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_figures_are_readable_as_shown(path):
    """Every font size and rcParams size set in a notebook is a number >= 9 points, no dpi below 100, no
    title or label cut by a slice, and every stored figure at most MAX_WIDTH_PX wide (shown unshrunk)."""
    nbformat = pytest.importorskip("nbformat", reason="nbformat is part of the test extra (pip install -e .[test])")
    book = nbformat.read(path, as_version=4)
    faults = [f for c in book.cells if c.cell_type == "code" for f in _figure_faults(c.source)]
    assert not faults, (path.stem, faults)
    widths = _png_widths(book)
    assert widths and max(widths) <= MAX_WIDTH_PX, (path.stem, widths)


def test_the_readability_check_finds_small_cut_and_wide():
    """The check itself, on sources it must refuse and accept (the faults issue 57 found)."""
    assert _figure_faults('ax.legend(fontsize=7)') == ["fontsize=7"]
    assert _figure_faults('ax.legend(fontsize="small")') == ['fontsize=\'small\'']
    assert _figure_faults('ax.tick_params(labelsize=8.5)') == ["labelsize=8.5"]
    assert _figure_faults('plt.rcParams["legend.fontsize"] = 8') == ["plt.rcParams['legend.fontsize'] = 8"]
    assert _figure_faults('fig = plt.figure(dpi=72)') == ["dpi=72"]
    assert _figure_faults('ax.set(title=name[:28])')[0].startswith("cut text")
    assert _figure_faults('ax.set_title(f"{r[\'params\'][:12]}", fontsize=9)')[0].startswith("cut text")
    assert _figure_faults('ax.legend(fontsize=9); ax.set_title(name, fontsize=10); x = rows[:3]') == []
    assert _figure_faults('plt.rcParams["figure.figsize"] = (9, 4)') == []
