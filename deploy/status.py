"""``plumeswarm status``: ask the bus what is running (bounded wait), as text or JSON."""

from __future__ import annotations

import time
from collections.abc import Sequence

import msgspec

from deploy.busview import BusView, Snapshot
from swarmbus.errors import PlumeswarmError
from swarmbus.keys import Keys, autopilot_node
from swarmbus.session import NetworkConfig, open_session

PRESENCE_WAIT_S = 2.0
# Once every vehicle's state and status are in: how long to wait on for the readings still
# missing (a vehicle's readings come at the sensor rate; one that reads nothing shows --).
READING_WAIT_S = 1.0


class NothingRunning(PlumeswarmError, RuntimeError):
    pass


def _complete(snap: Snapshot, vehicle_ids: Sequence[str]) -> bool:
    if not snap.alive or any(n not in snap.health for n in snap.alive):
        return False
    if "physics" in snap.alive:
        if snap.clock is None:
            return False
        for vid in vehicle_ids:
            v = snap.vehicles.get(vid)
            if v is None or v.state is None:
                return False
            if autopilot_node(vid) in snap.alive and v.status is None:
                return False
    return True


def _readings_in(snap: Snapshot) -> bool:
    """Whether every vehicle with a status (an autopilot flying it) has a reading too."""
    return all(v.reading is not None for v in snap.vehicles.values() if v.status is not None)


def query_status(
    net: NetworkConfig, keys: Keys, vehicle_ids: Sequence[str] = (), timeout_s: float = 5.0
) -> Snapshot:
    """What the bus says within ``timeout_s``; :class:`NothingRunning` if no node is alive."""
    client = msgspec.structs.replace(net, listen=[], mode="peer")  # keeps its TLS identity
    with open_session(client) as session:
        view = BusView(session, keys)
        try:
            start = time.monotonic()
            deadline = start + timeout_s
            complete_at: float | None = None
            while True:
                snap = view.snapshot()
                now = time.monotonic()
                if now >= deadline:
                    break
                if _complete(snap, vehicle_ids):
                    complete_at = complete_at if complete_at is not None else now
                    if _readings_in(snap) or now - complete_at >= READING_WAIT_S:
                        break
                if not snap.alive and now - start >= min(PRESENCE_WAIT_S, timeout_s):
                    break
                view.wait_changed(0.1)
        finally:
            view.close()
    if not snap.alive:
        raise NothingRunning(
            f"nothing is running in world {keys.world!r} via {', '.join(net.connect)}"
        )
    return snap


def format_status(snap: Snapshot) -> str:
    data = snap.to_json()
    lines = []
    t = data["sim_time"]
    rtf = data["real_time_factor"]
    lines.append(
        "sim time "
        + (f"{t:.2f} s" if t is not None else "--")
        + ", real-time factor "
        + (f"{rtf:.2f}x" if rtf is not None else "--")
    )
    lines.append(f"{'node':<22} {'role':<10} {'state':<9} {'pid':>8}  host")
    for n in data["nodes"]:
        lines.append(
            f"{n['name']:<22} {n['role'] or '?':<10} {n['state'] or '?':<9} "
            f"{n['pid'] if n['pid'] is not None else '?':>8}  {n['host'] or '?'}"
        )
        if n["state"] == "error":
            lines.append(f"  {n['name']} error: {n['detail']}")
    if data["vehicles"]:
        lines.append(
            f"{'vehicle':<10} {'mode':<9} {'armed':<6} {'x':>8} {'y':>8} {'z':>8} {'g/m3':>8}"
        )
    for vid, v in data["vehicles"].items():
        pos = v["position"] or [float("nan")] * 3
        reading = v["reading"]
        lines.append(
            f"{vid:<10} {v['mode'] or '?':<9} {('yes' if v['armed'] else 'no'):<6} "
            f"{pos[0]:8.2f} {pos[1]:8.2f} {pos[2]:8.2f} "
            + (f"{reading:8.4f}" if reading is not None else f"{'--':>8}")
        )
    return "\n".join(lines)
