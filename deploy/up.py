"""The body of ``plumeswarm up``: launch, supervise until Ctrl-C / SIGTERM, stop in order."""

from __future__ import annotations

import logging
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

from deploy.console import Console
from deploy.launcher import Launcher, LaunchError, LaunchOptions
from swarmbus.scenario import Scenario, not_on_mavlink_note

log = logging.getLogger(__name__)


@contextmanager
def stop_on_signals() -> Iterator[threading.Event]:
    """An event set by SIGINT/SIGTERM while the block runs (handlers restored after)."""
    stop = threading.Event()

    def handler(signum: int, frame: FrameType | None) -> None:
        stop.set()

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def run_up(scenario: Scenario, opts: LaunchOptions, console: Console) -> int:
    """0 after a requested stop; 1 when a critical process died; LaunchError when start failed."""
    with stop_on_signals() as stop:
        launcher = Launcher(scenario, opts, console=console.line)
        try:
            launcher.start()
        except BaseException:
            launcher.stop()
            raise
        if any(s.role == "gateway" for s in launcher.specs):
            off = scenario.not_on_mavlink()  # the gateway serves the whole scenario
            if off:
                console.line(f"plumeswarm: {not_on_mavlink_note(len(off))}")
        console.line(
            f"plumeswarm: {len(launcher.specs)} processes ready; run directory {opts.run_dir}"
            " (Ctrl-C stops)"
        )
        code = 0
        try:
            launcher.supervise(stop, on_status=console.status)
        except LaunchError as exc:
            console.close()
            console.line(f"plumeswarm: {exc}")
            code = 1
        finally:
            console.close()
            console.line("plumeswarm: stopping")
            launcher.stop()
            console.line("plumeswarm: stopped")
        return code
