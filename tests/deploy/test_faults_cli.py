"""Bad input at the command line: every ``plumeswarm`` command given a missing, unreadable
(a directory, binary garbage) or malformed file answers one clear line and a non-zero exit —
never a traceback. Real subprocesses (``python -m plumeswarm ...``), each bounded."""

from __future__ import annotations

from pathlib import Path

import pytest

from swarmbus.session import free_tcp_port
from tests.support.procs import run_cli

BAD_KINDS = ("missing", "directory", "garbage", "malformed", "wrong-schema", "empty")
# every command reads its scenario through the same loader: the commands get the four kinds
# that reach different code (open, read, decode, parse); ``scenario check`` gets them all
CORE_KINDS = BAD_KINDS[:4]


def bad_file(tmp: Path, kind: str, suffix: str) -> str:
    """A path of the given badness (tests run as root, so chmod 000 would not bite)."""
    path = tmp / f"bad-{kind}{suffix}"
    if kind == "missing":
        return str(path)
    if kind == "directory":
        path.mkdir()
    elif kind == "garbage":
        path.write_bytes(bytes(range(256)) * 8)
    elif kind == "malformed":
        path.write_text('[world\nname = "x\n= = =\n')
    elif kind == "wrong-schema":
        path.write_text('[world]\nname = 42\n[time]\nphysics_hz = "fast"\n')
    elif kind == "empty":
        path.write_text("")
    return str(path)


def assert_one_clear_line(args: list[str], timeout_s: float = 60.0) -> None:
    res = run_cli(args, timeout_s=timeout_s)
    shown = f"plumeswarm {' '.join(args)}\nstdout: {res.stdout}\nstderr: {res.stderr}"
    assert res.returncode != 0, shown
    assert "Traceback" not in res.stderr and "Traceback" not in res.stdout, shown
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert lines, shown
    errors = [ln for ln in lines if "error" in ln.lower()]
    assert len(errors) == 1, shown
    assert len(errors[0]) < 400, shown


SCENARIO_COMMANDS: dict[str, list[str]] = {
    "node": ["node", "physics", "--scenario", "{f}"],
    "up": ["up", "--headless", "--scenario", "{f}", "--out", "{tmp}/run"],
    "up-positional": ["up", "{f}", "--headless", "--out", "{tmp}/run"],
    "demo": ["demo", "--scenario", "{f}", "--out", "{tmp}/run", "--timeout", "30"],
    "plume-sample": ["plume", "sample", "--scenario", "{f}", "10", "0", "2"],
    "plume-mesh": [
        "plume",
        "mesh",
        "--scenario",
        "{f}",
        "--level",
        "0.001",
        "--out",
        "{tmp}/mesh.obj",
    ],
    "plume-plot": ["plume", "plot", "--scenario", "{f}", "--out", "{tmp}/plots"],
    "plume-series": [
        "plume",
        "series",
        "{f}",
        "--point",
        "10",
        "0",
        "2",
        "--seconds",
        "1",
        "--every",
        "0.5",
    ],
    "record": ["record", "--scenario", "{f}", "--out", "{tmp}/r.mcap"],
    "status": ["status", "--scenario", "{f}", "--timeout", "1"],
}


@pytest.mark.parametrize("kind", BAD_KINDS)
def test_scenario_check_of_a_bad_file(tmp_path: Path, kind: str) -> None:
    assert_one_clear_line(["scenario", "check", bad_file(tmp_path, kind, ".toml")])


@pytest.mark.parametrize("kind", CORE_KINDS)
@pytest.mark.parametrize("command", sorted(SCENARIO_COMMANDS))
def test_bad_scenario_file(tmp_path: Path, command: str, kind: str) -> None:
    f = bad_file(tmp_path, kind, ".toml")
    args = [a.format(f=f, tmp=tmp_path) for a in SCENARIO_COMMANDS[command]]
    assert_one_clear_line(args)


@pytest.mark.parametrize("kind", CORE_KINDS)
def test_bad_hosts_file(tmp_path: Path, kind: str) -> None:
    f = bad_file(tmp_path, kind, ".toml")
    assert_one_clear_line(["up", "--headless", "--hosts", f, "--out", str(tmp_path / "run")])


@pytest.mark.parametrize("kind", CORE_KINDS)
def test_bad_recording_for_report(tmp_path: Path, kind: str) -> None:
    f = bad_file(tmp_path, kind, ".mcap")
    assert_one_clear_line(["report", f, "--out", str(tmp_path / "rep")])


@pytest.mark.parametrize("kind", CORE_KINDS)
def test_bad_recording_for_replay(tmp_path: Path, kind: str) -> None:
    f = bad_file(tmp_path, kind, ".mcap")
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    assert_one_clear_line(["replay", f, "--connect", ep])


@pytest.mark.parametrize(
    "where", ["/proc/plumeswarm-test/r.mcap", "a-directory", "a-file/r.mcap"], ids=str
)
def test_record_to_a_bad_path(tmp_path: Path, where: str) -> None:
    (tmp_path / "a-directory").mkdir()
    (tmp_path / "a-file").write_text("x")
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    assert_one_clear_line(["record", "--connect", ep, "--out", str(tmp_path / where)], 30)


def test_report_out_is_a_file(tmp_path: Path) -> None:
    (tmp_path / "a-file").write_text("x")
    f = bad_file(tmp_path, "garbage", ".mcap")
    assert_one_clear_line(["report", f, "--out", str(tmp_path / "a-file")])
