"""Behaviours with changed parameters, built from their name in any process.

``plumeswarm.gsl.tuned:<module>:<Class>?<json>`` (made by
:func:`plumeswarm.gsl.registry.tuned_behavior`) is a subclass of ``<module>:<Class>`` whose
class attributes named in the JSON object take the values there. A behaviour's tunables are
its class attributes, so the subclass is the behaviour with those parameters, and a scenario
naming it flies the same on the kinematic bench, the fused runner and the distributed stack.
"""

from __future__ import annotations

import functools
import importlib
import json


@functools.cache
def _build(name: str) -> type:
    spec, sep, encoded = name.partition("?")
    module_name, colon, class_name = spec.partition(":")
    if not sep or not colon:
        raise AttributeError(f"{name!r}: expected '<module>:<Class>?<json>'")
    base = getattr(importlib.import_module(module_name), class_name)
    try:
        params = json.loads(encoded)
    except ValueError as exc:
        raise AttributeError(f"{name!r}: its parameters are not JSON ({exc})") from None
    if not isinstance(params, dict) or not all(hasattr(base, k) for k in params):
        raise AttributeError(f"{name!r}: not parameters of {class_name}")
    return type(class_name, (base,), {"__module__": base.__module__, **params})


def __getattr__(name: str) -> type:
    if name.startswith("__"):
        raise AttributeError(name)
    return _build(name)
