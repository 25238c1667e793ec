"""Starting, watching, restarting and stopping the OS processes of one run.

Each child runs in its own process group (so a stop reaches its own children, such as the meshcat
server the viewer starts) and with a parent-death signal (so it cannot outlive a launcher that was
killed). Its output goes, line by line, to its own log file in the run directory and to one
console view with a role prefix. Restart policy is per process: ``never`` or ``on-failure`` with a
maximum count and an exponential backoff. Stopping goes in stages (:attr:`ProcessSpec.stop_stage`)
with a bounded wait per stage and SIGKILL of the whole group after it.

Everything that spawns runs on the caller's thread (the parent-death signal is tied to the thread
that forked), only the log pumps run on their own threads.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import enum
import logging
import os
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Sequence
from contextlib import suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

log = logging.getLogger(__name__)

_PR_SET_PDEATHSIG = 1


class RestartMode(enum.StrEnum):
    NEVER = "never"
    ON_FAILURE = "on-failure"


@dataclass(frozen=True)
class RestartPolicy:
    """When a process that ended is started again (a clean exit 0 is never restarted)."""

    mode: RestartMode = RestartMode.NEVER
    max_restarts: int = 3
    backoff_s: float = 0.5
    backoff_max_s: float = 8.0

    def delay_s(self, restarts_so_far: int) -> float:
        return float(min(self.backoff_max_s, self.backoff_s * (2**restarts_so_far)))

    def allows(self, returncode: int, restarts_so_far: int) -> bool:
        return (
            self.mode is RestartMode.ON_FAILURE
            and returncode != 0
            and restarts_so_far < self.max_restarts
        )


@dataclass(frozen=True)
class ProcessSpec:
    """One process to run: its bus name, role, command line and policies."""

    name: str
    role: str
    argv: tuple[str, ...]
    restart: RestartPolicy = RestartPolicy()
    stop_stage: int = 0  # stages stop in increasing order
    critical: bool = True  # the run fails when it ends for good with an error
    env: dict[str, str] = field(default_factory=dict)


class ProcState(enum.StrEnum):
    PENDING = "pending"
    RUNNING = "running"
    BACKOFF = "backoff"  # ended, waiting to be started again
    EXITED = "exited"  # ended for good


@dataclass
class Supervised:
    spec: ProcessSpec
    log_path: Path
    proc: subprocess.Popen[bytes] | None = None
    state: ProcState = ProcState.PENDING
    restarts: int = 0
    restart_at: float = 0.0
    returncode: int | None = None
    pump: threading.Thread | None = None

    @property
    def pid(self) -> int | None:
        return self.proc.pid if self.proc is not None else None


@dataclass(frozen=True)
class ExitEvent:
    name: str
    returncode: int
    restarting: bool
    delay_s: float


def _pdeathsig() -> None:  # pragma: no cover - runs in the child between fork and exec
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)


def _pump(stream: IO[bytes], log_file: IO[bytes], prefix: str, console: ConsoleSink) -> None:
    with stream, log_file:
        for raw in iter(stream.readline, b""):
            log_file.write(raw)
            log_file.flush()
            console(f"{prefix}{raw.decode('utf-8', 'replace').rstrip()}")


ConsoleSink = Callable[[str], None]


def _no_console(line: str) -> None:
    pass


class Supervisor:
    """The processes of one run (see the module docstring)."""

    def __init__(
        self,
        specs: Sequence[ProcessSpec],
        run_dir: Path,
        console: ConsoleSink | None = None,
        cwd: Path | None = None,
    ) -> None:
        names = [s.name for s in specs]
        if len(set(names)) != len(names):
            raise ValueError(f"duplicate process names in {names}")
        self.run_dir = run_dir
        self.cwd = cwd
        self.console = console or _no_console
        self._width = max((len(n) for n in names), default=0)
        self.procs: dict[str, Supervised] = {
            s.name: Supervised(s, run_dir / f"{s.name}.log") for s in specs
        }

    # ------------------------------------------------------------------ start
    def start(self, name: str) -> Supervised:
        sv = self.procs[name]
        spec = sv.spec
        argv = list(spec.argv)
        log_file = open(sv.log_path, "ab")  # noqa: SIM115 - closed by the pump thread
        log_file.write(f"--- start {time.strftime('%H:%M:%S')}: {' '.join(argv)}\n".encode())
        log_file.flush()
        env = dict(os.environ, PYTHONUNBUFFERED="1", **spec.env)
        sv.proc = subprocess.Popen(
            argv,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            cwd=self.cwd,
            env=env,
            start_new_session=True,
            preexec_fn=_pdeathsig,
        )
        sv.state = ProcState.RUNNING
        sv.returncode = None
        assert sv.proc.stdout is not None
        prefix = f"[{spec.name:<{self._width}}] "
        sv.pump = threading.Thread(
            target=_pump,
            args=(sv.proc.stdout, log_file, prefix, self.console),
            name=f"log-{spec.name}",
            daemon=True,
        )
        sv.pump.start()
        log.info("started %s (pid %d)", spec.name, sv.proc.pid)
        return sv

    def start_all(self, names: Sequence[str] | None = None) -> None:
        for name in names if names is not None else list(self.procs):
            self.start(name)

    # ------------------------------------------------------------------ watch
    def poll(self, now: float | None = None) -> list[ExitEvent]:
        """Reap ended processes, restart those whose backoff elapsed; the exits seen now."""
        now = time.monotonic() if now is None else now
        events: list[ExitEvent] = []
        for sv in self.procs.values():
            if sv.state is ProcState.RUNNING and sv.proc is not None:
                rc = sv.proc.poll()
                if rc is None:
                    continue
                self._reap_group(sv)
                sv.returncode = rc
                if sv.spec.restart.allows(rc, sv.restarts):
                    delay = sv.spec.restart.delay_s(sv.restarts)
                    sv.state = ProcState.BACKOFF
                    sv.restart_at = now + delay
                    events.append(ExitEvent(sv.spec.name, rc, True, delay))
                else:
                    sv.state = ProcState.EXITED
                    events.append(ExitEvent(sv.spec.name, rc, False, 0.0))
            elif sv.state is ProcState.BACKOFF and now >= sv.restart_at:
                sv.restarts += 1
                self.start(sv.spec.name)
        return events

    def failed_for_good(self) -> list[Supervised]:
        """Critical processes that ended with an error and will not be restarted."""
        return [
            sv
            for sv in self.procs.values()
            if sv.spec.critical and sv.state is ProcState.EXITED and sv.returncode not in (0, None)
        ]

    def pids(self) -> dict[str, int]:
        return {n: sv.pid for n, sv in self.procs.items() if sv.pid is not None}

    def running(self) -> list[str]:
        return [n for n, sv in self.procs.items() if sv.state is ProcState.RUNNING]

    # ------------------------------------------------------------------ stop
    @staticmethod
    def _signal_group(sv: Supervised, sig: int) -> None:
        if sv.proc is not None:
            with suppress(ProcessLookupError, PermissionError):
                os.killpg(sv.proc.pid, sig)

    def _reap_group(self, sv: Supervised) -> None:
        # The leader ended; whatever it left in its group (a meshcat server) goes with it.
        self._signal_group(sv, signal.SIGKILL)

    def stop_all(self, stage_timeout_s: float = 4.0) -> dict[str, int | None]:
        """Stop every process, stage by stage: SIGTERM, a bounded wait, then SIGKILL the group."""
        stages = sorted({sv.spec.stop_stage for sv in self.procs.values()})
        for stage in stages:
            group = [
                sv
                for sv in self.procs.values()
                if sv.spec.stop_stage == stage and sv.proc is not None
            ]
            for sv in group:
                if sv.proc is not None and sv.proc.poll() is None:
                    self._signal_group(sv, signal.SIGTERM)
            deadline = time.monotonic() + stage_timeout_s
            for sv in group:
                assert sv.proc is not None
                try:
                    sv.proc.wait(timeout=max(0.05, deadline - time.monotonic()))
                except subprocess.TimeoutExpired:
                    log.warning(
                        "%s did not stop within %.1f s: killing it", sv.spec.name, stage_timeout_s
                    )
                    self._signal_group(sv, signal.SIGKILL)
                    sv.proc.wait(timeout=5.0)
                self._reap_group(sv)
                sv.returncode = sv.proc.returncode
                sv.state = ProcState.EXITED
        for sv in self.procs.values():
            if sv.state is not ProcState.EXITED:
                sv.state = ProcState.EXITED
            if sv.pump is not None:
                sv.pump.join(timeout=2.0)
        return {n: sv.returncode for n, sv in self.procs.items()}
