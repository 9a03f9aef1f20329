"""Report sections of one capability each (area lights, contact shadows), drawn from the run's files."""
