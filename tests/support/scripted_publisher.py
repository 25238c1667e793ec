"""A scripted publisher for recorder tests: a known stream of vehicle messages, counted here.

``python -m tests.support.scripted_publisher --connect EP --name NAME --vehicles uav1,uav2 --steps N
--rate-hz R --out FILE.json`` publishes, per step and vehicle, a VehicleState; every
``--every``-th step also a VehicleStatus and a ConcentrationReading. With ``--recorder NAME`` it
waits for that recorder to acknowledge it before the first message and after the last (so that
every message is known to have been recorded before it exits). ``--pause-at K --pause-s S``
inserts one pause (for replay timing); ``--garbage`` adds one undecodable payload.
It writes ``{"counts": {key: n}, "published": [[key, payload_hex, t_ns], ...]}`` to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path

import msgspec

from recorder.handshake import wait_until_recorded
from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import (
    ConcentrationReading,
    FlightMode,
    NodeState,
    VehicleState,
    VehicleStatus,
)
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.scenario import DEFAULT_SCENARIO, load_scenario
from swarmbus.session import NetworkConfig

PPM_PER_G_M3 = 1525.0  # made-up scale of the first vehicle's ppm
RESISTANCE_OHM = 12_000.0


def field_g_m3(x: float, y: float, z: float) -> float:
    """A smooth made-up field (not the plume model): a blob around (40, 0, 10)."""
    return 0.3 * math.exp(-((x - 40.0) ** 2 + y**2) / 100.0 - (z - 10.0) ** 2 / 50.0)


def position(index: int, step: int, steps: int) -> tuple[float, float, float]:
    angle = 2 * math.pi * step / max(steps, 1) + index
    radius = 10.0 + 2.0 * index
    climb = min(1.0, step / max(steps / 5, 1))
    return (30.0 + radius * math.cos(angle), radius * math.sin(angle), 10.0 * climb)


def messages(vehicle: str, index: int, step: int, args: argparse.Namespace) -> list[msgspec.Struct]:
    t = step / args.rate_hz
    x, y, z = position(index, step, args.steps)
    out: list[msgspec.Struct] = [
        VehicleState(
            vehicle_id=vehicle,
            tick=step,
            sim_time_s=t,
            position_enu_m=(x, y, z),
            velocity_enu_m_s=(0.0, 0.0, 0.0),
            attitude_xyzw=(0.0, 0.0, 0.0, 1.0),
            body_rates_rad_s=(0.0, 0.0, 0.0),
            lat_deg=47.4,
            lon_deg=8.5,
            alt_m=488.0 + z,
            on_ground=z < 0.1,
        )
    ]
    if step % args.every == 0:
        true = field_g_m3(x, y, z)
        # a sensor with a detection limit, saturation and a deterministic 10 % wobble
        wobbled = true * (1.0 + 0.1 * math.sin(0.7 * step + index))
        reported = 0.0 if wobbled < 0.01 else min(wobbled, 0.2)
        out.append(
            VehicleStatus(
                vehicle_id=vehicle,
                sim_time_s=t,
                mode=FlightMode.MISSION,
                armed=True,
                landed=z < 0.1,
            )
        )
        out.append(
            ConcentrationReading(
                vehicle_id=vehicle,
                sim_time_s=t,
                position_enu_m=(x, y, z),
                available=True,
                reported_g_m3=reported,
                true_g_m3=true,
                # the first vehicle's sensor also names a gas and has a resistance (made up)
                gas="methane" if index == 0 else None,
                reported_ppm=reported * PPM_PER_G_M3 if index == 0 else None,
                resistance_ohm=RESISTANCE_OHM if index == 0 else None,
            )
        )
    return out


def run_steps(
    args: argparse.Namespace, vehicles: list[str], keys: Keys, put: Callable[[str, bytes], None]
) -> None:
    """The script: ``args.steps`` steps at ``args.rate_hz``, with the pause, gap and garbage."""
    key_of: dict[type, Callable[[str], str]] = {
        VehicleState: keys.vehicle_state,
        VehicleStatus: keys.vehicle_status,
        ConcentrationReading: keys.vehicle_concentration,
    }
    next_t = time.monotonic()
    for step in range(args.steps):
        if step == args.pause_at:
            next_t += args.pause_s
        delay = next_t - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        next_t += 1.0 / args.rate_hz
        if args.skip_at <= step < args.skip_at + args.skip_n:
            continue
        for i, v in enumerate(vehicles):
            for msg in messages(v, i, step, args):
                put(key_of[type(msg)](v), encode(msg))
        if args.garbage and step == args.steps // 2:
            put(keys.vehicle_status(vehicles[0]), b"\xc1 not a message")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--connect", required=True)
    p.add_argument("--name", default="scripted")
    p.add_argument("--vehicles", default="uav1")
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--rate-hz", type=float, default=100.0)
    p.add_argument("--every", type=int, default=10)
    p.add_argument("--pause-at", type=int, default=-1)
    p.add_argument("--pause-s", type=float, default=0.0)
    p.add_argument("--garbage", action="store_true")
    p.add_argument("--skip-at", type=int, default=-1, help="publish nothing from this step ...")
    p.add_argument("--skip-n", type=int, default=0, help="... for this many steps")
    p.add_argument("--recorder", default="recorder")
    p.add_argument("--out", required=True, type=Path)
    args = p.parse_args(argv)

    scenario = load_scenario(DEFAULT_SCENARIO)
    net = NetworkConfig(connect=[args.connect], listen=["tcp/127.0.0.1:0"])
    ctx = NodeContext(scenario, net, args.name)
    vehicles = [v for v in args.vehicles.split(",") if v]
    counts: dict[str, int] = {}
    published: list[tuple[str, str, int]] = []
    with NodeRuntime(ctx, role="scripted") as rt:
        keys = rt.keys
        pubs = {}
        for v in vehicles:
            for key in (
                keys.vehicle_state(v),
                keys.vehicle_status(v),
                keys.vehicle_concentration(v),
            ):
                pubs[key] = rt.session.declare_publisher(key)

        def put(key: str, payload: bytes) -> None:
            pubs[key].put(payload)
            counts[key] = counts.get(key, 0) + 1
            published.append((key, payload.hex(), time.time_ns()))

        wait_until_recorded(
            rt.session,
            keys,
            args.name,
            NodeState.UP,
            lambda: rt.publish_health(NodeState.UP),
            recorder=args.recorder,
        )
        run_steps(args, vehicles, keys, put)
        wait_until_recorded(
            rt.session,
            keys,
            args.name,
            NodeState.STOPPING,
            lambda: rt.publish_health(NodeState.STOPPING),
            recorder=args.recorder,
        )
    args.out.write_text(json.dumps({"counts": counts, "published": published}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
