"""Experiment configs: TOML read once into the typed specs of dsm.core.types (dsm.config.read), the default experiment."""
