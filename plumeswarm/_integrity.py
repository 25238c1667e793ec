"""Are the top-level packages plumeswarm installs its own? Checked when the CLI starts.

plumeswarm installs ten top-level import names (:data:`PACKAGES`). Another distribution that
installs one of them (openai-agents' ``agents``, swarmbus-py's ``swarmbus``, …) overwrites
plumeswarm's files, or has them overwritten, and pip says nothing; a folder of the same name
earlier on ``sys.path`` shadows one. Either way the CLI would fail far from the cause, so it says
the cause in one line first. This module imports only the standard library, and none of the
packages it checks (README.md, "Installed names").
"""

from __future__ import annotations

import functools
import importlib.util
import re
import sys
from collections.abc import Iterable
from importlib.metadata import Distribution, distributions
from pathlib import Path

PACKAGES = (
    "swarmbus",
    "plume_atmosphere",
    "sim_world",
    "agents",
    "plume_service",
    "gcs_bridge",
    "recorder",
    "ros2_bridge",
    "deploy",
    "plumeswarm",
)
DISTRIBUTION = "plumeswarm"
ADVICE = "use a virtual environment of its own for plumeswarm"
# Where plumeswarm's packages sit side by side: site-packages for a wheel, the source tree for
# an editable install or a checkout.
HOME = Path(__file__).resolve().parent.parent


def _canonical(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _top_level(dist: Distribution) -> set[str]:
    """The top-level import names ``dist`` installs: its ``top_level.txt``, else the first part
    of each path in its ``RECORD`` (wheels built by other backends than setuptools)."""
    declared = dist.read_text("top_level.txt")
    if declared is not None:
        return set(declared.split())
    record = dist.read_text("RECORD")
    if record is None:
        return {f.parts[0] for f in dist.files or () if f.parts}
    paths = (line.partition(",")[0].strip('"') for line in record.splitlines())
    return {p.partition("/")[0].removesuffix(".py") for p in paths if p}


def claimed_by_others(packages: Iterable[str] = PACKAGES) -> dict[str, list[str]]:
    """Each of ``packages`` that another installed distribution also provides -> those
    distributions' names."""
    wanted = set(packages)
    found: dict[str, list[str]] = {}
    for dist in distributions():
        hit = _top_level(dist) & wanted
        if not hit:
            continue
        name = dist.metadata["Name"] or "?"
        if _canonical(name) == DISTRIBUTION:
            continue
        for package in hit:
            if name not in found.setdefault(package, []):
                found[package].append(name)
    return found


def _where(package: str) -> Path | None:
    """The folder ``import package`` would load (without importing it), or None if nothing."""
    spec = importlib.util.find_spec(package)
    if spec is None:
        return None
    if spec.origin not in (None, "namespace") and Path(spec.origin).name == "__init__.py":
        return Path(spec.origin).resolve().parent
    locations = list(spec.submodule_search_locations or ())
    return Path(locations[0]).resolve() if locations else Path(spec.origin or package)


def problem(packages: Iterable[str] = PACKAGES) -> str | None:
    """One line naming the first of ``packages`` that is not plumeswarm's own, or None."""
    packages = list(packages)
    others = claimed_by_others(packages)
    for package in packages:
        if package in others:
            by = " and ".join(others[package])
            return (
                f"the package {package!r} is also installed by {by}, which replaces "
                f"plumeswarm's: {ADVICE}"
            )
        where = _where(package)
        if where is None:
            return f"the package {package!r} of plumeswarm is missing: reinstall plumeswarm"
        if where != HOME / package:
            return (
                f"the package {package!r} is imported from {where}, not from plumeswarm's "
                f"{HOME / package}: take {where.parent} off the Python path (run plumeswarm "
                f"from another folder), or {ADVICE}"
            )
    return None


@functools.cache
def exit_if_not_ours() -> None:
    """Exit with status 2 and one line on stderr if a package of plumeswarm is not its own (the
    check runs once a process)."""
    message = problem()
    if message is not None:
        sys.stderr.write(f"plumeswarm: error: {message}\n")
        sys.exit(2)
