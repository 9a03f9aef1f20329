"""Screen-space contact shadows: the march (dsm.contact.march) and the engines' presets."""
from ..old_paths import forwarder

# the names of the module this folder replaced (dsm/contact.py), kept as an alias for one release
__getattr__ = forwarder(__name__, ('march',))
