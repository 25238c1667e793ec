"""The ros2 role on a bare router: it subscribes to a bus stream only while a ROS 2 subscriber
wants a topic made from it (a publisher of ours on ``sim/tick`` sees a match only then), what
it publishes then reaches that subscriber; bad options and bad ``export ros2`` input are one
line each."""

from __future__ import annotations

import time
from pathlib import Path

import msgspec
import zenoh

from swarmbus.codec import encode
from swarmbus.messages import SimTick
from tests.support.messages_samples import STATE
from tests.support.procs import Network, NodeProcs, keys_for, run_cli, wait_until
from tests.support.ros2_probe import Ros2Probe

DOMAIN = 3
QUIET_S = 2.0


def matching(pub: zenoh.Publisher) -> bool:
    status: object = pub.matching_status
    return bool(getattr(status, "matching", status))


def test_bus_streams_are_subscribed_only_while_a_ros2_subscriber_wants_them(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> None:
    net, session = network
    keys = keys_for()
    tick_pub = session.declare_publisher(keys.tick())
    reading_pub = session.declare_publisher(keys.vehicle_concentration("uav1"))
    probe = Ros2Probe(session, DOMAIN)
    with NodeProcs(net, log_dir=tmp_path) as procs:
        procs.start("ros2", "--set", f"domain_id={DOMAIN}")
        clock = wait_until(lambda: probe.publisher("/clock"), 60.0, "the bridge's /clock")
        deadline = time.monotonic() + QUIET_S
        while time.monotonic() < deadline:  # no ROS 2 subscriber: no bus subscription
            assert not matching(tick_pub) and not matching(reading_pub)
            time.sleep(0.1)
        probe.subscribe(clock)
        wait_until(lambda: matching(tick_pub), 10.0, "the bridge to subscribe to sim/tick")
        assert not matching(reading_pub)  # nobody wants /uav1/gas
        state = msgspec.structs.replace(STATE, sim_time_s=12.5, tick=1500)
        tick = SimTick(tick=1500, sim_time_s=12.5, control_dt_s=1 / 120, states=[state])
        wait_until(lambda: tick_pub.put(encode(tick)) or probe.messages("/clock"), 10.0, "/clock")
        got = probe.messages("/clock")[0].message.clock
        assert (got.sec, got.nanosec) == (12, 500_000_000)
        probe.close()  # the ROS 2 subscriber leaves: the bridge lets go of sim/tick
        wait_until(lambda: not matching(tick_pub), 10.0, "the bridge to leave sim/tick")
    assert probe.errors == []


def test_bad_domain_id_is_one_line() -> None:
    res = run_cli(["node", "ros2", "--set", "domain_id=999"], timeout_s=60)
    assert res.returncode == 2
    assert "domain_id" in res.stderr and "Traceback" not in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1, res.stderr


def test_export_ros2_bad_input_is_one_line(tmp_path: Path) -> None:
    missing = run_cli(["export", "ros2", str(tmp_path / "nope.mcap"), str(tmp_path / "bag")])
    assert missing.returncode != 0 and "no such file" in missing.stderr
    assert "Traceback" not in missing.stderr
    not_mcap = tmp_path / "x.mcap"
    not_mcap.write_text("hello")
    res = run_cli(["export", "ros2", str(not_mcap), str(tmp_path / "bag")])
    assert res.returncode != 0 and "Traceback" not in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1, res.stderr
