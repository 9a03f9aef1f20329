"""Tuning by gradient (dsm tune): relaxed objective, search, bias maps, resume."""
from ..old_paths import forwarder

# the names of the module this folder replaced (dsm/tune.py, then tuner.py, split into these),
# kept as an alias for one release
__getattr__ = forwarder(__name__, ('tuner', 'output', 'search', 'refine', 'compare', 'relax', 'evaluate', 'cases',
                                   'bias_map'))
