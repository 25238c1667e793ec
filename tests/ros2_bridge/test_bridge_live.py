"""The ROS 2 bridge on a real run (``plumeswarm up --headless --record --ros2``), seen by a ROS 2
client built from rmw_zenoh's design, not from the bridge (tests/support/ros2_probe.py): the
graph from the liveliness tokens, the topics' values against the bus's own messages, a
``cmd_vel`` that flies a vehicle, a malformed one that does nothing, the bridge killed and
restarted by the supervisor; then ``plumeswarm export ros2`` of the run's recording, opened by
``rosbags``' rosbag2 reader."""

from __future__ import annotations

import itertools
import math
import os
import signal
import threading
import time
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from agents import CommandRejected, VehicleCommander
from deploy.scaling import write_scenario
from recorder.reader import Recording
from swarmbus.codec import decode
from swarmbus.messages import (
    AnemometerReading,
    Arm,
    CommandReply,
    ConcentrationReading,
    FlightMode,
    NodeHealth,
    SetMode,
    SimTick,
    Takeoff,
    VehicleState,
)
from swarmbus.scenario import load_scenario, resolve_scenario_path
from swarmbus.session import NetworkConfig, open_session
from tests.support.procs import keys_for, run_cli, wait_until
from tests.support.ros2_probe import Entity, Ros2Probe, twist_cdr
from tests.support.upstack import Up, plumeswarm_up

DOMAIN = 7
# Published hashes (REP-2011 RIHS01), as `ros2 topic info --verbose` prints them for these types
# (the ROS 2 documentation's "Understanding topics" tutorial shows Twist's).
TWIST_HASH = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
CLOCK_HASH = "RIHS01_692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564"
TYPES = {
    "/clock": "rosgraph_msgs/msg/Clock",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/plume/markers": "visualization_msgs/msg/MarkerArray",
}
PER_VEHICLE = {
    "odom": "nav_msgs/msg/Odometry",
    "fix": "sensor_msgs/msg/NavSatFix",
    "gas": "sensor_msgs/msg/PointCloud",
    "wind": "geometry_msgs/msg/Vector3Stamped",
}
FLY_ID = "uav1"
CMD_BODY = (1.5, 1.0, 0.0)  # forward and left, m/s
WAIT_S = 90.0


def ns(sim_time_s: float) -> int:
    return round(sim_time_s * 1e9)


def stamp_ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


@dataclass
class Bus:
    """What the test itself hears on our bus, by sim time in ns."""

    states: dict[int, dict[str, VehicleState]] = field(default_factory=dict)
    readings: dict[tuple[str, int], ConcentrationReading] = field(default_factory=dict)
    winds: dict[tuple[str, int], AnemometerReading] = field(default_factory=dict)
    health: list[NodeHealth] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def on_tick(self, sample: Any) -> None:
        tick = decode(sample.payload.to_bytes(), SimTick)
        with self.lock:
            self.states[ns(tick.sim_time_s)] = {s.vehicle_id: s for s in tick.states}

    def on_reading(self, sample: Any) -> None:
        r = decode(sample.payload.to_bytes(), ConcentrationReading)
        with self.lock:
            self.readings[(r.vehicle_id, ns(r.sim_time_s))] = r

    def on_wind(self, sample: Any) -> None:
        w = decode(sample.payload.to_bytes(), AnemometerReading)
        with self.lock:
            self.winds[(w.vehicle_id, ns(w.sim_time_s))] = w

    def on_health(self, sample: Any) -> None:
        with self.lock:
            self.health.append(decode(sample.payload.to_bytes(), NodeHealth))

    def newest(self, vehicle_id: str) -> VehicleState | None:
        with self.lock:
            if not self.states:
                return None
            return self.states[max(self.states)].get(vehicle_id)


@dataclass
class Run:
    graph: list[Entity] = field(default_factory=list)
    probe_errors: list[str] = field(default_factory=list)
    received: dict[str, list[Any]] = field(default_factory=dict)
    bus: Bus = field(default_factory=Bus)
    flown: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # start, end, commanded
    offboard_after_valid: CommandReply | None = None
    offboard_after_malformed: CommandReply | None = None
    held_before: VehicleState | None = None
    held_after: VehicleState | None = None
    restarted: bool = False
    clock_after_restart: list[Any] = field(default_factory=list)
    recording: Path = Path()
    log: str = ""
    wall_ns: tuple[int, int] = (0, 0)  # the live part's wall-clock span


