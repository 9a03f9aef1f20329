"""Tuning by gradient (dsm tune): relaxed objective, search, bias maps, resume."""
from ..old_paths import forwarder

# the names of the module this folder replaced (dsm/tune.py), kept as an alias for one release
__getattr__ = forwarder(__name__, ('tuner',))
