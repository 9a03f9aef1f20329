"""Differentiable shadow maps: gradients of a shadowed image with respect to the scene.

``[gradient]`` (:mod:`.spec`) names the parameters (an occluder's translation, a vertex, a light's
position or angle, with units), the loss and the techniques; :class:`.problem.Problem` evaluates a
technique with Dr.Jit AD on the kit's occluder built-in (:mod:`.occluder`) through the map's
attached intersections (:mod:`.build`), the light's view with its frame in Dr.Jit (:mod:`.light`),
the antialiased map after Worchel & Alexa 2023 (:mod:`.antialias`) and the lookups
(:mod:`.techniques`); :mod:`.check` holds the self-checks (AD against central differences, closed
forms) and ``dsm grad`` (:mod:`.command`) writes their table; :func:`run` returns what it
measures, for Python users (:mod:`.api`).
"""
from .api import GradRun, run

__all__ = ["GradRun", "run"]