def bridge_scenario(tmp: Path) -> Path:
    sc = load_scenario(resolve_scenario_path(None))
    sc = msgspec.structs.replace(
        sc,
        time=msgspec.structs.replace(sc.time, mode="realtime"),
        anemometer=msgspec.structs.replace(sc.anemometer, period_ticks=12),
    )
    return write_scenario(sc, tmp / "scenario.toml")


def subscribe_all(probe: Ros2Probe, ids: list[str]) -> None:
    wanted = set(TYPES) | {f"/{v}/{leaf}" for v in ids for leaf in PER_VEHICLE}
    found = wait_until(
        lambda: (
            (pubs := {e.topic: e for e in probe.of_kind("MP")}) and wanted <= set(pubs) and pubs
        ),
        WAIT_S,
        "the bridge's publishers in the ROS graph",
    )
    for topic in sorted(wanted):
        probe.subscribe(found[topic])


def fly_with_cmd_vel(run: Run, probe: Ros2Probe, session: Any) -> None:
    cmd = VehicleCommander(session, keys_for(), FLY_ID, 5.0)
    deadline = time.monotonic() + 60.0
    for command in (Arm(), Takeoff(altitude_m=8.0)):
        reply = cmd.send(command, retry_until=deadline)
        assert reply.accepted, reply
    wait_until(
        lambda: (s := run.bus.newest(FLY_ID)) is not None and s.position_enu_m[2] > 6.0,
        WAIT_S,
        f"{FLY_ID} to climb",
    )
    twist_ms = next(e for e in probe.of_kind("MS") if e.topic == f"/{FLY_ID}/cmd_vel")
    pub = session.declare_publisher(twist_ms.data_key())
    stop = threading.Event()

    def stream() -> None:
        while not stop.wait(0.05):
            pub.put(twist_cdr(*CMD_BODY, 0.0, 0.0, 0.0))

    streamer = threading.Thread(target=stream, daemon=True)
    streamer.start()
    try:
        time.sleep(1.0)  # PX4: a setpoint stream before the switch to offboard
        reply = cmd.send(SetMode(mode=FlightMode.OFFBOARD), retry_until=time.monotonic() + 10)
        run.offboard_after_valid = reply
        assert reply.accepted, reply
        time.sleep(0.5)
        start = run.bus.newest(FLY_ID)
        assert start is not None
        time.sleep(4.0)
        end = run.bus.newest(FLY_ID)
        assert end is not None
    finally:
        stop.set()
        streamer.join(5)
        pub.undeclare()
    # The commanded direction: the body's forward/left turned by its heading, from scipy.
    r = Rotation.from_quat(start.attitude_xyzw)
    commanded = r.apply(np.array(CMD_BODY))
    commanded[2] = 0.0
    run.flown = (np.array(start.position_enu_m), np.array(end.position_enu_m), commanded)


def send_malformed(run: Run, probe: Ros2Probe, session: Any) -> None:
    """Payloads that are not Twists on the flying vehicle's cmd_vel, then a switch to offboard:
    the autopilot refuses it unless a setpoint arrived within its offboard timeout."""
    time.sleep(2.0)  # the valid stream is long gone: the vehicle holds
    run.held_before = run.bus.newest(FLY_ID)
    entity = next(e for e in probe.of_kind("MS") if e.topic == f"/{FLY_ID}/cmd_vel")
    pub = session.declare_publisher(entity.data_key())
    string_cdr = b"\x00\x01\x00\x00" + (6).to_bytes(4, "little") + b"hello\x00"
    for payload in (b"\x00\x01", string_cdr, twist_cdr(1, 0, 0, 0, 0, 0) + b"\x00" * 8):
        pub.put(payload)
    pub.undeclare()
    cmd = VehicleCommander(session, keys_for(), FLY_ID, 5.0)
    try:
        run.offboard_after_malformed = cmd.send(SetMode(mode=FlightMode.OFFBOARD))
    except CommandRejected as exc:
        run.offboard_after_malformed = CommandReply(
            vehicle_id=FLY_ID, accepted=False, code=exc.code, reason=exc.reason
        )
    time.sleep(2.0)
    run.held_after = run.bus.newest(FLY_ID)


