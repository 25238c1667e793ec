"""The supervisor with small stand-in processes: restart policy, logs, staged stop, no orphans."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import psutil

from deploy.supervisor import (
    ProcessSpec,
    ProcState,
    RestartMode,
    RestartPolicy,
    Supervisor,
)
from tests.support.procs import wait_until

PY = sys.executable


def spec(name: str, code: str, **kw: object) -> ProcessSpec:
    return ProcessSpec(name=name, role=name, argv=(PY, "-c", code), **kw)  # type: ignore[arg-type]


def test_restart_policy_backoff_and_limits() -> None:
    never = RestartPolicy()
    assert not never.allows(1, 0)
    p = RestartPolicy(RestartMode.ON_FAILURE, max_restarts=2, backoff_s=0.5, backoff_max_s=1.5)
    assert p.allows(1, 0) and p.allows(-9, 1)
    assert not p.allows(1, 2), "no more than max_restarts"
    assert not p.allows(0, 0), "a clean exit is not restarted"
    assert [p.delay_s(n) for n in range(4)] == [0.5, 1.0, 1.5, 1.5]


def test_on_failure_restarts_until_the_limit_then_reports(tmp_path: Path) -> None:
    policy = RestartPolicy(RestartMode.ON_FAILURE, max_restarts=2, backoff_s=0.01)
    sup = Supervisor(
        [spec("crashy", "print('boom', flush=True); raise SystemExit(3)", restart=policy)], tmp_path
    )
    sup.start_all()
    events = []

    def done() -> bool:
        events.extend(sup.poll())
        return sup.procs["crashy"].state is ProcState.EXITED

    wait_until(done, 30.0, "crashy to be given up on")
    assert [e.restarting for e in events] == [True, True, False]
    assert sup.procs["crashy"].restarts == 2
    assert [sv.spec.name for sv in sup.failed_for_good()] == ["crashy"]
    sup.stop_all()
    assert (tmp_path / "crashy.log").read_text().count("\nboom\n") == 3


def test_output_goes_to_log_file_and_prefixed_console(tmp_path: Path) -> None:
    lines: list[str] = []
    sup = Supervisor(
        [spec("talker", "print('hello'); print('world')")], tmp_path, console=lines.append
    )
    sup.start_all()
    wait_until(lambda: sup.poll() or sup.procs["talker"].state is ProcState.EXITED, 20.0, "exit")
    sup.stop_all()
    assert "[talker] hello" in lines and "[talker] world" in lines
    assert "hello\nworld\n" in (tmp_path / "talker.log").read_text()
    assert sup.failed_for_good() == []


def test_stop_all_kills_stubborn_groups_and_leaves_no_orphans(tmp_path: Path) -> None:
    stubborn = (
        "import signal, subprocess, sys, time\n"
        "signal.signal(signal.SIGTERM, signal.SIG_IGN)\n"
        "subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(120)'])\n"
        "print('up', flush=True)\n"
        "time.sleep(120)\n"
    )
    polite = "import time\nprint('up', flush=True)\ntime.sleep(120)\n"
    lines: list[str] = []
    sup = Supervisor(
        [spec("stubborn", stubborn, stop_stage=0), spec("polite", polite, stop_stage=1)],
        tmp_path,
        console=lines.append,
    )
    sup.start_all()
    wait_until(lambda: sum("up" in ln for ln in lines) == 2, 30.0, "both to print 'up'")
    family = []
    for pid in sup.pids().values():
        proc = psutil.Process(pid)
        family += [proc, *proc.children(recursive=True)]
    assert len(family) >= 3
    t0 = time.monotonic()
    codes = sup.stop_all(stage_timeout_s=1.0)
    assert time.monotonic() - t0 < 15.0
    assert codes["polite"] == -15 and codes["stubborn"] == -9
    _, alive = psutil.wait_procs(family, timeout=5.0)
    assert alive == [], f"survivors: {alive}"
