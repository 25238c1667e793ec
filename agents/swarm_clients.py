"""The Swarm client's errors, and its request-reply clients: :class:`VehicleCommander` (one
vehicle's commands) and :class:`PlumeClient` (the plume service's queries). ``from agents import
Swarm`` gives them (``Swarm.command(id)``, ``Swarm.plume``); see docs/agents.md ("Swarm client").
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, TypeVar

import msgspec
import numpy as np
import numpy.typing as npt
import zenoh

from swarmbus.errors import PlumeswarmError
from swarmbus.keys import AUTOPILOT_PREFIX, Keys
from swarmbus.messages import (
    Arm,
    CommandReply,
    Disarm,
    FlightMode,
    GcsHeartbeat,
    GetParams,
    Goto,
    Hold,
    Land,
    Message,
    MissionClear,
    MissionDownload,
    MissionItem,
    MissionPause,
    MissionStart,
    MissionUpload,
    PlumeInfo,
    PlumeInfoQuery,
    PlumeQuery,
    PlumeValues,
    RejectCode,
    ReturnToLaunch,
    SetMode,
    SetParam,
    Setpoint,
    Takeoff,
)
from swarmbus.reqrep import BadReply, NoReply, Refused, request

M = TypeVar("M", bound=Message)
ROUTE_RETRY_S = 0.05


class SwarmError(PlumeswarmError):
    """Base of the Swarm client's errors."""


class CommandRejected(SwarmError):
    """The vehicle refused a command: ``code`` (RejectCode), ``reason``, and ``field`` when the
    payload itself was invalid."""

    def __init__(
        self, vehicle_id: str, command: str, code: RejectCode, reason: str, field: str = ""
    ) -> None:
        self.vehicle_id = vehicle_id
        self.command = command
        self.code = code
        self.reason = reason
        self.field = field
        where = f" ({field})" if field else ""
        super().__init__(f"{vehicle_id}: {command} rejected [{code}]{where}: {reason}")


class CommandTimeout(SwarmError, TimeoutError):
    """No reply within the deadline (is the vehicle's autopilot running?)."""


class WaitTimeout(SwarmError, TimeoutError):
    """``wait_until`` ran out of time; the message names what did not happen."""


class PlumeError(SwarmError):
    """The plume service refused a query or did not answer."""


class ClockError(SwarmError):
    """A step was refused (the world is not stepped, another client holds its clock, the world
    stopped) or the physics did not answer."""


