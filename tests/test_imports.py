"""The kit's import graph, read with ast: no circles, no private names across modules.

Modules are the files of ``dsm``, of the plugins package (``plugins/dsm_plugins``) and of the
tests (which may not reach into private names either). An
edge A -> B is any ``import``/``from ... import`` of B in A, at any depth (imports inside
functions count: a circle hidden in a function is still a circle).
"""
import ast
import functools
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = {"dsm": ROOT / "dsm", "dsm_plugins": ROOT / "plugins" / "dsm_plugins"}
SCANNED = {**PACKAGES, "tests": ROOT / "tests"}     # the tests' imports obey the same rules


def _modules() -> dict:
    mods = {}
    for pkg, folder in SCANNED.items():
        for f in sorted(folder.rglob("*.py")):
            rel = f.relative_to(folder).with_suffix("")
            parts = [pkg, *rel.parts]
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join(parts)] = f
    return mods


def _resolve(mod: str, is_pkg: bool, level: int, name: str | None) -> str:
    if level == 0:
        return name or ""
    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


@functools.cache
def _trees() -> dict:
    """Each module's path and syntax tree, parsed once per session (parsing the kit takes seconds)."""
    return {mod: (path, ast.parse(path.read_text(), str(path))) for mod, path in _modules().items()}


@functools.cache
def _graph():
    mods = _modules()
    edges, private_imports, private_attrs = {}, [], []
    for mod, (path, tree) in _trees().items():
        is_pkg = path.name == "__init__.py"
        deps = set()
        aliases = {}                     # local name -> kit module it stands for
        reaches = []                     # (alias, attribute): checked once every import of the module is known
        for node in ast.walk(tree):      # one walk of the tree (it is most of the check's time)
            if isinstance(node, ast.Attribute):
                if node.attr.startswith("_") and not node.attr.startswith("__") and isinstance(node.value, ast.Name):
                    reaches.append((node.value.id, node.attr))
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name.split(".")[0] in PACKAGES:
                        deps.add(a.name)
                        aliases[a.asname or a.name.split(".")[0]] = a.name if a.asname else a.name.split(".")[0]
            elif isinstance(node, ast.ImportFrom):
                target = _resolve(mod, is_pkg, node.level, node.module)
                if target.split(".")[0] not in PACKAGES:
                    continue
                for a in node.names:
                    sub = f"{target}.{a.name}"
                    if sub in mods:          # "from . import config": the module itself
                        deps.add(sub)
                        aliases[a.asname or a.name] = sub
                    else:
                        deps.add(target)
                        if a.name.startswith("_") and target != mod:
                            private_imports.append(f"{mod}: from {target} import {a.name}")
        private_attrs += [f"{mod}: {name}.{attr}" for name, attr in reaches
                          if name in aliases and aliases[name] != mod]
        # a package's own submodules are not dependencies of importing it
        edges[mod] = {d if d in mods else _owner(d, mods) for d in deps} - {mod, None}
    return edges, private_imports, private_attrs


def _owner(name, mods):
    while name and name not in mods:
        name = name.rpartition(".")[0]
    return name or None


def _cycles(edges):
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))
    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def _package_edges(edges):
    """Edges between modules, leaving out a submodule's edges back to its own package and the
    top-level packages' edges to their submodules (``dsm/__init__`` is imported first and lists
    what it exposes). A subpackage's ``__init__`` importing its submodules is a real edge: who
    imports the subpackage runs them (report -> lights -> cascades -> report is a circle)."""
    out = {}
    for a, deps in edges.items():
        top = a in PACKAGES
        out[a] = {b for b in deps if not (top and b.startswith(a + ".")) and not a.startswith(b + ".")}
    return out


# The kit's packages as layers, bottom first: a package imports only from the levels below its
# own (imports inside functions count), never from a package beside it or above it. A level
# of several packages is a set of siblings that do not import each other. docs/design.md, *Layout*.
LAYERS = (
    ("core",),                       # types, the run record's schema, env, timing
    ("scenes",),                     # loading, the camera, the G-buffer, rays that leave a surface
    ("maps",),                       # views, the map build, stored formats, the lookup
    ("lights", "schemes"),           # light types (their views, an area light's surface); bias schemes
    ("prefilter",),                  # pre-filtered maps (moments)
    ("truth",),                      # exact visibility, metrics, the oracle
    ("contact", "hybrid"),           # screen-space contact shadows; hybrid rays (a rule, the rays, the error left)
    ("config",),                     # the TOML read into specs, the plan
    ("pipeline",),                   # the stages, one public function each
    ("case",),                       # a case as a value: its context, evaluation and row
    ("report",),                     # the run's files, tables, figures, report.html
    ("experiment",),                 # the runner, resume, motion, the cluster, the folder lock
    ("tune", "benchmark", "perf", "testing", "grad"),   # dsm tune, dsm benchmark, dsm perf; threshold asserts; dsm grad
    ("cli", "pytest_plugin"),        # the command line; the pytest plugin (its fixture)
    ("launch", "__main__", ""),      # its entry points and the package's facade (dsm/__init__: dsm.run, ...)
)


def _unit(mod: str) -> str | None:
    """The package (a LAYERS name) a kit module belongs to; None outside dsm."""
    parts = mod.split(".")
    if parts[0] != "dsm":
        return None
    return parts[1] if len(parts) > 1 else ""


def _level(unit: str) -> int:
    for i, names in enumerate(LAYERS):
        if unit in names:
            return i
    raise AssertionError(f"package dsm.{unit} is in no layer of tests/test_imports.py's LAYERS")


