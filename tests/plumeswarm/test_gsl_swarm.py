"""``bench gsl --vehicles N --radio ...``: the options reach every episode and the command line."""

from __future__ import annotations

import pytest

from plumeswarm.gsl.bench import GslError, command_line, make_options, parse_radio, specs_of
from plumeswarm.gsl.episode import episode_scenario
from swarmbus.radio import RadioSpec


def test_radio_text_becomes_the_radio_sections_fields() -> None:
    assert parse_radio("loss=0.2, latency=12,range=80,bytes=64") == (
        ("radio.loss", 0.2),
        ("radio.latency_ticks", 12),
        ("radio.range_m", 80.0),
        ("radio.max_message_bytes", 64),
    )
    assert parse_radio("") == ()
    with pytest.raises(GslError, match=r"'lost=0\.2'.*range, loss, latency, bytes"):
        parse_radio("lost=0.2")
    with pytest.raises(GslError, match=r"'x' is not a number"):
        parse_radio("latency=x")


def test_vehicles_and_radio_reach_every_episodes_scenario() -> None:
    opts = make_options(
        ["surge_cast"], ["steady_gaussian"], ["ideal"], runs=2, vehicles=4,
        radio="loss=0.5,latency=3",
    )  # fmt: skip
    specs = specs_of(opts)
    assert len(specs) == 3 * 2  # random_walk, surge_cast, oracle
    for spec in specs:
        scenario = episode_scenario(spec)
        assert len(scenario.vehicles) == 4
        assert scenario.radio == RadioSpec(loss=0.5, latency_ticks=3)
    assert "--vehicles 4 --radio loss=0.5,latency=3" in command_line(opts)
    with pytest.raises(GslError, match=r"radio\.loss"):
        make_options(["surge_cast"], ["steady_gaussian"], ["ideal"], radio="loss=2")


def test_without_the_options_each_algorithm_flies_its_own_vehicles_on_a_perfect_link() -> None:
    opts = make_options(["gradient_swarm", "surge_cast"], ["steady_gaussian"], ["ideal"], runs=1)
    counts = {s.algorithm: len(episode_scenario(s).vehicles) for s in specs_of(opts)}
    assert counts == {"random_walk": 1, "gradient_swarm": 3, "surge_cast": 1, "oracle": 1}
    assert all(episode_scenario(s).radio.perfect for s in specs_of(opts))
    assert "--vehicles" not in command_line(opts) and "--radio" not in command_line(opts)
