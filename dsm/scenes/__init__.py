"""Scenes: parameters, built-ins, mesh and XML files, loading, checks, closedness, the G-buffer, the exact frame."""
from ..old_paths import forwarder

# the names of the module this folder replaced (dsm/scenes.py, split into these), kept as an alias for one release
__getattr__ = forwarder(__name__, ('load', 'params', 'builtins', 'geometry', 'camera', 'files', 'ply', 'emitters',
                                   'checks', 'spec', 'data'))