def layer_violations(edges) -> list:
    """Every import from a module to a package at its own level (another package) or above."""
    out = []
    for a, deps in sorted(edges.items()):
        ua = _unit(a)
        if ua is None:
            continue
        for b in sorted(deps):
            ub = _unit(b)
            if ub is None or ub == ua or b == "dsm":
                continue       # its own package; ``dsm`` itself is only a parent of every module
            if _level(ub) >= _level(ua):
                out.append(f"{a} -> {b} (dsm.{ua} at level {_level(ua)}, dsm.{ub} at {_level(ub)})")
    return out


@pytest.mark.slow
def test_packages_are_layers():
    """No package imports one beside or above it (docs/design.md, *Layout*)."""
    edges, _, _ = _graph()
    assert layer_violations(edges) == []


def test_every_package_is_in_a_layer():
    folders = {p.parent.name for p in (ROOT / "dsm").glob("*/__init__.py")}
    modules = {p.stem for p in (ROOT / "dsm").glob("*.py") if p.stem != "__init__"}
    for name in folders | modules:
        _level(name)


def test_the_layer_check_sees_an_upward_and_a_sideways_import():
    """The check above can fail: maps importing the report, lights importing schemes."""
    assert layer_violations({"dsm.maps.cascades": {"dsm.report.io", "dsm.core.types"},
                             "dsm.lights.area": {"dsm.schemes.base"}, "dsm.report.io": {"dsm.core.record"}}) == [
        "dsm.lights.area -> dsm.schemes.base (dsm.lights at level 3, dsm.schemes at 3)",
        "dsm.maps.cascades -> dsm.report.io (dsm.maps at level 2, dsm.report at 10)"]


@pytest.mark.slow
def test_no_import_circles():
    edges, _, _ = _graph()
    assert _cycles(_package_edges(edges)) == []


@pytest.mark.slow
def test_no_private_names_across_modules():
    _, imports, attrs = _graph()
    assert imports == [] and attrs == []


def test_the_checker_sees_a_circle_and_a_private_reach_in():
    """The checks above can fail: a made-up graph with a circle, and a private attribute."""
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    tree = ast.parse("from dsm import config as cfgmod\ncfgmod._parse_scheme(1)\n")
    names = [n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute) and n.attr.startswith("_")]
    assert names == ["_parse_scheme"]


@pytest.mark.slow
def test_plugins_depend_on_the_pipeline_and_the_case_only():
    """The plugins use the stages and the case's evaluation (their class image is the runner's), nothing else."""
    edges, _, _ = _graph()
    kit = {d for m, deps in edges.items() if m.startswith("dsm_plugins") for d in deps if d.startswith("dsm.")}
    assert kit <= {"dsm.pipeline", "dsm.case", "dsm.core.types", "dsm"}, kit
    assert not any(d.startswith("dsm_plugins") for m, deps in edges.items() if m.startswith("dsm.") or m == "dsm"
                   for d in deps)


@pytest.mark.slow
def test_light_types_branch_only_in_the_registry():
    """No module of the kit outside dsm/lights compares a light's type with a type's name, but
    the few listed here (each a reason in docs/design.md, *Light types*): a new light type is a
    module in dsm/lights and a line in its REGISTRY."""
    allowed = {"dsm.config.plan": 5, "dsm.scenes.data": 2, "dsm.experiment.motion": 2, "dsm.schemes.presets": 1, "dsm.config.read": 1,
               "dsm_plugins.integrators": 5}
    names = {"directional", "spot", "point", "area", "scene"}
    found = {}
    for mod, (_, tree) in _trees().items():
        if mod.startswith(("dsm.lights", "tests")):
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Compare) and any(isinstance(c, ast.Constant) and c.value in names
                                                     for c in node.comparators):
                left = node.left
                if (isinstance(left, ast.Attribute) and left.attr == "type") or \
                        (isinstance(left, ast.Name) and left.id in ("light_type", "ltype")):
                    found[mod] = found.get(mod, 0) + 1
    assert found == allowed, found


def test_every_folder_of_the_kit_is_packaged():
    """pyproject.toml lists every package of dsm/ (a folder missing there is missing from a
    wheel, while an editable install still finds it)."""
    import tomllib
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    folders = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "dsm").rglob("__init__.py")}
    assert folders | {"dsm_plugins", "dsm_meshes"} == listed       # dsm_meshes: data/meshes in a wheel


def test_no_folder_shadows_a_public_name():
    """A subpackage named like a public function of dsm (``dsm.run``) would replace it as an
    attribute of the package the moment any module of the folder is imported."""
    import dsm
    folders = {p.parent.name for p in (ROOT / "dsm").rglob("__init__.py")}
    public = {n for n in dir(dsm) if not n.startswith("_") and callable(getattr(dsm, n))
              and not isinstance(getattr(dsm, n), type(dsm))}
    assert "run" in public and not folders & public


def test_pyproject_ships_every_data_file_of_the_package():
    """Each TOML, JSON, HTML, JS and CSS file under dsm/ (default.toml, the benchmark's suites and its tune,
    the pages' templates, scripts and style) is in pyproject's package-data for its package, by name or
    pattern: a wheel without one fails where it is read."""
    import fnmatch
    import tomllib
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    files = [p for ext in ("toml", "json", "html", "js", "css") for p in (ROOT / "dsm").rglob(f"*.{ext}")]
    assert {p.suffix for p in files} == {".toml", ".json", ".html", ".js", ".css"}
    for p in files:
        pkg = ".".join(p.parent.relative_to(ROOT).parts)
        assert any(fnmatch.fnmatch(p.name, pattern) for pattern in data.get(pkg, [])), (pkg, p.name)