class VehicleCommander:
    """Commands to one vehicle; each returns when the vehicle accepted it, else raises."""

    def __init__(self, session: zenoh.Session, keys: Keys, vehicle_id: str, timeout_s: float):
        self.vehicle_id = vehicle_id
        self._session = session
        self._key = keys.vehicle_cmd(vehicle_id)
        self.timeout_s = timeout_s

    def send(self, command: Message, retry_until: float | None = None) -> CommandReply:
        """Send any ``Command`` message; the accepted reply, or a typed error.

        ``retry_until`` (a ``time.monotonic()`` deadline): while no autopilot answers (it is
        still starting), ask again until then instead of raising :class:`CommandTimeout`."""
        name = type(command).__name__
        while True:
            try:
                reply = request(self._session, self._key, command, CommandReply, self.timeout_s)
                break
            except NoReply as exc:
                if retry_until is None or time.monotonic() > retry_until:
                    raise CommandTimeout(
                        f"{self.vehicle_id}: no reply to {name} within {self.timeout_s} s "
                        f"(is {AUTOPILOT_PREFIX}{self.vehicle_id} running?)"
                    ) from exc
                time.sleep(ROUTE_RETRY_S)
            except Refused as exc:  # the payload itself was invalid
                raise CommandRejected(
                    self.vehicle_id, name, RejectCode.INVALID, exc.reason, exc.field
                ) from None
            except BadReply as exc:
                raise SwarmError(f"{self.vehicle_id}: {name}: {exc}") from None
        if not reply.accepted:
            raise CommandRejected(self.vehicle_id, name, reply.code, reply.reason)
        return reply

    def arm(self) -> None:
        self.send(Arm())

    def disarm(self, force: bool = False) -> None:
        self.send(Disarm(force=force))

    def takeoff(self, altitude_m: float | None = None, *, alt_m: float | None = None) -> None:
        """Take off to ``altitude_m`` above home; ``alt_m=`` is its old name (deprecated: a
        DeprecationWarning, then the same command)."""
        self.send(Takeoff(altitude_m=takeoff_altitude(altitude_m, alt_m)))

    def land(self) -> None:
        self.send(Land())

    def rtl(self) -> None:
        self.send(ReturnToLaunch())

    def hold(self) -> None:
        self.send(Hold())

    def goto(
        self, x: float, y: float, z: float, yaw_deg: float | None = None, speed_m_s: float = 0.0
    ) -> None:
        """Fly to ENU (x, y, z) m and hold there (yaw: ENU degrees, 0 = east, CCW)."""
        self.send(Goto(position_enu_m=(x, y, z), yaw_deg=yaw_deg, speed_m_s=speed_m_s))

    def set_mode(self, mode: FlightMode | str) -> None:
        self.send(SetMode(mode=FlightMode(mode)))

    def offboard(self) -> None:
        self.set_mode(FlightMode.OFFBOARD)

    def upload_mission(self, items: Iterable[MissionItem | Mapping[str, Any]]) -> None:
        mission = [
            i if isinstance(i, MissionItem) else msgspec.convert(i, MissionItem) for i in items
        ]
        self.send(MissionUpload(items=mission))

    def download_mission(self) -> list[MissionItem]:
        return list(self.send(MissionDownload()).mission or [])

    def clear_mission(self) -> None:
        self.send(MissionClear())

    def start_mission(self, start_index: int = 0) -> None:
        self.send(MissionStart(start_index=start_index))

    def pause_mission(self) -> None:
        self.send(MissionPause())

    def resume_mission(self) -> None:
        self.set_mode(FlightMode.MISSION)

    def setpoint(
        self,
        position: Sequence[float] | None = None,
        velocity: Sequence[float] | None = None,
        yaw_deg: float | None = None,
    ) -> None:
        """One offboard setpoint (position and/or velocity, ENU)."""
        pos = (float(position[0]), float(position[1]), float(position[2])) if position else None
        vel = (float(velocity[0]), float(velocity[1]), float(velocity[2])) if velocity else None
        self.send(Setpoint(position_enu_m=pos, velocity_enu_m_s=vel, yaw_deg=yaw_deg))

    def heartbeat(self, source: str = "swarm") -> None:
        self.send(GcsHeartbeat(source=source))

    def params(self) -> dict[str, float]:
        return dict(self.send(GetParams()).params or {})

    def set_param(self, name: str, value: float) -> dict[str, float]:
        return dict(self.send(SetParam(name=name, value=value)).params or {})


class PlumeClient:
    """Queries to the plume service (one batched query per call)."""

    def __init__(self, session: zenoh.Session, keys: Keys, timeout_s: float) -> None:
        self._session = session
        self._keys = keys
        self.timeout_s = timeout_s

    def concentration(
        self, points: npt.ArrayLike, sim_time_s: float | None = None
    ) -> npt.NDArray[np.float64]:
        """Concentration (g/m³) at ENU points, shape (N, 3) → (N,)."""
        arr = np.asarray(points, dtype=float).reshape(-1, 3)
        pts = [(float(x), float(y), float(z)) for x, y, z in arr.tolist()]
        values = self._ask(
            self._keys.plume_concentration(),
            PlumeQuery(points_enu_m=pts, sim_time_s=sim_time_s),
            PlumeValues,
        )
        return np.asarray(values.values_g_m3, dtype=float)

    def info(self) -> PlumeInfo:
        return self._ask(self._keys.plume_info(), PlumeInfoQuery(), PlumeInfo)

    def _ask(self, key: str, query: Message, reply_type: type[M]) -> M:
        try:
            return request(self._session, key, query, reply_type, self.timeout_s)
        except Refused as exc:
            raise PlumeError(
                f"plume refused the query: {exc.field or '<payload>'}: {exc.reason}"
            ) from None
        except NoReply:
            raise PlumeError(
                f"the plume service did not answer within {self.timeout_s} s"
            ) from None
        except BadReply as exc:
            raise PlumeError(str(exc)) from None


def takeoff_altitude(altitude_m: float | None, alt_m: float | None) -> float:
    """The take-off altitude of :meth:`VehicleCommander.takeoff` from its name or its old one."""
    if alt_m is None:
        if altitude_m is None:
            raise TypeError("takeoff() needs altitude_m, the height above home (m)")
        return altitude_m
    if altitude_m is not None:
        raise TypeError("takeoff(): give altitude_m only (alt_m is its old name)")
    warnings.warn(
        "takeoff(alt_m=...) is deprecated: use takeoff(altitude_m=...)",
        DeprecationWarning,
        stacklevel=3,
    )
    return alt_m
