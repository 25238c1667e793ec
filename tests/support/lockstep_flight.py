"""A lockstep flight that a test drives from another network namespace, to compare two runs bit
for bit.

``python -m tests.support.lockstep_flight ROUTER SCENARIO START_TICK RELEASE OUT``: joins the bus
at ROUTER and keeps every vehicle's states and readings (:class:`tests.support.flown.Flown`);
once every vehicle of SCENARIO has reached tick START_TICK (held there by a scripted
participant, the scenario's last vehicle, until RELEASE exists) it arms the others and starts
their missions, then touches RELEASE. It writes ``OUT/on_leg`` (the last tick of uav1 seen once
uav1 flies its first mission leg) and, once every mission has finished and every vehicle
landed, ``OUT/flown.msgpack`` (:func:`tests.support.flown.save`), and exits.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from swarmbus.keys import Keys
from swarmbus.messages import Arm, CommandReply, MissionStart
from swarmbus.reqrep import request
from swarmbus.scenario import load_scenario
from swarmbus.session import NetworkConfig, open_session
from tests.support.flown import Flown, save
from tests.support.scale import patience


def main() -> int:
    router, scenario_path, start = sys.argv[1], Path(sys.argv[2]), int(sys.argv[3])
    release, out = Path(sys.argv[4]), Path(sys.argv[5])
    sc = load_scenario(scenario_path)
    ids = [v.id for v in sc.vehicles]
    f = Flown(tuple(ids[:-1]), ids[-1], sc.time.control_hz)
    slow = patience(f.vehicles)
    keys = Keys(sc.world.name)
    with open_session(NetworkConfig(connect=[router], listen=[])) as session:
        subs = [
            session.declare_subscriber(keys.all_vehicle_states(), f.on_state),
            session.declare_subscriber(keys.all_vehicle_status(), f.on_status),
            session.declare_subscriber(keys.all_vehicle_concentration(), f.on_reading),
        ]
        f.wait(lambda: all(f.last_tick(v) >= start for v in ids), 120.0 * slow, f"tick {start}")
        for vid in f.vehicles:
            for cmd in (Arm(), MissionStart(start_index=0)):
                reply = request(session, keys.vehicle_cmd(vid), cmd, CommandReply, 30.0)
                assert reply.accepted, (vid, cmd, reply.reason)
        assert all(f.last_tick(v) == start for v in f.vehicles), "the gate did not hold"
        release.touch()
        (out / "on_leg").write_text(str(f.on_first_leg("uav1", 300.0 * slow)))
        f.wait(f.done, 300.0 * slow, "every mission finished and landed")
        time.sleep(0.5)  # a few more ticks on the ground
        for sub in subs:
            sub.undeclare()
    save(f, out / "flown.msgpack")
    return 0


if __name__ == "__main__":
    sys.exit(main())
