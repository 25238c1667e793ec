"""``plumeswarm bench gsl`` at scale: shards merged, a killed grid resumed, episodes on a Ray
cluster (a worker killed among them) — each the same bytes as the grid run at once on one
process."""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import psutil
import pytest

from tests.support.procs import REPO, run_cli, wait_until

GRID = [
    "bench", "gsl", "--algorithms", "casting", "--environments", "meander_low",
    "--sensors", "ideal", "--runs", "2", "--seed", "4", "--time-limit", "40",
]  # fmt: skip
EPISODES = 6  # random_walk, casting, oracle × 2 runs
TABLES = ("runs.csv", "gsl.json", "gsl.md", "paired.json")
RAN = re.compile(r"^grid: (\d+) episodes, (\d+) already done, (\d+) to run$", re.M)
RAY = importlib.util.find_spec("ray") is not None
RAY_ENV = {"RAY_AUTH_MODE": "disabled", "RAY_USAGE_STATS_ENABLED": "0", "PYTHONPATH": str(REPO)}


def _tables(out: Path) -> dict[str, bytes]:
    return {name: (out / name).read_bytes() for name in TABLES}


def _ok(result: subprocess.CompletedProcess[str]) -> str:
    assert result.returncode == 0, result.stderr[-2000:]
    return result.stdout


def _refused(result: subprocess.CompletedProcess[str]) -> str:
    """The one line a refusal prints (exit status 2, no traceback)."""
    assert result.returncode == 2, result.stdout[-500:] + result.stderr[-1500:]
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    return lines[0]


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """The grid run at once on one process."""
    out = tmp_path_factory.mktemp("reference")
    stdout = _ok(run_cli([*GRID, "--jobs", "1", "--out", str(out)]))
    assert _ran(stdout) == (str(EPISODES), "0", str(EPISODES))
    return _tables(out)


def _ran(stdout: str) -> tuple[str, ...]:
    """What the run said it had to do: episodes in all, already done, to run."""
    match = RAN.search(stdout)
    assert match is not None, stdout[-1000:]
    return match.groups()


def _episode_lines(journal: Path) -> int:
    """Whole episode lines in a journal (its first line is the grid's header)."""
    return max(0, journal.read_bytes().count(b"\n") - 1) if journal.exists() else 0


def test_shards_merged_are_the_grid_run_at_once(
    tmp_path: Path, reference: dict[str, bytes]
) -> None:
    shards = [tmp_path / "s1", tmp_path / "s2"]
    for i, out in enumerate(shards, 1):
        stdout = _ok(run_cli([*GRID, "--shard", f"{i}/2", "--out", str(out)]))
        # every second episode from the i-th: 3 each
        assert _ran(stdout) == ("3", "0", "3")
        assert not (out / "gsl.json").exists()
    merged = tmp_path / "merged"
    _ok(run_cli([*GRID[:2], "merge", *map(str, shards), "--out", str(merged)]))
    assert _tables(merged) == reference

    missing = _refused(run_cli([*GRID[:2], "merge", str(shards[0]), "--out", str(tmp_path / "x")]))
    # the grid's order is algorithm, then run: every second episode from the second is run 1's
    assert missing.endswith(
        "3 episode(s) in no directory: random_walk/meander_low/ideal run 1, "
        "casting/meander_low/ideal run 1, oracle/meander_low/ideal run 1"
    )
    twice = _refused(
        run_cli(
            [*GRID[:2], "merge", str(shards[0]), *map(str, shards), "--out", str(tmp_path / "y")]
        )
    )
    assert "more than one directory: random_walk/meander_low/ideal run 0" in twice
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