def kill_bridge(run: Run, up: Up, probe: Ros2Probe) -> None:
    old = up.pids()["ros2"]
    os.kill(old, signal.SIGKILL)
    up.restarted("ros2", old)
    wait_until(
        lambda: any(e.fields["node"] == "plumeswarm" for e in probe.of_kind("NN")),
        WAIT_S,
        "the restarted bridge's node token",
    )
    n = len(probe.messages("/clock"))  # the restarted publisher's key is the same
    wait_until(lambda: len(probe.messages("/clock")) > n + 20, WAIT_S, "/clock after the restart")
    run.clock_after_restart = [m.message for m in probe.messages("/clock")[n:]]
    run.restarted = True


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Run]:
    tmp = tmp_path_factory.mktemp("ros2")
    path = bridge_scenario(tmp)
    ids = [v.id for v in load_scenario(path).vehicles]
    out = Run()
    args = ["--headless", "--record", "--ros2-domain", str(DOMAIN)]
    with plumeswarm_up(path, tmp, *args) as up:
        keys = keys_for()
        with open_session(NetworkConfig(connect=[up.endpoint], listen=[])) as session:
            subs = [
                session.declare_subscriber(keys.tick(), out.bus.on_tick),
                session.declare_subscriber(keys.all_vehicle_concentration(), out.bus.on_reading),
                session.declare_subscriber(keys.all_vehicle_wind(), out.bus.on_wind),
                session.declare_subscriber(keys.node_health("ros2"), out.bus.on_health),
            ]
            probe = Ros2Probe(session, DOMAIN)
            started_ns = time.time_ns()
            try:
                subscribe_all(probe, ids)
                out.graph = list(probe.entities.values())
                fly_with_cmd_vel(out, probe, session)
                send_malformed(out, probe, session)
                wait_until(
                    lambda: any(
                        m.ns == "plume_isosurface"
                        for r in probe.messages("/plume/markers")
                        for m in r.message.markers
                    ),
                    WAIT_S,
                    "the plume's isosurfaces on /plume/markers",
                    poll_s=0.5,
                )
                kill_bridge(out, up, probe)
                out.received = {t: [r for r in v] for t, v in probe.received.items()}
                out.probe_errors = list(probe.errors)
                out.wall_ns = (started_ns, time.time_ns())
            finally:
                probe.close()
                for sub in subs:
                    sub.undeclare()
        out.log = (up.run / "ros2.log").read_text()
    out.recording = up.run / "recording.mcap"
    yield out


def test_graph_shows_the_node_its_publishers_and_subscriptions(run: Run) -> None:
    ids = ["uav1", "uav2", "uav3"]
    nodes = [e for e in run.graph if e.kind == "NN"]
    assert [(e.fields["namespace"], e.fields["node"]) for e in nodes] == [("%", "plumeswarm")]
    pubs = {e.topic: e for e in run.graph if e.kind == "MP"}
    expected = dict(TYPES) | {f"/{v}/{leaf}": t for v in ids for leaf, t in PER_VEHICLE.items()}
    assert {t: e.ros_type for t, e in pubs.items()} == expected
    subs = {e.topic: e for e in run.graph if e.kind == "MS"}
    assert set(subs) == {f"/{v}/cmd_vel" for v in ids}
    assert all(e.fields["hash"] == TWIST_HASH for e in subs.values())
    assert pubs["/clock"].fields["hash"] == CLOCK_HASH
    store = get_typestore(Stores.ROS2_KILTED)  # every other hash: the distribution's own
    assert all(e.fields["hash"] == store.hash_rihs01(e.ros_type) for e in pubs.values())
    # Every entity hangs off the node: the same session, node id, domain
    assert {(e.fields["zid"], e.fields["nid"], e.fields["domain"]) for e in run.graph} == {
        (nodes[0].fields["zid"], nodes[0].fields["nid"], str(DOMAIN))
    }


