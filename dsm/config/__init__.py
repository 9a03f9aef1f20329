"""Experiment configs: TOML read once into the typed specs of dsm.types (dsm.config.read), the default experiment."""
from ..old_paths import forwarder

# the names of the module this folder replaced (dsm/config.py), kept as an alias for one release
__getattr__ = forwarder(__name__, ('read',))
