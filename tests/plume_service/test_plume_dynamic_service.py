"""The plume service with time-dependent models: values by sim time, restarts, plume/info
(model, wind, σ fits outside their range) and the published filament state."""

from __future__ import annotations

import msgspec
import numpy as np

from plume_service.from_scenario import field_from_scenario
from plume_service.gaussian import GaussianPlume
from plume_service.service import PlumeService, SigmaUse, StatePublisher
from swarmbus.messages import PlumeInfoQuery, PlumeQuery
from swarmbus.scenario import load_scenario, parse_scenario

FILAMENT = """
[world]
seed = 9
[wind]
speed_m_s = 2.0
model = "meander"
[wind.meander]
preset = "small"
[plume]
model = "filament"
[[plume.sources]]
release_rate_g_s = 1.0
release_height_m = 2.0
[[vehicles]]
id = "a"
"""

POINTS = [(4.0, 0.0, 2.0), (8.0, 0.3, 2.0), (12.0, -0.5, 1.5)]


def _service(text: str = FILAMENT) -> PlumeService:
    scenario = parse_scenario(text)
    return PlumeService(field_from_scenario(scenario), scenario)


def test_values_depend_on_sim_time_only_also_after_a_restart() -> None:
    a = _service()
    times = [s * 0.05 for s in range(0, 400, 7)]
    first = [a.concentration(PlumeQuery(points_enu_m=POINTS, sim_time_s=t)) for t in times]
    # a physics restart: time goes back to 5 s and runs forward again
    replay = [a.concentration(PlumeQuery(points_enu_m=POINTS, sim_time_s=t)) for t in times[30:]]
    assert replay == first[30:]
    b = _service()  # another process, asking in another order
    backwards = [b.concentration(PlumeQuery(points_enu_m=POINTS, sim_time_s=t)) for t in times]
    assert sorted(map(repr, backwards)) == sorted(map(repr, first))
    assert any(v > 0.0 for r in first for v in r.values_g_m3)


def test_info_names_the_model_the_wind_and_time_dependence() -> None:
    info = _service().info(PlumeInfoQuery())
    assert (info.model, info.wind_model, info.time_dependent) == ("filament", "meander", True)
    assert info.sources[0].release_height_m == 2.0
    assert info.sigma_validity == []  # filaments use no σ fit


def test_info_says_when_a_sigma_fit_is_used_outside_its_range() -> None:
    scenario = load_scenario("swarmbus/scenarios/novak2018.toml")
    service = PlumeService(field_from_scenario(scenario), scenario)
    assert service.info(PlumeInfoQuery()).sigma_validity == []
    service.concentration(PlumeQuery(points_enu_m=[(500.0, 0.0, 10.0)]))
    assert service.info(PlumeInfoQuery()).sigma_validity == []  # 500 m: inside 100 m – 100 km
    service.concentration(PlumeQuery(points_enu_m=[(14.0, 0.0, 10.0), (50.0, 0.0, 10.0)]))
    (note,) = service.info(PlumeInfoQuery()).sigma_validity
    assert "14–500 m downwind" in note and "100–100000 m" in note


def test_sigma_use_of_a_few_points_is_the_plume_frames_distance_to_the_bit() -> None:
    """A sensor tick's few points are noted in scalar maths: each point's downwind distance
    is the one the numpy plume frame gives (two sources, wind along an axis and not)."""
    rng = np.random.default_rng(3)
    for from_deg in (270.0, 200.0, 33.3):
        scenario = load_scenario("swarmbus/scenarios/novak2018.toml")
        source = scenario.plume.sources[0]
        scenario = msgspec.structs.replace(
            scenario,
            wind=msgspec.structs.replace(scenario.wind, from_deg=from_deg),
            plume=msgspec.structs.replace(
                scenario.plume,
                sources=[source, msgspec.structs.replace(source, x_m=-7.3, y_m=2.9)],
            ),
        )
        field = field_from_scenario(scenario)
        sources = SigmaUse(field).sources
        assert len(sources) == 2
        compared = 0
        for point in rng.uniform((-300, -300, 0), (300, 300, 20), (300, 3)):
            use = SigmaUse(field)
            use.note(point[None, :], np.ones(1))
            for index, plume in enumerate(sources):
                assert isinstance(plume, GaussianPlume)
                x = float(plume.to_plume_frame(point[None, :])[0][0])
                assert use._range.get(index) == ((x, x) if x > 0.0 else None)
                compared += x > 0.0
        assert compared > 100


def test_state_publisher_sends_the_filaments_at_multiples_of_its_period() -> None:
    scenario = parse_scenario(FILAMENT)
    field = field_from_scenario(scenario)
    states = StatePublisher(field, 0.5)
    assert states.active
    for t in (0.1, 0.3, 0.52, 0.61, 1.7):
        states.on_clock(t)
    due = [states.next_time(0.01) for _ in range(4)]
    assert due == [0.0, 0.5, 1.5, None]
    state = states.state(1.5)
    centres = np.frombuffer(state.centres_f32, dtype="<f4").reshape(-1, 3)
    radii = np.frombuffer(state.radii_f32, dtype="<f4")
    assert state.count == centres.shape[0] == radii.shape[0] > 0
    # the same state whoever computes it, whenever
    other = StatePublisher(field_from_scenario(scenario), 0.5).state(1.5)
    assert other == state
    assert not StatePublisher(field_from_scenario(load_scenario()), 0.5).active  # Gaussian