def test_a_killed_grid_resumes_running_only_the_missing_episodes(
    tmp_path: Path, reference: dict[str, bytes]
) -> None:
    out = tmp_path / "grid"
    journal = out / "episodes.jsonl"
    args = [*GRID, "--jobs", "1", "--out", str(out)]
    proc = subprocess.Popen(
        [sys.executable, "-m", "plumeswarm", *args],
        cwd=REPO,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        wait_until(lambda: _episode_lines(journal) >= 2, 60.0, "two episodes in the journal")
    finally:
        proc.kill()
        proc.wait(timeout=10)
    done = _episode_lines(journal)
    assert 2 <= done < EPISODES, "the grid was not cut off half-way"
    with journal.open("a") as f:  # a kill in the middle of writing a line
        f.write('{"episode": "casting/meander_low/ideal run 1", "key": "')

    changed = [*GRID, "--runs", "3", "--jobs", "1", "--out", str(out)]
    refusal = _refused(run_cli(changed))
    assert refusal.startswith(f"plumeswarm: error: --out {out}: holds episodes of `")

    stdout = _ok(run_cli(args))
    assert _ran(stdout) == (str(EPISODES), str(done), str(EPISODES - done))
    assert _tables(out) == reference
    assert _episode_lines(journal) == EPISODES
    # once more: nothing left to run, the same bytes
    assert _ran(_ok(run_cli(args))) == (str(EPISODES), str(EPISODES), "0")
    assert _tables(out) == reference


def test_without_ray_the_executor_names_the_extra(tmp_path: Path) -> None:
    code = (
        "import sys; sys.modules['ray'] = None\n"  # as if it were not installed
        "from plumeswarm.cli.main import main; main()"
    )
    result = subprocess.run(
        [sys.executable, "-c", code, *GRID, "--executor", "ray", "--out", str(tmp_path / "g")],
        cwd=REPO,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert "pip install 'plumeswarm[cluster]'" in _refused(result)


@pytest.mark.skipif(not RAY, reason="ray is not installed (pip install 'plumeswarm[cluster]')")
def test_a_ray_address_where_no_head_answers_is_one_line(tmp_path: Path) -> None:
    with socket.socket() as s:  # a port nothing listens on: bound, never listening
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        args = [*GRID, "--executor", f"ray=127.0.0.1:{port}", "--out", str(tmp_path / "g")]
        line = _refused(run_cli(args, timeout_s=60))
    assert line.startswith(f"plumeswarm: error: --executor ray=127.0.0.1:{port}: no Ray head")
    assert not (tmp_path / "g").exists()


def _netns_refusal() -> str | None:
    if shutil.which("ip") is None or os.geteuid() != 0:
        return "needs root and iproute2 for a loopback-only network namespace"
    probe = subprocess.run(["ip", "netns", "add", f"rayprobe{os.getpid()}"], capture_output=True)
    if probe.returncode != 0:
        return f"`ip netns add` is not allowed here: {probe.stderr.decode().strip()}"
    subprocess.run(["ip", "netns", "del", f"rayprobe{os.getpid()}"], capture_output=True)
    return None


PORT = 6379  # the namespace is the test's own: no other listener


@dataclass(frozen=True)
class Head:
    prefix: list[str]  # runs a command in the head's network namespace
    pid: int  # `ray start --block`: every Ray process of the head descends from it


@pytest.fixture(scope="module")
def ray_head(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Head]:
    """A Ray head (2 CPUs) in a network namespace with only loopback. Stopped, every process
    of it, at the end."""
    if not RAY:
        pytest.skip("ray is not installed (pip install 'plumeswarm[cluster]')")
    why = _netns_refusal()
    if why is not None:
        pytest.skip(why)
    ns = f"ray{os.getpid() % 100000}"
    subprocess.run(["ip", "netns", "add", ns], check=True, timeout=30)
    prefix = ["ip", "netns", "exec", ns]
    head: subprocess.Popen[bytes] | None = None
    try:
        subprocess.run([*prefix, "ip", "link", "set", "lo", "up"], check=True, timeout=30)
        ray_bin = str(Path(sys.executable).with_name("ray"))
        head = subprocess.Popen(
            [*prefix, ray_bin, "start", "--head", f"--port={PORT}", "--num-cpus=2",
             "--include-dashboard=false", "--disable-usage-stats", "--block",
             f"--temp-dir={tmp_path_factory.mktemp('ray')}"],
            env=dict(os.environ, **RAY_ENV),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )  # fmt: skip

        def up() -> bool:
            status = subprocess.run(
                [*prefix, ray_bin, "status", f"--address=127.0.0.1:{PORT}"],
                env=dict(os.environ, **RAY_ENV),
                capture_output=True,
                timeout=60,
            )
            return status.returncode == 0 and b"CPU" in status.stdout

        wait_until(up, 90.0, "the Ray head", poll_s=1.0)
        yield Head(prefix, head.pid)
    finally:
        if head is not None:
            _stop(head)
        subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=30)


def _stop(head: subprocess.Popen[bytes]) -> None:
    """The head's process group, then any of its processes that left it."""
    try:
        family = psutil.Process(head.pid).children(recursive=True)
    except psutil.NoSuchProcess:
        family = []
    os.killpg(head.pid, signal.SIGTERM)
    _, alive = psutil.wait_procs(family, timeout=5)
    for p in alive:
        p.kill()
    os.killpg(head.pid, signal.SIGKILL) if head.poll() is None else None
    head.wait(timeout=15)


def _ray_grid(head: Head, out: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [*head.prefix, sys.executable, "-m", "plumeswarm", *GRID,
         "--executor", f"ray=127.0.0.1:{PORT}", "--out", str(out)],
        cwd=REPO,
        env=dict(os.environ, **RAY_ENV),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )  # fmt: skip


def test_ray_cluster_gives_the_bytes_of_one_local_process(
    tmp_path: Path, reference: dict[str, bytes], ray_head: Head
) -> None:
    proc = _ray_grid(ray_head, tmp_path / "ray")
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr[-2000:]
    assert _ran(stdout) == (str(EPISODES), "0", str(EPISODES))
    assert f"{EPISODES}/{EPISODES}" in stderr  # the progress bar counted every episode
    assert _tables(tmp_path / "ray") == reference


def _running_episode(head: Head) -> psutil.Process | None:
    """A worker process of ``head`` in the middle of an episode (Ray titles it after the
    task)."""
    for p in psutil.Process(head.pid).children(recursive=True):
        try:
            cmdline = p.cmdline()
        except psutil.Error:
            continue
        if cmdline and cmdline[0].startswith("ray::run_episode"):
            return p
    return None


def test_a_ray_worker_killed_mid_grid_loses_and_duplicates_nothing(
    tmp_path: Path, reference: dict[str, bytes], ray_head: Head
) -> None:
    out = tmp_path / "ray"
    proc = _ray_grid(ray_head, out)
    try:
        victim = wait_until(
            lambda: _running_episode(ray_head), 90.0, "a Ray worker running an episode", 0.01
        )
        victim.kill()
        _, stderr = proc.communicate(timeout=120)
    finally:
        proc.kill() if proc.poll() is None else None
    assert proc.returncode == 0, stderr[-2000:]
    assert _tables(out) == reference
    assert _episode_lines(out / "episodes.jsonl") == EPISODES
