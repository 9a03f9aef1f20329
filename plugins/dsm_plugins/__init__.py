"""Mitsuba integrator plugins: ``dsm_shadow`` and ``dsm_error``.

A package of its own, installed with the kit, depending on ``dsm.pipeline`` and ``dsm.case`` only. The kit
finds it through the entry-point group ``dsm.plugins``: :func:`register` (an explicit list,
as Mitsuba registers its own) runs when ``import dsm`` finds a variant set and when
:func:`dsm.core.env.use_variant` sets one. Both plugins run the same view, map, scheme, filter,
format and metric stages as the experiment runner.
"""
from __future__ import annotations

PLUGINS = ("dsm_shadow", "dsm_error")
_registered: set = set()


def register() -> list:
    """Register the plugins for the current Mitsuba variant; returns their names."""
    import mitsuba as mi
    if mi.variant() is None:
        raise RuntimeError("set a Mitsuba variant (mi.set_variant) before registering the dsm plugins")
    if mi.variant() in _registered:
        return list(PLUGINS)
    from .integrators import DsmError, DsmShadow, clean_config_errors
    # the factory is the outermost Python frame Mitsuba calls: it drops a ConfigError's
    # traceback, so Mitsuba's message carries the one line naming the bad property
    mi.register_integrator("dsm_shadow", clean_config_errors(DsmShadow))
    mi.register_integrator("dsm_error", clean_config_errors(DsmError))
    _registered.add(mi.variant())
    return list(PLUGINS)
