"""QGroundControl's flows, replayed with raw pymavlink, on three vehicles at once: the connect
sequence, takeoff (NAV_TAKEOFF while disarmed, then ARM) and a mode change by SET_MODE (RTL),
start mission (SET_MODE mission while disarmed, then ARM) with every item reached, and the
data-link-loss failsafe configured by PARAM_SET and fed by the GCS's heartbeats. Against the
real stack (plume + physics + autopilots).
"""

from __future__ import annotations

from pathlib import Path

from gcs_bridge.dialect import mavlink
from gcs_bridge.params import float_bits_of_int
from swarmbus.scenario import Origin
from tests.support.gateway_stack import gateway, vehicles
from tests.support.mavclient import MavClient, write_scenario
from tests.support.procs import zenoh_network

NAN = float("nan")
ORIGIN = Origin()
ACCEPTED = mavlink.MAV_RESULT_ACCEPTED


def at_altitude(c: MavClient, sysid: int, metres: float) -> None:
    c.wait_above(sysid, metres - 0.5)


def test_qgc_flows(tmp_path: Path) -> None:
    scenario, gcs_port, _ = write_scenario(tmp_path / "scenario.toml", 3)
    with (
        zenoh_network() as (net, _router),
        vehicles(net, scenario, tmp_path, ["uav1", "uav2", "uav3"], backend="real"),
        gateway(net, scenario, tmp_path, "cmd_timeout_s=3"),
        MavClient(gcs_port) as c,
    ):
        c.beat = True
        for sysid in (1, 2, 3):
            c.wait_standby(sysid)
            assert c.command(sysid, mavlink.MAV_CMD_REQUEST_MESSAGE, 148) == ACCEPTED
            assert c.command(sysid, mavlink.MAV_CMD_REQUEST_MESSAGE, 300) == ACCEPTED
            assert c.command(sysid, mavlink.MAV_CMD_REQUEST_MESSAGE, 435) == (
                mavlink.MAV_RESULT_UNSUPPORTED
            )
            assert len(c.params(sysid)) >= 9
            assert [i.command for i in c.download(sysid)] == [22, 16, 16, 21]

        # uav1 — QGC's takeoff: NAV_TAKEOFF (AMSL) while disarmed, ARM once accepted
        assert c.command(1, 22, -1, 0, 0, NAN, NAN, NAN, ORIGIN.alt_m + 6.0) == ACCEPTED
        c.wait_mode(1, 4, 2, armed=False)
        assert c.command(1, 400, 1) == ACCEPTED
        # uav2 — QGC's start mission: SET_MODE mission while disarmed, ARM once it shows
        c.set_mode(2, 4, 4)
        c.wait_mode(2, 4, 4, armed=False)
        assert c.command(2, 400, 1) == ACCEPTED
        c.wait_mode(2, 4, 4, armed=True)

        at_altitude(c, 1, 6.0)
        c.wait_mode(1, 4, 3, armed=True)  # hold after the takeoff
        c.set_mode(1, 4, 5)  # RTL by SET_MODE: QGC sees it in the heartbeat
        c.wait_mode(1, 4, 5, armed=True)

        c.until(
            "4 items reached by uav2", lambda: len(c.logged("MISSION_ITEM_REACHED", 2)) >= 4, 180.0
        )
        assert [m.seq for m in c.logged("MISSION_ITEM_REACHED", 2)] == [0, 1, 2, 3]
        c.wait_disarmed(2, 180.0)  # the last item lands
        c.wait_disarmed(1, 180.0)  # RTL lands too

        # uav3 — data-link loss: the failsafe is configured by PARAM_SET (the autopilot's
        # values), fed by our heartbeats, and trips in sim time once they stop
        assert c.param_set(
            3, "COM_DL_LOSS_T", float_bits_of_int(2), mavlink.MAV_PARAM_TYPE_INT32
        ).param_value == float_bits_of_int(2)
        assert c.param_set(
            3, "NAV_DLL_ACT", float_bits_of_int(3), mavlink.MAV_PARAM_TYPE_INT32
        ).param_value == float_bits_of_int(3)
        assert c.command(3, 400, 1) == ACCEPTED  # MAVSDK-style: arm, then take off
        assert c.command(3, 22, 0, 0, 0, NAN, NAN, NAN, NAN) == ACCEPTED  # MIS_TAKEOFF_ALT
        at_altitude(c, 3, 9.5)
        c.wait_mode(3, 4, 3, armed=True)
        c.beat = False  # the ground station goes silent
        c.wait_mode(3, 4, 6, armed=True, timeout_s=120.0)  # NAV_DLL_ACT = 3: land
        c.wait_disarmed(3, 180.0)
