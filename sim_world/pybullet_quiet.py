"""pybullet without its build banner: ``from sim_world.pybullet_quiet import pb``.

pybullet's C module prints ``pybullet build time: …`` when it is imported, straight to a file
descriptor (2 in the PyPI build), past ``sys.stdout``/``sys.stderr`` and any redirection of
them; every import of pybullet in plumeswarm goes through here, which points file descriptors 1
and 2 at the null device for that import only (an import error is raised after they are back).
The version is logged instead (``-vv``)."""

from __future__ import annotations

import logging
import os
import sys
from types import ModuleType

log = logging.getLogger(__name__)


def import_quietly(name: str) -> ModuleType:
    """Import the module ``name`` with file descriptors 1 and 2 silenced for the import."""
    import importlib

    if name in sys.modules:
        return sys.modules[name]
    sys.stdout.flush()
    sys.stderr.flush()
    saved = {fd: os.dup(fd) for fd in (1, 2)}
    try:
        with open(os.devnull, "wb") as null:
            for fd in saved:
                os.dup2(null.fileno(), fd)
            module = importlib.import_module(name)
    finally:
        for fd, copy in saved.items():
            os.dup2(copy, fd)
            os.close(copy)
    return module


pb = import_quietly("pybullet")
log.debug("pybullet API version %s", pb.getAPIVersion())
