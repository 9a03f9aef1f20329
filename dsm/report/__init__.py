"""The report: the run's files (io), tables, figures, report.html; publish is the only composer."""
from ..old_paths import forwarder

# the names of the module this folder replaced (dsm/report.py), kept as an alias for one release
__getattr__ = forwarder(__name__, ('tables', 'io'))
