"""Multi-host deployment, for real: three network namespaces joined only by veth links and TCP.

``sim`` (router, physics, plume), ``agents`` (the autopilots) and ``gcs`` (gateway, and the demo
driver) each run ``plumeswarm up --hosts FILE --host NAME`` inside their own namespace, the way
three machines would. The namespaces share a private 10.200.0.0/24 on a bridge inside ``sim``;
nothing leaves them. Needs root and iproute2 (CI is root); skips with a message otherwise.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import psutil
import pytest

from tests.support.hosts import write_hosts as write_hosts_file
from tests.support.procs import REPO, wait_until

pytestmark = pytest.mark.netns

SUBNET = "10.200.0"
ADDRESSES = {"sim": f"{SUBNET}.1", "agents": f"{SUBNET}.2", "gcs": f"{SUBNET}.3"}
ROUTER = f"tcp/{ADDRESSES['sim']}:7447"


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, timeout=30)


def _namespaces_allowed() -> str | None:
    """None when namespaces work here, else why not."""
    if shutil.which("ip") is None:
        return "iproute2 (`ip`) is not installed"
    if os.geteuid() != 0:
        return "creating network namespaces needs root"
    probe = f"psprobe{os.getpid()}"
    try:
        _ip("netns", "add", probe)
    except subprocess.CalledProcessError as exc:
        return f"`ip netns add` is not allowed here: {exc.stderr.decode().strip()}"
    _ip("netns", "del", probe)
    return None


@pytest.fixture
def hosts(tmp_path: Path) -> Iterator[dict[str, str]]:
    """Three namespaces on one bridge: host name → namespace name."""
    with three_namespaces() as ns:
        yield ns


@contextmanager
def three_namespaces() -> Iterator[dict[str, str]]:
    """Three namespaces on one bridge (skips the test without root): host → namespace."""
    why = _namespaces_allowed()
    if why is not None:
        pytest.skip(f"network namespaces unavailable: {why}")
    tag = f"ps{os.getpid() % 100000}"
    ns = {h: f"{tag}{h}" for h in ADDRESSES}
    made: list[str] = []
    try:
        for name in ns.values():
            _ip("netns", "add", name)
            made.append(name)
            _ip("-n", name, "link", "set", "lo", "up")
        hub = ns["sim"]
        _ip("-n", hub, "link", "add", "br0", "type", "bridge")
        _ip("-n", hub, "addr", "add", f"{ADDRESSES['sim']}/24", "dev", "br0")
        _ip("-n", hub, "link", "set", "br0", "up")
        for host in ("agents", "gcs"):
            near, far = f"v{host[:3]}h", f"v{host[:3]}"
            _ip(
                "link",
                "add",
                near,
                "netns",
                hub,
                "type",
                "veth",
                "peer",
                "name",
                far,
                "netns",
                ns[host],
            )
            _ip("-n", hub, "link", "set", near, "master", "br0", "up")
            _ip("-n", ns[host], "addr", "add", f"{ADDRESSES[host]}/24", "dev", far)
            _ip("-n", ns[host], "link", "set", far, "up")
        yield ns
    finally:
        for name in made:
            subprocess.run(["ip", "netns", "del", name], capture_output=True, timeout=30)


def write_hosts(path: Path, roles: dict[str, list[str]], tls_certs: str | None = None) -> Path:
    """A hosts file; with ``tls_certs`` (a directory) every endpoint is ``tls/``."""
    router = ROUTER.replace("tcp/", "tls/", 1) if tls_certs else ROUTER
    return write_hosts_file(path, router, roles, ADDRESSES, tls_certs=tls_certs)


class Hosts:
    """``plumeswarm up`` per namespace; stops them all and checks nothing survives. ``stepped``:
    every host flies the stepped scenario (``up --stepped``), so a demo attached to it steps
    the clock and each command lands on a known tick. Free-running, when each vehicle's mission
    starts depends on the machine's load, and the seed scenario's return legs cross at one
    altitude: a loaded run once started uav1 and uav3 so that they met mid-air. ``up_args``: more
    options of every host's ``plumeswarm up`` (``--vehicles-per-process 8``)."""

    def __init__(
        self,
        ns: dict[str, str],
        hosts_file: Path,
        out: Path,
        stepped: bool = False,
        up_args: Sequence[str] = (),
    ):
        self.ns, self.hosts_file, self.out = ns, hosts_file, out
        self.stepped = stepped
        self.up_args = tuple(up_args)
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self.family: list[psutil.Process] = []

    def env(self) -> dict[str, str]:
        return dict(os.environ, PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1")

    def up(self, host: str) -> dict[str, int]:
        run = self.out / host
        run.mkdir(parents=True)
        with open(self.out / f"{host}.console", "wb") as console:
            proc = subprocess.Popen(
                [
                    "ip",
                    "netns",
                    "exec",
                    self.ns[host],
                    sys.executable,
                    "-m",
                    "plumeswarm",
                    "up",
                    "--hosts",
                    str(self.hosts_file),
                    "--host",
                    host,
                    "--out",
                    str(run),
                    *(["--stepped"] if self.stepped else []),
                    *self.up_args,
                ],
                cwd=REPO,
                env=self.env(),
                stdout=console,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        self.procs[host] = proc
        pids_file = run / "pids.json"

        def ready() -> bool:
            if proc.poll() is not None:
                raise AssertionError(
                    f"{host}: up exited {proc.returncode}: "
                    + (self.out / f"{host}.console").read_text()[-2000:]
                )
            return pids_file.exists()

        wait_until(ready, 120.0, f"{host} to be up (pids.json)")
        root = psutil.Process(proc.pid)
        self.family += [root, *root.children(recursive=True)]
        return json.loads(pids_file.read_text())

    def run(
        self, host: str, *args: str, timeout_s: float, module: str = "plumeswarm"
    ) -> subprocess.CompletedProcess[str]:
        """``python -m MODULE ARGS`` inside ``host``'s namespace, to completion."""
        return subprocess.run(
            ["ip", "netns", "exec", self.ns[host], sys.executable, "-m", module, *args],
            cwd=REPO,
            env=self.env(),
            capture_output=True,
            text=True,
            timeout=timeout_s,
        )

    def stop(self, first: Sequence[str] = ()) -> None:
        """Stops ``first``, then every other host and process in the reverse of their start."""
        rest = [name for name in reversed(list(self.procs)) if name not in first]
        for host in [*first, *rest]:
            proc = self.procs[host]
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(10)
        _, alive = psutil.wait_procs(self.family, timeout=10.0)
        for p in alive:
            p.kill()
        assert alive == [], f"processes left behind: {alive}"


def fly_demo(h: Hosts, out: Path, router: str, *extra: str) -> dict[str, Any]:
    """``plumeswarm demo --attach ROUTER`` from ``gcs``: every vehicle completes and lands."""
    result = h.run(
        "gcs",
        "demo",
        "--attach",
        router,
        *extra,
        "--out",
        str(out),
        "--timeout",
        "900",
        timeout_s=1000,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-2000:]
    summary: dict[str, Any] = json.loads((out / "summary.json").read_text())
    assert summary["ok"]
    assert summary["clock"] == ("stepped" if h.stepped else "lockstep"), summary["clock"]
    for vid, v in summary["vehicles"].items():
        assert v["mission_completed"] and v["landed"], vid
        assert v["readings"] > 0 and v["max_concentration_g_m3"] > 0.0, vid
    return summary


def netns_of(pid: int) -> int:
    return os.stat(f"/proc/{pid}/ns/net").st_ino


def test_bus_spans_namespaces_over_tcp(hosts: dict[str, str], tmp_path: Path) -> None:
    """Router and plume in `sim`; `plumeswarm status` in `gcs` sees them through the veth."""
    hosts_file = write_hosts(tmp_path / "hosts.toml", {"sim": ["router", "plume"]})
    h = Hosts(hosts, hosts_file, tmp_path)
    try:
        pids = h.up("sim")
        assert netns_of(pids["plume"]) != netns_of(os.getpid())
        result = h.run(
            "gcs", "status", "--json", "--connect", ROUTER, "--timeout", "20", timeout_s=60
        )
        assert result.returncode == 0, result.stderr
        nodes = {n["name"]: n for n in json.loads(result.stdout)["nodes"]}
        assert nodes["plume"]["pid"] == pids["plume"]
        assert nodes["router"]["pid"] == pids["router"]
    finally:
        h.stop()


def test_seed_scenario_flies_across_three_namespaces(hosts: dict[str, str], tmp_path: Path) -> None:
    gcs_roles = ["gateway"]
    hosts_file = write_hosts(
        tmp_path / "hosts.toml",
        {"sim": ["router", "physics", "plume"], "agents": ["autopilot"], "gcs": gcs_roles},
    )
    h = Hosts(hosts, hosts_file, tmp_path, stepped=True)
    try:
        sim = h.up("sim")
        agents = h.up("agents")
        spaces = {netns_of(sim["physics"]), netns_of(agents["autopilot-uav1"])}
        if gcs_roles:
            spaces.add(netns_of(h.up("gcs")["gateway"]))
        assert len(spaces) == (3 if gcs_roles else 2), "one namespace per host"
        assert netns_of(sim["physics"]) != netns_of(os.getpid())
        # The demo driver joins from the gcs namespace: the third host in every case.
        fly_demo(h, tmp_path / "demo", ROUTER)
    finally:
        h.stop()
