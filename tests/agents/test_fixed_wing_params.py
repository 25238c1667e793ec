"""A fixed wing's PX4 parameters through the autopilot's GetParams / SetParam (fused runner, on
the ground): the type file's values by their PX4 names, refusals (out of bounds, below the
stall speed the type file states, MIN <= TRIM <= MAX broken) and a value that is then what the
stall protection checks against."""

from __future__ import annotations

import tomllib

from plumeswarm.experiments.fused import FusedRunner
from swarmbus.messages import GetParams, Goto, RejectCode, SetParam
from swarmbus.vehicle_types import VEHICLES_DIR, load_vehicle_type
from tests.support.fixed_wing import plane_scenario

FILE = tomllib.loads((VEHICLES_DIR / "aerosonde.toml").read_text())["fixed_wing"]["params"]
STALL_M_S = 15.3  # the type file's note: C_L peaks at 1.63 → 15.3 m/s level at 13.5 kg


def test_stall_speed_is_the_type_files() -> None:
    assert abs(load_vehicle_type("aerosonde").stall_speed_m_s - STALL_M_S) < 0.05
    assert load_vehicle_type("iris").stall_speed_m_s == 0.0


def test_parameters_read_refused_and_set() -> None:
    with FusedRunner(plane_scenario(), plume=False) as run:
        params = run.command("p", GetParams()).params or {}
        assert {k: params[k] for k in FILE} == FILE
        assert params["NAV_L1_PERIOD"] == 20.0  # a schema default, not in the file
        assert "MPC_XY_CRUISE" not in params and "RTL_RETURN_ALT" in params

        def refused(name: str, value: float, why: str) -> None:
            reply = run.command("p", SetParam(name=name, value=value))
            assert not reply.accepted and reply.code == RejectCode.INVALID, reply
            assert why in reply.reason, reply.reason

        refused("FW_AIRSPD_MIN", STALL_M_S - 0.5, "below the stall speed 15.3 m/s")
        refused("FW_AIRSPD_MIN", -1.0, "FW_AIRSPD_MIN")
        refused("FW_AIRSPD_TRIM", 36.0, "FW_AIRSPD_MIN <= FW_AIRSPD_TRIM <= FW_AIRSPD_MAX")
        refused("FW_THR_MAX", 1.5, "FW_THR_MAX")
        assert (run.command("p", GetParams()).params or {})["FW_AIRSPD_MIN"] == 18.0

        reply = run.command("p", SetParam(name="FW_AIRSPD_MIN", value=21.0))
        assert reply.accepted and (reply.params or {})["FW_AIRSPD_MIN"] == 21.0
        # the stall protection now checks against the new minimum
        goto = run.command("p", Goto(position_enu_m=(0.0, 0.0, 40.0), speed_m_s=20.0))
        assert not goto.accepted and "below FW_AIRSPD_MIN 21 m/s" in goto.reason
