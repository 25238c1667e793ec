"""A filament scenario flown by the real stack (plume service, physics, autopilots, recorder):
the distributed field is the offline field, bit for bit, and the recorder draws its filaments
in the Foxglove scene."""

from __future__ import annotations

import json
from pathlib import Path

from plume_atmosphere.wind import wind_from_scenario
from plume_service.from_scenario import field_from_scenario
from plume_service.service import StatePublisher
from recorder.foxglove.channels import (
    PLUME_STATE_TOPIC,
)
from recorder.reader import Recording
from swarmbus.messages import AnemometerReading, ConcentrationReading, PlumeState
from swarmbus.scenario import SCENARIOS_DIR, load_scenario
from tests.support.foxglove_decode import topic_messages
from tests.support.procs import run_cli

VEHICLES = """
[[vehicles]]
id = "uav1"
spawn_enu_m = [6.0, -3.0, 0.0]
mission = [
  { command = "takeoff", x = 6.0, y = -3.0, z = 5.0 },
  { x = 6.0, y = -3.0, z = 5.0, hold_s = 3.0 },
  { x = 6.0, y = 3.0, z = 5.0, speed_m_s = 2.0 },
  { command = "land", x = 6.0, y = 3.0, z = 0.0 },
]

[[vehicles]]
id = "uav2"
spawn_enu_m = [8.0, 3.0, 0.0]
mission = [
  { command = "takeoff", x = 8.0, y = 3.0, z = 5.0 },
  { x = 8.0, y = 3.0, z = 5.0, hold_s = 3.0 },
  { x = 8.0, y = -3.0, z = 5.0, speed_m_s = 2.0 },
  { command = "land", x = 8.0, y = -3.0, z = 0.0 },
]
"""


def test_a_filament_flight_reads_the_field_offline_evaluation_gives_bit_for_bit(
    tmp_path: Path,
) -> None:
    """The demo's vehicles take off and land on ticks set by its commands (wall-clock), so two
    flights differ in their tracks; what must not differ is the field: every reading's true
    value is the scenario's field at the reading's (position, sim time), which this process
    recomputes offline, in reverse order, bit for bit; the same for the recorded field/state,
    which the recorder's Foxglove scene draws."""
    base = (SCENARIOS_DIR / "filament.toml").read_text().split("[[vehicles]]")[0]
    path = tmp_path / "short.toml"
    path.write_text(base + VEHICLES)
    out = tmp_path / "run"
    result = run_cli(
        ["demo", "--scenario", str(path), "--out", str(out), "--timeout", "400"], timeout_s=600
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["ok"]
    recording = Recording.open(summary["recording"])
    readings = [m.message() for m in recording.messages() if m.topic.endswith("/concentration")]
    states = [m.message() for m in recording.messages() if m.topic.endswith("/field/state")]
    scenario = load_scenario(path)
    field = field_from_scenario(scenario)
    live = [r for r in readings if isinstance(r, ConcentrationReading) and r.available]
    assert len(live) > 100
    for r in reversed(live):
        offline = field.concentration([r.position_enu_m], r.sim_time_s)[0]
        assert offline == r.true_g_m3, (r.vehicle_id, r.sim_time_s)
        assert r.reported_g_m3 == r.true_g_m3  # ideal sensor
    assert max(r.true_g_m3 or 0.0 for r in live) > 0.0, "the vehicles never met a filament"
    assert len(states) > 5
    # the anemometers read the scenario's wind, as this process computes it, bit for bit
    winds = [m.message() for m in recording.messages() if m.topic.endswith("/wind")]
    assert len(winds) > 20
    wind = wind_from_scenario(scenario)
    for w in reversed(winds):
        assert isinstance(w, AnemometerReading)
        expected = wind.velocity([w.position_enu_m], w.sim_time_s)[0]
        assert w.true_wind_enu_m_s == tuple(float(v) for v in expected)
        assert w.wind_enu_m_s != w.true_wind_enu_m_s  # with its own noise
    publisher = StatePublisher(field_from_scenario(scenario), scenario.plume.state_period_s)
    for state in reversed(states):
        assert isinstance(state, PlumeState)
        assert publisher.state(state.sim_time_s) == state
    # the recorder drew each state in the Foxglove scene: its filaments, one frame per state
    frames = topic_messages(Path(summary["recording"]), PLUME_STATE_TOPIC)
    assert [len(f.entities[0].spheres) for _, f in frames] == [
        s.count for s in states if isinstance(s, PlumeState)
    ]
