"""The report: the run's files (io), tables, figures, report.html; publish is the only composer."""
