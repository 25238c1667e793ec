"""The optional parts of plumeswarm and the pip extra that installs each.

A module of an extra that is missing gives one line naming the extra to install, never a
traceback (the CLI) or a bare ``No module named …`` (a library import).
"""

from __future__ import annotations

import importlib.util

from swarmbus.errors import PlumeswarmError

# Top-level module -> the extra that installs it (pyproject.toml [project.optional-dependencies]).
EXTRA_OF_MODULE: dict[str, str] = {
    "gymnasium": "rl",
    "pettingzoo": "rl",
    "matplotlib": "report",
    "rosbags": "ros2",
    "stable_baselines3": "train",
    "supersuit": "train",
    "ray": "cluster",
}


class MissingExtra(PlumeswarmError, ImportError):
    """An optional dependency is not installed; the message names the extra."""


def missing_extra_message(module: str, feature: str | None = None) -> str | None:
    """The one-line message for a missing top-level ``module`` of an extra, or None when the
    module belongs to no extra (a missing core dependency: a broken install)."""
    top = module.partition(".")[0]
    extra = EXTRA_OF_MODULE.get(top)
    if extra is None:
        return None
    what = f"{feature} needs" if feature else "this needs"
    return f"{what} {top}, from the {extra!r} extra: pip install 'plumeswarm[{extra}]'"


def require(feature: str, *modules: str) -> None:
    """Raise :class:`MissingExtra` naming the extra if any of ``modules`` is not installed."""
    for module in modules:
        if importlib.util.find_spec(module) is None:
            raise MissingExtra(missing_extra_message(module, feature) or f"{module} is missing")
