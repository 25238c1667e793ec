"""sim_world.admission: a participant's token counts once its process's health carried the
physics's scenario hash; another hash is refused; no health at all is let in after a while."""

from __future__ import annotations

import pytest

from sim_world import admission
from sim_world.admission import Admission
from sim_world.plume_part import PLUME
from swarmbus.messages import NodeHealth, NodeState


def health(name: str, role: str, scenario: str, vehicles: tuple[str, ...] = ()) -> NodeHealth:
    return NodeHealth(
        name=name, role=role, state=NodeState.UP, version="0", pid=1, host="h",
        scenario=scenario, vehicles=list(vehicles),
    )  # fmt: skip


def test_tokens_count_once_the_hash_is_checked_and_another_hash_is_refused(
    caplog: pytest.LogCaptureFixture,
) -> None:
    admitted: list[str] = []
    adm = Admission("a" * 16, admitted.append)
    assert not adm.arrival("uav1", "autopilot-uav1-uav2")  # no health yet: waits
    assert not adm.arrival("uav2", "autopilot-uav1-uav2")
    adm.health(health("autopilot-uav1-uav2", "autopilot", "a" * 16, ("uav1", "uav2")))
    assert admitted == ["autopilot-uav1-uav2"] * 2
    adm.wait_settled(0.1)
    adm.health(health("plume", "plume", "b" * 16))
    adm.health(health("plume", "plume", "b" * 16))  # logged once
    assert not adm.arrival(PLUME, "plume")
    assert caplog.text.count(f"scenario hash {'b' * 16} there, {'a' * 16} here") == 1
    assert adm.departure("uav1") and not adm.departure(PLUME)
    adm.health(health("plume", "plume", "a" * 16))  # a new plume, our scenario
    assert adm.arrival(PLUME, "plume")


def test_a_token_without_health_is_let_in_unchecked(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(admission, "UNCHECKED_ADMIT_S", 0.05)
    admitted: list[str] = []
    adm = Admission("a" * 16, admitted.append)
    assert not adm.arrival("uav1", "autopilot-uav1")
    adm.wait_settled(5.0)
    assert admitted == ["autopilot-uav1"]
    assert adm.departure("uav1")
