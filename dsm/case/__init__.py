"""A case as a value: what one map's cases share (:class:`MapContext`), one case
(:class:`Case`), its pure evaluation (:func:`evaluate` -> :class:`CaseResult`) and the one
builder of a metrics.csv row (:mod:`dsm.case.row`).

The runner, motion's frame loop, the Ray tasks (which run the runner's map groups), ``dsm perf``
and ``dsm benchmark`` (which run the runner) schedule contexts and hand each result to the run's
sink; none of them looks up, counts or classifies a case itself.
"""
from .context import Case, MapContext, Where
from .evaluation import CaseResult, evaluate

__all__ = ["Case", "CaseResult", "MapContext", "Where", "evaluate"]
