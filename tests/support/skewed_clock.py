"""A process whose wall clock is off, as on a host whose clock is: libfaketime, preloaded.

``skewed_clock_env(+5.0)`` is the environment that makes a child process's wall clock
(``CLOCK_REALTIME``: Python's ``time.time()``, Rust's ``SystemTime`` and so Zenoh's hybrid
logical clock) run 5 s ahead of the machine's; its monotonic clock stays the machine's (which
no other host could compare with anyway). The library is the one the ``libfaketime`` wheel
ships (a development dependency); ``faketime_library()`` is None where it is not installed.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path


def faketime_library() -> Path | None:
    """The ``libfaketime.so.1`` of the installed ``libfaketime`` package, if any (found
    without importing the package, which would need its own dependencies)."""
    spec = importlib.util.find_spec("libfaketime")
    if spec is None or not spec.submodule_search_locations:
        return None
    for root in spec.submodule_search_locations:
        lib = Path(root) / "vendor" / "libfaketime" / "src" / "libfaketime.so.1"
        if lib.is_file():
            return lib
    return None


def skewed_clock_env(offset_s: float) -> dict[str, str]:
    """The environment for a child whose wall clock is ``offset_s`` off the machine's."""
    lib = faketime_library()
    if lib is None:
        raise RuntimeError("libfaketime is not installed (pip install libfaketime)")
    return {
        "LD_PRELOAD": str(lib),
        "FAKETIME": f"{offset_s:+.3f}",  # relative: the clock runs on from now + offset_s
        "FAKETIME_DONT_FAKE_MONOTONIC": "1",
        "FAKETIME_DONT_RESET": "1",  # children of the child keep the same offset
    }
