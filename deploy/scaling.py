"""Scaling a scenario to N vehicles, and writing a scenario back to TOML.

``plumeswarm demo --vehicles N`` flies the same scenario with N vehicles: vehicle k copies the
mission of the scenario's vehicle ``k mod len(vehicles)``; vehicles are spawned in a grid
(``spacing_m`` apart) and each mission is shifted with its vehicle's spawn point. Copies of the
same template fly one ``layer_m`` higher per copy so that parallel tracks do not meet. A
fixed-wing vehicle is not copied (its runway and its pattern, hundreds of metres long, are its
own): a scenario with one scales down, not up (:class:`ScalingError`), and the runners that fly
every vehicle as a multirotor (the environments, ``bench scale``) refuse it
(:func:`multirotors_only`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import msgspec
import tomli_w

from swarmbus.errors import PlumeswarmError
from swarmbus.messages import MissionCommand, MissionFrame, MissionItem
from swarmbus.scenario import Scenario, VehicleSpec, parse_scenario
from swarmbus.session import free_tcp_port
from swarmbus.vehicle_types import available_types, load_vehicle_type


class ScalingError(PlumeswarmError, ValueError):
    """A scenario a runner cannot fly as asked: one line naming the vehicle and what is valid."""


def fixed_wing_vehicles(scenario: Scenario) -> list[str]:
    """The ids of the scenario's fixed-wing vehicles, in its order."""
    return [v.id for v in scenario.vehicles if load_vehicle_type(v.type).kind == "fixed_wing"]


def multirotors_only(scenario: Scenario, why: str) -> None:
    """:class:`ScalingError` when the scenario has a fixed-wing vehicle, for a runner that
    flies every vehicle as a multirotor (``why``: what it does that a plane cannot)."""
    planes = fixed_wing_vehicles(scenario)
    if planes:
        vid = planes[0]
        rotors = [t for t in available_types() if load_vehicle_type(t).kind == "multirotor"]
        raise ScalingError(
            f"vehicle {vid!r} is a fixed wing ({scenario.vehicle(vid).type}): {why}; "
            f"valid vehicle types: {', '.join(rotors)}"
        )


def scale_scenario(
    scenario: Scenario, n: int, spacing_m: float = 4.0, layer_m: float = 1.5
) -> Scenario:
    """``scenario`` with ``n`` vehicles (the scenario itself when ``n`` equals its count)."""
    if n < 1:
        raise ValueError(f"--vehicles must be at least 1, got {n}")
    base = scenario.vehicles
    if n == len(base):
        return scenario
    if n < len(base):
        return msgspec.structs.replace(scenario, vehicles=list(base[:n]))
    planes = fixed_wing_vehicles(scenario)
    if planes:
        raise ScalingError(
            f"--vehicles {n}: vehicle {planes[0]!r} is a fixed wing, whose copies would share "
            f"its runway and pattern; valid: 1..{len(base)} (the scenario's vehicles or fewer)"
        )
    columns = math.ceil(math.sqrt(n))
    x0 = min(v.spawn_enu_m[0] for v in base)
    y_mid = sum(v.spawn_enu_m[1] for v in base) / len(base)
    vehicles: list[VehicleSpec] = []
    for k in range(n):
        template = base[k % len(base)]
        copy = k // len(base)
        row, col = divmod(k, columns)
        spawn = (
            x0 + row * spacing_m,
            y_mid + (col - (columns - 1) / 2) * spacing_m,
            template.spawn_enu_m[2],
        )
        dx = spawn[0] - template.spawn_enu_m[0]
        dy = spawn[1] - template.spawn_enu_m[1]
        dz = copy * layer_m
        mission = [
            msgspec.structs.replace(
                item, x=item.x + dx, y=item.y + dy, z=item.z + (dz if item.z > 0 else 0.0)
            )
            if item.frame == MissionFrame.ENU
            else item
            for item in template.mission
        ]
        vehicles.append(
            msgspec.structs.replace(
                template,
                id=f"uav{k + 1}",
                sysid=None,  # index + 1 for the first 254; MAVLink has no id for the rest
                spawn_enu_m=spawn,
                mission=mission,
            )
        )
    return msgspec.structs.replace(scenario, vehicles=vehicles)


def _drop_none(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _drop_none(v) for k, v in obj.items() if v is not None}
    if isinstance(obj, list):
        return [_drop_none(v) for v in obj]
    return obj


def scenario_toml(scenario: Scenario) -> str:
    """TOML that loads back into an equal scenario."""
    return tomli_w.dumps(_drop_none(msgspec.to_builtins(scenario)))


def write_scenario(scenario: Scenario, path: Path) -> Path:
    text = scenario_toml(scenario)
    parse_scenario(text, str(path))  # what we write must load
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def local_stack_scenario(
    sc: Scenario, run_dir: Path, mode: str, startup_timeout_s: float = 0.0
) -> tuple[Scenario, Path]:
    """``sc`` as a stack on this host runs it — its router on a free loopback port, the clock in
    ``mode``, no duration limit, at least ``startup_timeout_s`` to start — written into
    ``run_dir``: the one way the demo, the bus driver and ``bench scale`` start their stacks."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    sc = msgspec.structs.replace(
        sc,
        network=msgspec.structs.replace(sc.network, connect=[endpoint]),
        time=msgspec.structs.replace(
            sc.time,
            mode=mode,
            duration_s=0.0,
            startup_timeout_s=max(sc.time.startup_timeout_s, startup_timeout_s),
        ),
    )
    return sc, write_scenario(sc, run_dir / "scenario.toml")


ALTITUDE_M = 10.0
LAYER_M = 1.5  # vehicles on one spawn grid fly at different heights, one layer per row
SQUARE_M = 3.0  # half side of each vehicle's looping square
LAPS = 200


def flight_altitude(sc: Scenario, index: int) -> float:
    """Vehicles in one spawn row share a layer; rows stack up so squares never meet."""
    return ALTITUDE_M + (index % 8) * LAYER_M


def loop_mission(sc: Scenario, index: int) -> list[MissionItem]:
    """A square of side ``2·SQUARE_M`` around the spawn point, ``LAPS`` times (no landing)."""
    v = sc.vehicles[index]
    x0, y0, z0 = v.spawn_enu_m
    z = z0 + flight_altitude(sc, index)
    items = [MissionItem(command=MissionCommand.TAKEOFF, x=x0, y=y0, z=z)]
    corners = [(1, 1), (-1, 1), (-1, -1), (1, -1)]
    for _ in range(LAPS):
        items += [
            MissionItem(x=x0 + dx * SQUARE_M, y=y0 + dy * SQUARE_M, z=z, acceptance_radius_m=1.0)
            for dx, dy in corners
        ]
    return items[:1000]
