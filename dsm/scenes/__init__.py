"""Scenes: built-ins, mesh and XML files, their closedness, the G-buffer, the exact side's frame."""
from ..old_paths import forwarder

# the names of the module this folder replaced (dsm/scenes.py), kept as an alias for one release
__getattr__ = forwarder(__name__, ('load',))
