"""The concentration sensor model: thresholds, saturation, lag, seeded noise, unavailability,
rise/decay time constants, quantisation, ppm, the MOX (GADEN's order: the filter acts on
RS/R0, checked against its closed form) and PID presets."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.sensor import ConcentrationSensor
from plume_atmosphere.gases import molar_mass_g_mol, ppm_per_g_m3
from swarmbus.messages import PeerReading
from swarmbus.scenario import Mox, Sensor

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


# ----------------------------------------------------------------------------- sensor v2
MOX = Sensor(preset="mox-tgs2620")
ETHANOL_G_MOL = 2 * 12.011 + 6 * 1.008 + 15.999  # C2H5OH, IUPAC conventional atomic weights
MOLAR_VOLUME_M3 = 8.314462618 * 298.15 / 101325.0  # ideal gas at 298.15 K, 1 atm


# GADEN's TGS2620, by hand: RS/R0 = 62.32·ppm^-0.7155 capped at the clean-air 21, R0 3 kΩ,
# rise τ 2.96 s while RS/R0 falls, decay τ 15.71 s while it rises; ethanol at 298.15 K, 1 atm
PPM_PER_G_M3 = MOLAR_VOLUME_M3 / ETHANOL_G_MOL * 1e6  # ≈ 531 ppm per g/m³
RISE_S, DECAY_S, CLEAN_RS_R0 = 2.96, 15.71, 21.0


def _gaden_rs_r0(g_m3: float) -> float:
    ppm = g_m3 * PPM_PER_G_M3
    return CLEAN_RS_R0 if ppm <= 0.0 else min(62.32 * ppm**-0.7155, CLEAN_RS_R0)


def _calibrated_g_m3(rs_r0: float) -> float:
    return 0.0 if rs_r0 >= CLEAN_RS_R0 else (rs_r0 / 62.32) ** (1.0 / -0.7155) / PPM_PER_G_M3


def test_mox_step_up_moves_rs_r0_with_the_rise_time_constant() -> None:
    """From clean air, a held 1 g/m³: RS/R0(t) = r + (21 − r)·exp(−t/2.96), r the curve's
    value; the reading is that RS/R0 read back through the curve."""
    step_g_m3, dt = 1.0, 0.05
    target = _gaden_rs_r0(step_g_m3)
    s = ConcentrationSensor(MOX, 0, 0)
    assert s.sample(0.0, 0.0) == 0.0  # switched on in clean air
    for k in range(1, 400):
        t = round(k * dt, 10)
        m = s.measure(step_g_m3, t)
        expected = target + (CLEAN_RS_R0 - target) * math.exp(-t / RISE_S)
        assert m.resistance_ohm == pytest.approx(expected * 3000.0, rel=1e-9)
        assert m.reported_g_m3 == pytest.approx(_calibrated_g_m3(expected), rel=1e-9)
    # one rise time constant covers 63.2 % of the way in RS/R0
    one = ConcentrationSensor(MOX, 0, 0)
    one.sample(0.0, 0.0)
    r = one.measure(step_g_m3, RISE_S).resistance_ohm
    assert r is not None
    assert (CLEAN_RS_R0 - r / 3000.0) / (CLEAN_RS_R0 - target) == pytest.approx(1 - math.exp(-1))


def test_mox_step_down_moves_rs_r0_with_the_decay_time_constant() -> None:
    """After a settled 1 g/m³, clean air: RS/R0(t) = 21 + (r − 21)·exp(−t/15.71)."""
    step_g_m3, dt, off_s = 1.0, 0.05, 100.0
    target = _gaden_rs_r0(step_g_m3)
    s = ConcentrationSensor(MOX, 0, 0)
    s.sample(0.0, 0.0)
    settled = s.measure(step_g_m3, off_s).resistance_ohm
    assert settled is not None
    assert settled / 3000.0 == pytest.approx(target, rel=1e-12)
    for k in range(1, 2000):
        t = round(off_s + k * dt, 10)
        m = s.measure(0.0, t)
        expected = CLEAN_RS_R0 + (target - CLEAN_RS_R0) * math.exp(-(t - off_s) / DECAY_S)
        assert m.resistance_ohm == pytest.approx(expected * 3000.0, rel=1e-9)
        assert m.reported_g_m3 == pytest.approx(_calibrated_g_m3(expected), rel=1e-9)
    left = s.measure(0.0, off_s + 100.0 + DECAY_S).resistance_ohm
    assert left is not None  # 36.8 % of the way left after one decay time constant
    lagged = CLEAN_RS_R0 + (target - CLEAN_RS_R0) * math.exp(-100.0 / DECAY_S)
    assert (CLEAN_RS_R0 - left / 3000.0) / (CLEAN_RS_R0 - lagged) == pytest.approx(math.exp(-1))


def test_one_short_strong_hit_reads_just_above_the_floor() -> None:
    """0.1 s at 65 g/m³: RS/R0 = 21 + (r − 21)(1 − exp(−0.1/2.96)) ≈ 20.30, which reads
    ≈ 4.79 ppm ≈ 0.009 g/m³ of ethanol — just above the 4.57 ppm floor. (Filtering the
    concentration before the curve instead read 2.16 g/m³.)"""
    rs_r0 = CLEAN_RS_R0 + (_gaden_rs_r0(65.0) - CLEAN_RS_R0) * (1.0 - math.exp(-0.1 / RISE_S))
    peak = _calibrated_g_m3(rs_r0)
    assert peak == pytest.approx(0.009, abs=0.0005)
    s = ConcentrationSensor(MOX, 0, 0)
    s.sample(0.0, 0.0)
    assert s.sample(65.0, 0.1) == pytest.approx(peak, rel=1e-9)
    after = [s.measure(0.0, round(0.1 + 0.1 * k, 10)) for k in range(1, 600)]
    for k, m in enumerate(after, start=1):
        expected = CLEAN_RS_R0 + (rs_r0 - CLEAN_RS_R0) * math.exp(-0.1 * k / DECAY_S)
        assert m.resistance_ohm == pytest.approx(expected * 3000.0, rel=1e-9)
        assert m.reported_g_m3 <= peak
        assert m.reported_g_m3 == 0.0 or m.reported_g_m3 >= s.floor_g_m3


def test_mox_floor_is_the_clean_air_value_and_nothing_reads_below_it() -> None:
    floor_ppm = (62.32 / 21.0) ** (1.0 / 0.7155)  # the curve at RS/R0 = 21
    assert floor_ppm == pytest.approx(4.57, abs=0.005)
    s = ConcentrationSensor(MOX, 0, 0)
    assert s.floor_g_m3 == pytest.approx(floor_ppm / PPM_PER_G_M3, rel=1e-12)
    assert s.floor_g_m3 == pytest.approx(0.0086, abs=0.00005)
    assert s.noise_std_g_m3 == 0.0  # the preset adds no noise
    settle = 1000.0
    for true in (0.5, 0.99, 1.01, 2.0, 100.0):
        t = ConcentrationSensor(MOX, 0, 0)
        t.sample(true * s.floor_g_m3, 0.0)
        value = t.sample(true * s.floor_g_m3, settle)
        assert value == (0.0 if true < 1.0 else pytest.approx(true * s.floor_g_m3, rel=1e-9))


def test_mox_resistance_noise_is_relative_and_seeded() -> None:
    """RS noise σ (relative) gives the calibrated value a relative std σ/0.7155 (d ln ppm =
    d ln RS / b), and noise_std_g_m3 reports that at the floor."""
    sigma = 0.01
    cfg = Sensor(preset="mox-tgs2620", mox=Mox(rs_noise_rel=sigma))
    s = ConcentrationSensor(cfg, 4, 1)
    level = 0.5
    s.sample(level, 0.0)
    measured = [s.measure(level, 1000.0 + 0.1 * k) for k in range(6000)]
    values = np.array([m.reported_g_m3 for m in measured])
    rs = np.array([m.resistance_ohm for m in measured], dtype=np.float64)
    assert np.std(rs) / np.mean(rs) == pytest.approx(sigma, rel=0.05)
    assert np.std(values) / np.mean(values) == pytest.approx(sigma / 0.7155, rel=0.05)
    assert s.noise_std_g_m3 == pytest.approx(sigma / 0.7155 * s.floor_g_m3, rel=1e-12)
    again = ConcentrationSensor(cfg, 4, 1)
    again.sample(level, 0.0)
    assert again.sample(level, 1000.0) == values[0]
    other = ConcentrationSensor(cfg, 4, 2)
    other.sample(level, 0.0)
    assert other.sample(level, 1000.0) != values[0]


def test_mox_baseline_drift_is_linear_in_time_and_drawn_per_vehicle() -> None:
    """R0 drifts at a constant rate per vehicle (std r0_drift_rel_per_h per hour): the
    settled resistance is RS/R0 · R0 · (1 + rate · t)."""
    cfg = Sensor(preset="mox-tgs2620", mox=Mox(r0_drift_rel_per_h=0.02))
    level = 0.5
    ideal_ohm = _gaden_rs_r0(level) * 3000.0
    rates = []
    for index in range(400):
        s = ConcentrationSensor(cfg, 9, index)
        s.sample(level, 0.0)
        drift = [
            (s.measure(level, t).resistance_ohm or 0.0) / ideal_ohm - 1.0
            for t in (600.0, 1800.0, 3600.0)
        ]
        assert drift[1] == pytest.approx(3.0 * drift[0], rel=1e-6, abs=1e-15)
        assert drift[2] == pytest.approx(6.0 * drift[0], rel=1e-6, abs=1e-15)
        rates.append(drift[2])  # per hour
    assert len(set(rates)) == len(rates)
    assert float(np.std(rates)) == pytest.approx(0.02, rel=0.1)
    assert abs(float(np.mean(rates))) < 4 * 0.02 / math.sqrt(len(rates))


def test_rise_and_decay_time_constants_are_separate() -> None:
    s = ConcentrationSensor(Sensor(rise_time_constant_s=1.0, decay_time_constant_s=4.0), 0, 0)
    assert s.sample(1.0, 0.0) == 0.0
    assert s.sample(1.0, 1.0) == pytest.approx(1.0 - math.exp(-1.0))
    up = s.sample(1.0, 30.0)
    assert s.sample(0.0, 34.0) == pytest.approx(up * math.exp(-1.0))
    # time_constant_s alone is both; an explicit one overrides it
    t = ConcentrationSensor(Sensor(time_constant_s=2.0, decay_time_constant_s=0.0), 0, 0)
    t.sample(1.0, 0.0)
    assert t.sample(1.0, 2.0) == pytest.approx(1.0 - math.exp(-1.0))
    assert t.sample(0.25, 2.5) == 0.25  # no lag on the way down


def test_mox_curve_rs_r0_at_10_ppm_and_the_reading_carries_the_resistance() -> None:
    expected_rs_r0 = 62.32 * 10.0**-0.7155  # GADEN's TGS2620 curve, by hand
    assert expected_rs_r0 == pytest.approx(12.00, rel=1e-3)
    ten_ppm_g_m3 = 10e-6 * ETHANOL_G_MOL / MOLAR_VOLUME_M3
    s = ConcentrationSensor(MOX, 0, 0)
    s.sample(ten_ppm_g_m3, 0.0)
    r = s.reading("uav1", 1000.0, (0.0, 0.0, 0.0), ten_ppm_g_m3, [])  # lag long settled
    assert r.resistance_ohm == pytest.approx(expected_rs_r0 * 3000.0, rel=1e-9)
    assert r.resistance_ohm is not None
    assert r.resistance_ohm / 3000.0 == pytest.approx(12.00, rel=1e-3)
    assert r.gas == "ethanol"
    assert r.reported_g_m3 == pytest.approx(ten_ppm_g_m3, rel=1e-9)  # calibrated back
    assert r.reported_ppm == pytest.approx(10.0, rel=1e-9)


def test_mox_reads_its_clean_air_resistance_and_zero_below_the_curve() -> None:
    clean_below_ppm = (62.32 / 21.0) ** (1.0 / 0.7155)  # where the curve meets RS/R0 = 21
    s = ConcentrationSensor(MOX, 0, 0)
    g_m3 = 0.9 * clean_below_ppm * 1e-6 * ETHANOL_G_MOL / MOLAR_VOLUME_M3
    s.sample(g_m3, 0.0)
    m = s.measure(g_m3, 1000.0)
    assert m.resistance_ohm == 21.0 * 3000.0
    assert m.reported_g_m3 == 0.0


def test_one_g_m3_of_methane_is_1525_ppm_at_298_15_k_and_one_atmosphere() -> None:
    assert ppm_per_g_m3("methane", 298.15, 101325.0) == pytest.approx(1525.0, rel=1e-3)
    assert molar_mass_g_mol("methane") == pytest.approx(16.043, abs=1e-3)  # CH4, by hand
    s = ConcentrationSensor(Sensor(gas="methane"), 0, 0)
    r = s.reading("uav1", 0.0, (0.0, 0.0, 0.0), 1.0, [])
    assert r.reported_ppm == pytest.approx(1525.0, rel=1e-3)
    # ppm scale with T / p (ideal gas): hotter or thinner air, more ppm per g/m³
    hot = ConcentrationSensor(Sensor(gas="methane"), 0, 0, 2 * 298.15, 101325.0)
    assert hot.to_ppm(1.0) == pytest.approx(2 * 1525.0, rel=1e-3)


def test_quantisation_rounds_to_the_nearest_step() -> None:
    s = ConcentrationSensor(Sensor(resolution_g_m3=0.01), 0, 0)
    assert s.sample(0.123, 0.0) == pytest.approx(0.12)
    assert s.sample(0.127, 0.1) == pytest.approx(0.13)
    assert s.sample(0.004, 0.2) == 0.0
    # on a ramp the error is uniform in ±step/2: mean 0, rms step/√12
    rng = np.random.default_rng(3)
    step = 0.05
    q = ConcentrationSensor(Sensor(resolution_g_m3=step), 0, 0)
    truth = rng.uniform(1.0, 2.0, 20_000)
    err = np.array([q.sample(float(v), 0.01 * k) for k, v in enumerate(truth)]) - truth
    assert np.max(np.abs(err)) <= step / 2 + 1e-12
    assert abs(err.mean()) < 3 * step / math.sqrt(12 * err.size)
    assert np.sqrt(np.mean(err**2)) == pytest.approx(step / math.sqrt(12), rel=0.03)


@pytest.mark.parametrize("level", [0.5, 2.0])
def test_proportional_noise_has_the_configured_relative_std(level: float) -> None:
    s = ConcentrationSensor(Sensor(noise_rel=0.1), 11, 2)
    values = np.array([s.sample(level, 0.01 * k) for k in range(8000)])
    assert values.mean() == pytest.approx(level, abs=4 * 0.1 * level / math.sqrt(values.size))
    assert values.std() == pytest.approx(0.1 * level, rel=0.05)


def test_noise_is_the_same_bits_whoever_asks_and_in_whatever_order() -> None:
    cfg = Sensor(noise_std_g_m3=0.01, noise_rel=0.05)
    times = [0.1 * k for k in range(50)]
    forward = [ConcentrationSensor(cfg, 5, 1).sample(0.3, t) for t in times]
    one = ConcentrationSensor(cfg, 5, 1)
    in_order = [one.sample(0.3, t) for t in times]
    other = ConcentrationSensor(cfg, 5, 1)
    every_other = {t: other.sample(0.3, t) for t in times[::2]}  # skipped samples
    assert in_order == forward
    assert all(
        every_other[t] == v for t, v in zip(times, in_order, strict=True) if t in every_other
    )
    assert len(set(in_order)) == len(in_order)
    assert [ConcentrationSensor(cfg, 5, 2).sample(0.3, t) for t in times] != in_order
    assert [ConcentrationSensor(cfg, 6, 1).sample(0.3, t) for t in times] != in_order


def test_pid_preset_is_fast_and_reports_isobutylene_ppm() -> None:
    cfg = Sensor(preset="pid").resolved()
    assert cfg.gas == "isobutylene" and cfg.mox is None
    assert cfg.rise_s == cfg.decay_s == pytest.approx(3.0 / math.log(10.0), abs=0.01)  # T90 3 s
    s = ConcentrationSensor(Sensor(preset="pid"), 0, 0)
    s.sample(1.0, 0.0)
    r = s.reading("uav1", 3.0, (0.0, 0.0, 0.0), 1.0, [])
    assert r.reported_g_m3 == pytest.approx(0.9, abs=0.01)  # 90 % after T90
    isobutylene_g_mol = 4 * 12.011 + 8 * 1.008
    assert r.reported_g_m3 is not None
    assert r.reported_ppm == pytest.approx(
        r.reported_g_m3 / isobutylene_g_mol * MOLAR_VOLUME_M3 * 1e6
    )
    assert r.resistance_ohm is None


def test_pid_presets_floor_is_the_datasheet_detection_level_and_noise_a_third_of_it() -> None:
    """MiniPID 2 (0-4000 ppm): minimum detection level 0.1 ppm isobutylene, read as 3σ."""
    isobutylene_g_mol = 4 * 12.011 + 8 * 1.008
    mdl_g_m3 = 0.1e-6 * isobutylene_g_mol / MOLAR_VOLUME_M3
    for name in ("pid", "pid-fast"):
        s = ConcentrationSensor(Sensor(preset=name), 0, 0)
        assert s.floor_g_m3 == pytest.approx(mdl_g_m3, rel=1e-4)
        assert s.noise_std_g_m3 == pytest.approx(mdl_g_m3 / 3.0, rel=1e-4)
        assert s.sample(0.0, 0.0) == 0.0  # clean air + noise below the floor → 0


def test_fast_pid_follows_a_step_within_one_sample() -> None:
    """τ 0.3 ms: after one 0.05 s sample the step is reached to exp(−0.05/0.0003) ≈ 0."""
    cfg = Sensor(preset="pid-fast").resolved()
    assert cfg.rise_s == cfg.decay_s == pytest.approx(0.0003)
    s = ConcentrationSensor(Sensor(preset="pid-fast", noise_std_g_m3=1e-12), 0, 0)
    s.sample(0.0, 0.0)
    assert s.sample(1.0, 0.05) == pytest.approx(1.0, abs=1e-9)
    assert s.sample(0.0, 0.10) == 0.0
    assert s.sample(0.3, 0.15) == pytest.approx(0.3, abs=1e-9)


def test_preset_fills_only_what_is_unset() -> None:
    cfg = Sensor(preset="mox-tgs2620", decay_time_constant_s=5.0, noise_rel=0.2).resolved()
    assert (cfg.rise_s, cfg.decay_s, cfg.noise_rel, cfg.gas) == (2.96, 5.0, 0.2, "ethanol")
    assert cfg.mox == Mox()


def test_time_going_back_replays_the_same_readings() -> None:
    """Physics resumed from a checkpoint: the sensor resumes from its state before that time,
    so the readings from there on equal those of a run without the restart."""
    mox = Mox(rs_noise_rel=0.02, r0_drift_rel_per_h=0.05)
    cfg = Sensor(preset="mox-tgs2620", noise_rel=0.05, mox=mox)
    truth = [0.0 if k < 10 or 60 < k < 80 else 0.5 for k in range(120)]
    times = [0.1 * k for k in range(120)]
    straight = ConcentrationSensor(cfg, 3, 0)
    expected = [straight.sample(c, t) for c, t in zip(truth, times, strict=True)]
    resumed = ConcentrationSensor(cfg, 3, 0)
    for c, t in zip(truth[:90], times[:90], strict=True):  # ran ahead to 8.9 s ...
        resumed.sample(c, t)
    replay = [resumed.sample(c, t) for c, t in zip(truth[70:], times[70:], strict=True)]  # ... 7 s
    assert replay == expected[70:]
    again = ConcentrationSensor(cfg, 3, 0)
    assert [again.sample(c, t) for c, t in zip(truth, times, strict=True)] == expected


def test_for_vehicle_keeps_two_checkpoint_periods_of_history() -> None:
    from swarmbus.scenario import load_scenario

    sc = load_scenario()
    s = ConcentrationSensor.for_vehicle(sc, 0)
    period_samples = sc.time.checkpoint_period_s * sc.time.control_hz / sc.sensor.period_ticks
    assert s._history.maxlen is not None and s._history.maxlen >= 2 * period_samples