def test_every_sample_has_an_attachment_and_a_cdr_payload_of_its_type(run: Run) -> None:
    assert run.probe_errors == []
    for topic in ("/clock", "/tf", "/uav1/odom", "/uav1/gas"):
        got = run.received.get(topic, [])
        assert len(got) > 10, topic
        # nothing was published before this subscriber came: its first sample is the first
        assert got[0].sequence == 1, (topic, got[0].sequence)
        # the source timestamp is the wall clock (rmw_zenoh's), within the live part
        assert all(run.wall_ns[0] <= r.source_timestamp_ns <= run.wall_ns[1] for r in got)
        assert len({r.gid for r in got[:5]}) == 1


def test_clock_advances_with_sim_time(run: Run) -> None:
    clocks = [stamp_ns(r.message.clock) for r in run.received["/clock"]]
    assert len(clocks) > 50
    assert all(b > a for a, b in itertools.pairwise(clocks))
    with run.bus.lock:
        known = set(run.bus.states)
    on_bus = [c for c in clocks if c in known]
    assert len(on_bus) >= 0.9 * len(clocks)  # each a tick's sim time (the test may miss a few)
    seqs = [r.sequence for r in run.received["/clock"][:50]]
    assert all(b > a for a, b in itertools.pairwise(seqs))


def _state_at(run: Run, t_ns: int, vid: str) -> VehicleState | None:
    with run.bus.lock:
        return run.bus.states.get(t_ns, {}).get(vid)


def test_tf_and_odometry_equal_the_vehicles_states_on_the_bus(run: Run) -> None:
    compared = 0
    for r in run.received["/uav1/odom"]:
        odom = r.message
        st = _state_at(run, stamp_ns(odom.header.stamp), "uav1")
        if st is None:
            continue
        compared += 1
        assert (odom.header.frame_id, odom.child_frame_id) == ("map", "uav1/base_link")
        p, q = odom.pose.pose.position, odom.pose.pose.orientation
        assert (p.x, p.y, p.z) == tuple(st.position_enu_m)
        assert (q.x, q.y, q.z, q.w) == tuple(st.attitude_xyzw)
        v = odom.twist.twist.linear  # in the body frame (nav_msgs/Odometry: child_frame_id)
        expected = Rotation.from_quat(st.attitude_xyzw).inv().apply(st.velocity_enu_m_s)
        assert np.allclose((v.x, v.y, v.z), expected, rtol=0, atol=1e-9)
    assert compared > 20
    compared = 0
    for r in run.received["/tf"]:
        for t in r.message.transforms:
            st = _state_at(run, stamp_ns(t.header.stamp), t.child_frame_id.split("/")[0])
            if st is None:
                continue
            compared += 1
            tr, rot = t.transform.translation, t.transform.rotation
            assert t.header.frame_id == "map"
            assert (tr.x, tr.y, tr.z) == tuple(st.position_enu_m)
            assert (rot.x, rot.y, rot.z, rot.w) == tuple(st.attitude_xyzw)
    assert compared > 60


def test_fix_is_the_states_geodetic_position(run: Run) -> None:
    compared = 0
    for r in run.received["/uav2/fix"]:
        st = _state_at(run, stamp_ns(r.message.header.stamp), "uav2")
        if st is not None:
            compared += 1
            m = r.message
            assert (m.latitude, m.longitude, m.altitude) == (st.lat_deg, st.lon_deg, st.alt_m)
    assert compared > 20


def test_gas_and_wind_equal_the_readings_on_the_bus(run: Run) -> None:
    compared = 0
    for vid in ("uav1", "uav2", "uav3"):
        for r in run.received[f"/{vid}/gas"]:
            cloud = r.message
            with run.bus.lock:
                bus = run.bus.readings.get((vid, stamp_ns(cloud.header.stamp)))
            if bus is None:
                continue
            compared += 1
            assert cloud.header.frame_id == f"{vid}/base_link"
            channels = {c.name: float(c.values[0]) for c in cloud.channels}
            expected = bus.reported_g_m3 if bus.available else math.nan
            assert channels["concentration_g_m3"] == pytest.approx(
                float(np.float32(expected)), nan_ok=True, rel=0, abs=0
            )
    assert compared > 20
    compared = 0
    for r in run.received["/uav1/wind"]:
        with run.bus.lock:
            bus_w = run.bus.winds.get(("uav1", stamp_ns(r.message.header.stamp)))
        if bus_w is not None:
            compared += 1
            v = r.message.vector
            assert (v.x, v.y, v.z) == tuple(bus_w.wind_enu_m_s)
    assert compared > 5


