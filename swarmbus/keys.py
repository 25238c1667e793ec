"""Every Zenoh key expression of plumeswarm, built in one place (:class:`Keys`) — no other module
formats one — and the node names (:func:`autopilot_node`, :func:`process_node`). Data, control
(queryables) and presence are separate planes under ``plumeswarm/<world>/``, so that no wildcard
crosses them. See docs/bus.md ("Keys").
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from swarmbus.errors import PlumeswarmError

ROOT = "plumeswarm"
# Outside every world: the liveliness query by which a new peer flushes its new links
# (swarmbus.session.join_peers; no token lives there), and a router's admin-space entry.
JOIN_FLUSH = f"{ROOT}/join"
ROUTER_ADMIN = "@/*/router"
_NAME_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$")


class KeyNameError(PlumeswarmError, ValueError):
    """A world, vehicle or node name that cannot be part of a key expression."""


def check_name(kind: str, name: str) -> str:
    """Return ``name`` if it is safe inside a key (no ``/``, wildcards or ``$``), else raise."""
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise KeyNameError(
            f"{kind} name {name!r} is not allowed: use 1-64 of A-Z a-z 0-9 _ . - "
            "(not starting with . or -)"
        )
    return name


@dataclass(frozen=True)
class Keys:
    """Key expressions of one world."""

    world: str = "default"

    def __post_init__(self) -> None:
        check_name("world", self.world)

    @property
    def prefix(self) -> str:
        return f"{ROOT}/{self.world}"

    # -- everything (recorder) -------------------------------------------------
    def everything(self) -> str:
        return f"{self.prefix}/**"

    # -- sim plane -------------------------------------------------------------
    def clock(self) -> str:
        return f"{self.prefix}/sim/clock"

    def tick(self) -> str:
        return f"{self.prefix}/sim/tick"

    def sensor_tick(self) -> str:
        """The sensor ticks of ``sim/tick`` again, the same bytes: for the plume service, which
        answers those alone (reading ``sim/tick`` would wake it on every tick)."""
        return f"{self.prefix}/sim/sensor"

    def backfill(self) -> str:
        """The physics's recent ticks and states again, for a restarted recorder: the ones
        published between the old recorder's death and the physics's noticing it."""
        return f"{self.prefix}/sim/backfill/**"

    def backfill_of(self, key: str) -> str:
        """``key`` (of this world) as re-sent on :meth:`backfill`."""
        return f"{self.prefix}/sim/backfill/{key.removeprefix(self.prefix + '/')}"

    def backfilled(self, key: str) -> str | None:
        """The original key of a :meth:`backfill` key, None for any other key."""
        head = f"{self.prefix}/sim/backfill/"
        return f"{self.prefix}/{key.removeprefix(head)}" if key.startswith(head) else None

    # -- stepped clock (control plane: a queryable of the physics) -------------
    def clock_step(self) -> str:
        """``StepRequest`` → ``StepReply``: the stepped clock's grants."""
        return f"{self.prefix}/clock/step"

    # -- one name's keys and every name's: ``<plane>/<name>/<leaf>``, ``<plane>/*/<leaf>`` ----
    def _named(self, plane: str, kind: str, name: str, leaf: str) -> str:
        return f"{self.prefix}/{plane}/{check_name(kind, name)}/{leaf}"

    def _every(self, plane: str, leaf: str) -> str:
        return f"{self.prefix}/{plane}/*/{leaf}"

    def owned(self, plane: str, name: str, leaf: str) -> str:
        """``<plane>/<name>/<leaf>`` for the access-control list: ``name`` is one name, ``*``
        (every name) or a name ending in ``$*`` (every name that starts so)."""
        if name != "*":
            check_name(plane, name.removesuffix("$*"))
        return f"{self.prefix}/{plane}/{name}/{leaf}"

    # -- vehicle data plane ----------------------------------------------------
    def _vehicle(self, vehicle_id: str, leaf: str) -> str:
        return self._named("vehicle", "vehicle", vehicle_id, leaf)

    def vehicle_state(self, vehicle_id: str) -> str:
        return self._vehicle(vehicle_id, "state")

    def vehicle_status(self, vehicle_id: str) -> str:
        return self._vehicle(vehicle_id, "status")

    def vehicle_concentration(self, vehicle_id: str) -> str:
        return self._vehicle(vehicle_id, "concentration")

    def vehicle_cmd(self, vehicle_id: str) -> str:
        return self._vehicle(vehicle_id, "cmd")

    def vehicle_radio(self, vehicle_id: str) -> str:
        """A talking behaviour's ``RadioBatch`` of each tick (subscribed), and its last ones
        again (queryable, for a receiver that missed some)."""
        return self._vehicle(vehicle_id, "radio")

    def all_vehicle_radio(self) -> str:
        return self._every("vehicle", "radio")

    def all_vehicle_states(self) -> str:
        return self._every("vehicle", "state")

    def all_vehicle_status(self) -> str:
        return self._every("vehicle", "status")

    def all_vehicle_concentration(self) -> str:
        return self._every("vehicle", "concentration")

    # -- autopilot process data plane ------------------------------------------
    def autopilot_actuators(self, node_name: str) -> str:
        """One autopilot process's ``ActuatorBatch`` (see the module doc)."""
        return self._named("autopilot", "node", node_name, "actuators")

    def all_autopilot_actuators(self) -> str:
        return self._every("autopilot", "actuators")

    # -- plume control plane ---------------------------------------------------
    def plume_concentration(self) -> str:
        return f"{self.prefix}/plume/concentration"

    def plume_info(self) -> str:
        return f"{self.prefix}/plume/info"

    def plume_mesh(self) -> str:
        return f"{self.prefix}/plume/mesh"

    # -- dynamic plume and anemometer data --------------------------------------
    def plume_state(self) -> str:
        """Filaments or puffs of a time-dependent plume (data, not a queryable: not plume/)."""
        return f"{self.prefix}/field/state"

    def plume_sample(self) -> str:
        """The plume service's values at a sensor tick's positions (its lockstep answer)."""
        return f"{self.prefix}/field/sample"

    def vehicle_wind(self, vehicle_id: str) -> str:
        return self._vehicle(vehicle_id, "wind")

    def all_vehicle_wind(self) -> str:
        return self._every("vehicle", "wind")

    # -- presence plane --------------------------------------------------------
    def node_health(self, node_name: str) -> str:
        return self._named("node", "node", node_name, "health")

    def all_node_health(self) -> str:
        return self._every("node", "health")

    def node_restart(self, node_name: str) -> str:
        """The launcher's :class:`~swarmbus.messages.RestartNotice` about ``node_name``."""
        return self._named("node", "node", node_name, "restart")

    def all_node_restart(self) -> str:
        return self._every("node", "restart")

    # -- parsing ---------------------------------------------------------------
    def vehicle_id_of(self, key: str) -> str:
        """The vehicle id in a ``vehicle/<id>/...`` key of this world."""
        return self._name_in(key, "vehicle", "a vehicle")

    def node_name_of(self, key: str) -> str:
        """The node name in a ``node/<name>/health`` key of this world."""
        return self._name_in(key, "node", "a node")

    def autopilot_node_of(self, key: str) -> str:
        """The node name in an ``autopilot/<node>/actuators`` key of this world."""
        return self._name_in(key, "autopilot", "an autopilot", exact=True)

    def _name_in(self, key: str, plane: str, what: str, exact: bool = False) -> str:
        """The ``<name>`` of a ``<plane>/<name>/<leaf>...`` key of this world (``exact``: one
        leaf, no more), else :class:`KeyNameError` saying the key is not ``what`` key."""
        parts = str(key).split("/")
        head = self.prefix.split("/")
        n = len(head)
        sized = len(parts) == n + 3 if exact else len(parts) >= n + 3
        if parts[:n] != head or not sized or parts[n] != plane:
            raise KeyNameError(f"{key!r} is not {what} key of world {self.world!r}")
        return parts[n + 1]

    def relative(self, key: str) -> str:
        """``key`` without the ``plumeswarm/<world>/`` prefix (for channel names)."""
        key = str(key)
        p = self.prefix + "/"
        return key[len(p) :] if key.startswith(p) else key


