"""Offboard setpoints (SET_POSITION_TARGET_*, SET_ATTITUDE_TARGET), MANUAL_CONTROL sticks and
FOLLOW_TARGET, measured against where the vehicle is, and sent to its autopilot."""

from __future__ import annotations

import logging
import math

from gcs_bridge import mission as ms
from gcs_bridge import offboard
from gcs_bridge.core import Autopilots, Handler
from gcs_bridge.dialect import Msg
from gcs_bridge.frames import euler_ned_frd
from gcs_bridge.links import Link
from gcs_bridge.vehicle import Vehicle
from swarmbus.messages import Setpoint

log = logging.getLogger(__name__)


def here_of(v: Vehicle) -> offboard.Here:
    """What a setpoint of ``v`` is measured against."""
    st = v.state
    return offboard.Here(
        position_enu=st.position_enu_m if st is not None else v.spawn_enu,
        yaw_enu_rad=math.pi / 2 - euler_ned_frd(st.attitude_xyzw)[2] if st is not None else 0.0,
        local_origin_enu=v.spawn_enu,
        home_amsl_m=v.home_place().alt_amsl_m,
        origin=v.origin,
    )


class OffboardHandlers:
    """Setpoint messages → bus ``Setpoint`` commands (MAVLink has no ACK for them)."""

    def __init__(self, autopilots: Autopilots) -> None:
        self._autopilots = autopilots

    def handlers(self) -> dict[str, Handler]:
        return {
            "SET_POSITION_TARGET_LOCAL_NED": self.on_position_target,
            "SET_POSITION_TARGET_GLOBAL_INT": self.on_global_target,
            "SET_ATTITUDE_TARGET": self.on_attitude_target,
            "MANUAL_CONTROL": self.on_manual_control,
            "FOLLOW_TARGET": self.on_follow_target,
        }

    def _send(self, v: Vehicle, setpoint: Setpoint | None) -> None:
        """Offboard setpoints have no ACK in MAVLink: unusable ones are dropped."""
        if setpoint is None:
            log.debug("%s: unusable offboard setpoint dropped", v.id)
            return
        self._autopilots.tell(v, setpoint)

    def on_position_target(
        self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float
    ) -> None:
        """SET_POSITION_TARGET_LOCAL_NED (from the vehicle's local origin, as PX4)."""
        self._send(v, offboard.from_local_ned(msg, here_of(v)))

    def on_global_target(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        """SET_POSITION_TARGET_GLOBAL_INT."""
        self._send(v, offboard.from_global_int(msg, here_of(v)))

    def on_manual_control(
        self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float
    ) -> None:
        """MANUAL_CONTROL sticks: velocity and yaw-rate setpoints for position mode."""
        self._send(v, offboard.from_manual_control(msg, here_of(v)))

    def on_follow_target(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        """FOLLOW_TARGET (follow-me): where to be, from the target and the FLW_TGT_* params."""
        p = v.params
        follow = offboard.Follow(
            height_m=p.value("FLW_TGT_HT"),
            distance_m=p.value("FLW_TGT_DST"),
            angle_deg=p.value("FLW_TGT_FA"),
        )
        self._send(v, offboard.from_follow_target(msg, here_of(v), follow))

    def on_attitude_target(
        self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float
    ) -> None:
        """SET_ATTITUDE_TARGET: attitude or body rates with a thrust."""
        self._send(v, offboard.from_attitude_target(msg))