def test_markers_show_the_source_and_the_plume(run: Run) -> None:
    sc = load_scenario(resolve_scenario_path(None))
    arrays = [r.message for r in run.received["/plume/markers"]]
    drawn = [a for a in arrays if any(m.ns == "plume_isosurface" for m in a.markers)]
    assert drawn
    markers = drawn[-1].markers
    sources = [m for m in markers if m.ns == "source"]
    assert [(m.pose.position.x, m.pose.position.y, m.pose.position.z) for m in sources] == [
        (s.x_m, s.y_m, s.release_height_m) for s in sc.plume.sources
    ]
    iso = [m for m in markers if m.ns == "plume_isosurface"]
    assert iso and all(m.type == 11 and len(m.points) % 3 == 0 and m.points for m in iso)


def test_cmd_vel_flies_the_vehicle_in_the_commanded_direction(run: Run) -> None:
    assert run.flown is not None
    start, end, commanded = run.flown
    moved = end - start
    moved[2] = 0.0
    assert np.linalg.norm(moved) > 2.0, moved
    cosine = float(moved @ commanded / (np.linalg.norm(moved) * np.linalg.norm(commanded)))
    assert cosine >= 0.99, (moved, commanded)


def test_a_malformed_cmd_vel_is_rejected_with_a_log_line_and_changes_nothing(run: Run) -> None:
    assert run.log.count(f"/{FLY_ID}/cmd_vel: rejected payload") == 3, run.log[-2000:]
    # After the valid stream the switch to offboard was accepted; after the malformed payloads
    # it is refused: none of them reached the autopilot as a setpoint.
    assert run.offboard_after_valid is not None and run.offboard_after_valid.accepted
    refused = run.offboard_after_malformed
    assert refused is not None and not refused.accepted, refused
    assert "setpoint" in refused.reason
    before, after = run.held_before, run.held_after
    assert before is not None and after is not None
    assert after.position_enu_m == pytest.approx(before.position_enu_m, abs=0.3)


def test_the_bridge_is_restarted_after_it_dies_and_publishes_again(run: Run) -> None:
    assert run.restarted
    stamps = [stamp_ns(c.clock) for c in run.clock_after_restart]
    assert stamps == sorted(stamps) and stamps[-1] > stamps[0]


def test_export_ros2_writes_a_rosbag2_with_the_recordings_messages(
    run: Run, tmp_path: Path
) -> None:
    out = tmp_path / "bag"
    res = run_cli(["export", "ros2", str(run.recording), str(out)], timeout_s=600)
    assert res.returncode == 0, res.stderr
    assert (out / "metadata.yaml").exists()
    ticks: list[float] = []
    readings: dict[str, list[float]] = defaultdict(list)
    for rec in Recording.open(run.recording).messages():
        msg = rec.message()
        if isinstance(msg, SimTick):
            ticks.append(msg.sim_time_s)
        elif isinstance(msg, ConcentrationReading):
            readings[msg.vehicle_id].append(msg.sim_time_s)
    store = get_typestore(Stores.ROS2_KILTED)
    by_topic: dict[str, list[int]] = defaultdict(list)
    with Reader(out) as reader:
        assert {c.topic: c.msgtype for c in reader.connections}["/uav1/odom"] == PER_VEHICLE["odom"]
        for conn, timestamp, data in reader.messages():
            ros_msg: Any = store.deserialize_cdr(data, conn.msgtype)
            by_topic[conn.topic].append(timestamp)
            if conn.topic == "/clock":
                assert stamp_ns(ros_msg.clock) == timestamp
            elif hasattr(ros_msg, "header"):
                assert stamp_ns(ros_msg.header.stamp) == timestamp
    assert sorted(by_topic["/clock"]) == sorted(ns(t) for t in ticks)
    assert len(by_topic["/uav2/odom"]) == len(ticks)
    for vid, times in readings.items():
        assert sorted(by_topic[f"/{vid}/gas"]) == sorted(ns(t) for t in times)
    assert by_topic["/plume/markers"]
