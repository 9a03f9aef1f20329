"""Scenes: parameters, built-ins, mesh and XML files, loading, checks, closedness, the G-buffer, the exact frame."""
