"""Differentiable shadow maps: gradients of a shadowed image with respect to the scene.

A config's ``[gradient]`` table (:mod:`.spec`) names the parameters (an occluder's translation, a
vertex, a light's position or angle, with units) and the loss; the scene, light, map and bias come
from the kit's ``[[scene]]``, ``[[light]]``, ``[map]`` and ``[[scheme]]`` (:mod:`.kit_tables`).
:class:`Problem` holds the scene, light and receivers; :func:`evaluate` (ctx, case, params) returns one
technique's (a :class:`GradCase`: the kit's Case and antialias) loss, gradients and image with Dr.Jit
AD on the kit's occluder built-in (:mod:`.occluder`) through the map's attached intersections
(:mod:`.build`), the light's view with its frame in Dr.Jit (:mod:`.light`), the antialiased map
after Worchel & Alexa 2023 (:mod:`.antialias`) and the lookups (:mod:`.techniques`); :mod:`.check` holds the self-checks (AD against central differences, closed
forms) and ``dsm grad`` (:mod:`.command`) writes their table; :func:`run` returns what it measures,
for Python users (:mod:`.api`).
"""
from .api import GradRun, run, spec_of
from .evaluation import GradCase, GradResult, case_of, cases, evaluate
from .problem import Problem

__all__ = ["GradCase", "GradResult", "GradRun", "Problem", "case_of", "cases", "evaluate", "run", "spec_of"]
