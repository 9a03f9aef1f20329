"""Test files named by what they guard: each tests/test_<name>.py names a module or package of dsm/ or
plugins/, or a documented topic of conftest.TEST_TOPICS; helpers are tests/helpers_*.py."""
from conftest import ROOT, TEST_TOPICS


def guarded_names() -> set:
    """Every module and package name under dsm/ and plugins/ (``__init__`` aside)."""
    names = set()
    for top in ("dsm", "plugins"):
        for path in (ROOT / top).rglob("*.py"):
            names.update(path.relative_to(ROOT / top).parts[:-1])
            names.add(path.stem)
    return names - {"__init__", "__pycache__"}


def names_what_it_guards(stem: str, modules: set) -> bool:
    """``stem`` (a test file's name without test_) is a module, a module then ``_more``, or a topic."""
    words = stem.split("_")
    return stem in TEST_TOPICS or any("_".join(words[:i]) in modules for i in range(1, len(words) + 1))


def test_every_test_file_names_a_module_or_a_documented_topic():
    """A new tests/test_x.py must name a module (test_lock.py, test_config_inputs.py) or a topic listed,
    with its documentation, in conftest.TEST_TOPICS."""
    modules = guarded_names()
    stray = [p.name for p in sorted((ROOT / "tests").glob("test_*.py")) if not names_what_it_guards(p.stem[5:], modules)]
    assert stray == [], f"name these by the module they guard, or add a documented topic to conftest.TEST_TOPICS: {stray}"


def test_every_topic_is_documented_where_it_says():
    """Each topic's documentation exists: the file (or folder), and the heading where one is named."""
    for topic, (path, heading) in TEST_TOPICS.items():
        assert (ROOT / path).exists(), (topic, path)
        if heading:
            assert heading in (ROOT / path).read_text().splitlines(), (topic, path, heading)


def test_the_rule_refuses_an_issue_name_and_takes_a_module_or_topic():
    """The rule on names it must refuse and take (test_hostile.py was filed by the issue that asked for it)."""
    modules = guarded_names()
    assert not names_what_it_guards("hostile2", modules)
    assert not names_what_it_guards("tour_inputs", modules)
    assert names_what_it_guards("lock", modules) and names_what_it_guards("config_inputs", modules)
    assert names_what_it_guards("far_from_origin", modules)


def test_helpers_are_named_as_helpers():
    """A Python file in tests/ that is not a test file or conftest.py is a helper named helpers_*.py."""
    others = [p.name for p in (ROOT / "tests").glob("*.py")
              if not p.name.startswith(("test_", "helpers_")) and p.name != "conftest.py"]
    assert others == [], others
