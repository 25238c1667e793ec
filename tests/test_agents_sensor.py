"""The concentration sensor model: thresholds, saturation, lag, seeded noise, unavailability."""

from __future__ import annotations

import math

import pytest

from agents.sensor import ConcentrationSensor
from swarmbus.messages import PeerReading
from swarmbus.scenario import Sensor

NOVAK = Sensor(preset="novak2018")


def test_novak2018_window_clips_below_detection_and_above_saturation() -> None:
    s = ConcentrationSensor(NOVAK, 2018, 0)
    assert s.sample(0.005, 0.0) == 0.0
    assert s.sample(0.0123, 0.1) == 0.0123
    assert s.sample(0.5, 0.2) == 0.2
    assert s.sample(0.0, 0.3) == 0.0


def test_ideal_sensor_passes_the_field_through() -> None:
    s = ConcentrationSensor(Sensor(preset="ideal"), 1, 0)
    assert s.sample(1e-7, 0.0) == 1e-7
    assert s.sample(123.0, 0.0) == 123.0


def test_first_order_lag_reaches_63_percent_after_one_time_constant() -> None:
    s = ConcentrationSensor(Sensor(time_constant_s=2.0), 0, 0)
    assert s.sample(0.0, 0.0) == 0.0
    assert s.sample(1.0, 2.0) == pytest.approx(1.0 - math.exp(-1.0))
    # exact discretisation: ten steps of 0.2 s land on the same value as one of 2 s
    t = ConcentrationSensor(Sensor(time_constant_s=2.0), 0, 0)
    t.sample(0.0, 0.0)
    value = 0.0
    for k in range(1, 11):
        value = t.sample(1.0, 0.2 * k)
    assert value == pytest.approx(1.0 - math.exp(-1.0))


def test_noise_is_seeded_per_vehicle_and_repeats() -> None:
    cfg = Sensor(noise_std_g_m3=0.01)
    a = [ConcentrationSensor(cfg, 7, 0).sample(0.1, 0.0) for _ in range(3)]
    b = [ConcentrationSensor(cfg, 7, 0).sample(0.1, 0.0) for _ in range(3)]
    c = ConcentrationSensor(cfg, 7, 1).sample(0.1, 0.0)
    assert a == b
    assert a[0] != c
    series = ConcentrationSensor(cfg, 7, 0)
    values = [series.sample(0.1, 0.01 * k) for k in range(2000)]
    mean = sum(values) / len(values)
    std = math.sqrt(sum((v - mean) ** 2 for v in values) / len(values))
    assert mean == pytest.approx(0.1, abs=0.002)
    assert std == pytest.approx(0.01, rel=0.1)


def test_period_ticks() -> None:
    s = ConcentrationSensor(Sensor(period_ticks=4), 0, 0)
    assert [k for k in range(10) if s.due(k)] == [0, 4, 8]


def test_unavailable_reading_has_no_values_never_a_silent_zero() -> None:
    s = ConcentrationSensor(NOVAK, 0, 0)
    r = s.reading("uav1", 1.0, (1.0, 2.0, 3.0), None, [])
    assert not r.available and r.reported_g_m3 is None and r.true_g_m3 is None
    peer = PeerReading(vehicle_id="uav2", position_enu_m=(0.0, 0.0, 0.0), true_g_m3=0.3)
    r = s.reading("uav1", 1.0, (1.0, 2.0, 3.0), 0.3, [peer])
    assert r.available and r.reported_g_m3 == 0.2 and r.true_g_m3 == 0.3 and r.peers == [peer]
