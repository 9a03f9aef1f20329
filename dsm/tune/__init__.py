"""Tuning by gradient (dsm tune): relaxed objective, search, bias maps, resume.

The Python API: ``dsm.tune.tune(config, out=None, ...)`` runs it (:func:`dsm.tune.tuner.tune`)
and ``dsm.tune.table_text(result)`` gives its table.md as text (:func:`dsm.tune.output.table_text`).
"""
from .output import table_text
from .tuner import tune

__all__ = ["tune", "table_text"]
