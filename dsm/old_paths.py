"""The flat module paths of the kit before its folders per stage (``dsm.metrics``,
``dsm.figures``, ...), kept as aliases for one release: importing one gives the module at
its new home, the same object (docs/design.md, *Layout*)."""
import importlib
import importlib.abc
import importlib.util
import sys

MOVED = {
    "area": "truth.area", "intervals": "truth.intervals", "metrics": "truth.metrics",
    "oracle": "truth.oracle", "reference": "truth.reference",
    "bench": "tools.bench", "env": "tools.env", "timing": "tools.timing",
    "cascade_layouts": "maps.cascade_layouts", "cascades": "maps.cascades", "formats": "maps.formats",
    "headroom": "maps.headroom", "lookup": "maps.lookup", "shadowmap": "maps.shadowmap",
    "shrink": "maps.shrink", "spawn": "maps.spawn", "views": "maps.views",
    "closedness": "scenes.closedness", "exact_frame": "scenes.exact_frame", "gbuffer": "scenes.gbuffer",
    "scene_size": "scenes.size", "terrain": "scenes.terrain",
    "cluster": "experiment.cluster", "lock": "experiment.lock", "motion": "experiment.motion", "plan": "experiment.plan",
    "record": "experiment.record", "resume": "experiment.resume", "runner": "experiment.runner",
    "contact_presets": "contact.presets", "contact_images": "report.sections.contact_images",
    "contact_report": "report.sections.contact", "soft_report": "report.sections.soft",
    "figures": "report.figures", "htmlpage": "report.html", "publish": "report.publish",
    "summary": "report.summary", "residual_map": "tune.residual_map", "tune_resume": "tune.resume",
}


class OldPathFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds ``dsm.<old name>`` and loads it as the module at its new home."""

    def find_spec(self, fullname, path=None, target=None):
        """A spec for an old path, None for any other name."""
        package, _, leaf = fullname.rpartition(".")
        if package == "dsm" and leaf in MOVED:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec):
        """The module at the new home (imported now), which the old name then also names."""
        return importlib.import_module(f"dsm.{MOVED[spec.name.rpartition('.')[2]]}")

    def exec_module(self, module):
        """Nothing to run: the new home's import ran the module."""


def install():
    """Put the finder on ``sys.meta_path`` once."""
    if not any(isinstance(f, OldPathFinder) for f in sys.meta_path):
        sys.meta_path.append(OldPathFinder())


def forwarder(package: str, homes: tuple):
    """A package's ``__getattr__`` that hands on the names of the flat module the package
    replaced (``dsm.config.parse``, ``dsm.report.case_time``, ...), read from ``homes``."""
    def getattr_(name: str):
        if not name.startswith("__") and importlib.util.find_spec(f"{package}.{name}") is not None:
            # a submodule not imported yet (``from . import exact_frame`` asks here first): imported
            # as itself, not searched for in the homes, which may be half-imported at that moment
            return importlib.import_module(f"{package}.{name}")
        for home in homes:
            module = importlib.import_module(f"{package}.{home}")
            if hasattr(module, name):
                return getattr(module, name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    return getattr_