# -- node names ------------------------------------------------------------------------------
# A process's node name is the ``<name>`` of its ``node/<name>`` presence keys. An autopilot
# declares one token per vehicle it serves, ``autopilot-<vehicle id>``: that token is the
# vehicle's lockstep participant, whatever the process is called.
AUTOPILOT_PREFIX = "autopilot-"


def autopilot_node(vehicle_id: str) -> str:
    """The presence name of one vehicle's autopilot."""
    return AUTOPILOT_PREFIX + check_name("vehicle", vehicle_id)


def vehicle_of_autopilot(node_name: str) -> str | None:
    """The vehicle id in an ``autopilot-<id>`` presence name; None for any other node."""
    return (
        node_name.removeprefix(AUTOPILOT_PREFIX) if node_name.startswith(AUTOPILOT_PREFIX) else None
    )


_SEVERAL_RE = re.compile(r"-plus[1-9][0-9]*$")


def serves_several(node_name: str) -> bool:
    """Whether ``node_name`` is :func:`process_node`'s name of a process serving several
    vehicles (``role-<first id>-plus<n - 1>``): an autopilot of that name is no vehicle's
    presence name (each of its vehicles has its own, ``autopilot-<vehicle id>``)."""
    return _SEVERAL_RE.search(node_name) is not None


def process_node(role: str, vehicle_ids: Sequence[str] = ()) -> str:
    """The default node name of a ``role`` process serving ``vehicle_ids``: ``role``,
    ``role-<id>``, or ``role-<first id>-plus<n - 1>`` (all ids would outgrow a key segment)."""
    if not vehicle_ids:
        return role
    more = f"-plus{len(vehicle_ids) - 1}" if len(vehicle_ids) > 1 else ""
    return f"{role}-{vehicle_ids[0]}{more}"
