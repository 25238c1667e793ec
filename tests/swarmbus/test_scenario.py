"""Scenario files: the default is valid; each broken file names the exact field."""

from __future__ import annotations

from pathlib import Path

import pytest

from swarmbus.scenario import (
    DEFAULT_SCENARIO,
    MAX_VEHICLES,
    ScenarioError,
    load_scenario,
    parse_scenario,
)
from tests.support.procs import run_cli

GOOD_VEHICLE = '[[vehicles]]\nid = "uav1"\n'


def test_default_scenario_is_the_seed() -> None:
    sc = load_scenario(DEFAULT_SCENARIO)
    assert [v.id for v in sc.vehicles] == ["uav1", "uav2", "uav3"]
    assert {v.type for v in sc.vehicles} == {"iris"}
    assert all(v.spawn_enu_m[2] == 0.0 for v in sc.vehicles)
    assert sc.plume.coefficients == "novak2018"
    assert sc.plume.stability == "D"
    (src,) = sc.plume.sources
    assert (src.x_m, src.y_m, src.release_rate_g_s, src.release_height_m) == (0, 0, 10, 10)
    assert sc.wind.speed_m_s == 6.0
    assert sc.wind.from_deg == 270.0
    sensor = sc.sensor.resolved()
    assert (sensor.detection_limit_g_m3, sensor.saturation_g_m3) == (0.01, 0.2)
    assert sc.time.physics_hz % sc.time.control_hz == 0
    for v in sc.vehicles:
        # enters the plume on take-off at ~10 m and flies inside the seed's readable band
        assert v.mission[0].command == "takeoff"
        assert v.mission[0].z == pytest.approx(10.0)
        assert v.mission[-1].command == "land"
        assert all(14.0 <= item.x <= 50.2 for item in v.mission)


BROKEN: list[tuple[str, str]] = [
    ("[time]\ncontrol_hz = 7\n" + GOOD_VEHICLE, "time.control_hz"),
    ("[time]\nphysics_hz = 0\n" + GOOD_VEHICLE, "time.physics_hz"),
    ('[time]\nmode = "warp"\n' + GOOD_VEHICLE, "time.mode"),
    ("[wind]\nspeed_m_s = 0.0\n" + GOOD_VEHICLE, "wind.speed_m_s"),
    ("[wind]\nspeed_m_s = nan\n" + GOOD_VEHICLE, "wind.speed_m_s"),
    ('[plume]\nstability = "G"\n' + GOOD_VEHICLE, "plume.stability"),
    (
        "[plume]\nsources = [{ release_rate_g_s = -1.0 }]\n" + GOOD_VEHICLE,
        "plume.sources[0].release_rate_g_s",
    ),
    ("[world]\norigin = { lat_deg = 95.0 }\n" + GOOD_VEHICLE, "world.origin.lat_deg"),
    ('[world]\nname = "a/b"\n' + GOOD_VEHICLE, "world.name"),
    ("vehicles = []\n", "vehicles"),
    ('[[vehicles]]\nid = "uav 1"\n', "vehicles[0].id"),
    ('[[vehicles]]\nid = "a"\ntype = "blimp"\n', "vehicles[0].type"),
    ('[[vehicles]]\nid = "a"\n[[vehicles]]\nid = "a"\n', "vehicles[1].id"),
    ('[[vehicles]]\nid = "a"\nsysid = 300\n', "vehicles[0].sysid"),
    ('[[vehicles]]\nid = "a"\nsysid = 5\n[[vehicles]]\nid = "b"\nsysid = 5\n', "vehicles[1].sysid"),
    ('[[vehicles]]\nid = "a"\nspawn_enu_m = [0.0, 0.0]\n', "vehicles[0].spawn_enu_m"),
    (
        '[[vehicles]]\nid = "a"\nmission = [{ x = 1.0, y = 2.0, z = inf }]\n',
        "vehicles[0].mission[0].z",
    ),
    ('[[vehicles]]\nid = "a"\nmission = [{ x = 1.0, y = 2.0 }]\n', "vehicles[0].mission[0].z"),
    ('[[vehicles]]\nid = "a"\nbehavior = "nocolon"\n', "vehicles[0].behavior"),
    # a process serving several vehicles is named <role>-<first id>-plus<N>: no vehicle's id
    ('[[vehicles]]\nid = "a"\n[[vehicles]]\nid = "uav1-plus2"\n', "vehicles[1].id"),
    (
        "[sensor]\ndetection_limit_g_m3 = 0.5\nsaturation_g_m3 = 0.2\n" + GOOD_VEHICLE,
        "sensor.saturation_g_m3",
    ),
    ('[sensor]\ngas = "unobtainium"\n' + GOOD_VEHICLE, "sensor.gas"),
    ("[sensor]\nnoise_rel = -0.1\n" + GOOD_VEHICLE, "sensor.noise_rel"),
    ("[sensor]\nresolution_g_m3 = -0.01\n" + GOOD_VEHICLE, "sensor.resolution_g_m3"),
    ("[sensor]\nrise_time_constant_s = -1.0\n" + GOOD_VEHICLE, "sensor.rise_time_constant_s"),
    ("[sensor]\ndecay_time_constant_s = inf\n" + GOOD_VEHICLE, "sensor.decay_time_constant_s"),
    ('[sensor]\npreset = "tgs2620"\n' + GOOD_VEHICLE, "sensor.preset"),
    ("[sensor.mox]\nr0_ohm = 3000.0\n" + GOOD_VEHICLE, "sensor.gas"),  # a curve needs a gas
    (
        '[sensor]\ngas = "ethanol"\n[sensor.mox]\nrs_r0_exponent = 0.7\n' + GOOD_VEHICLE,
        "sensor.mox.rs_r0_exponent",
    ),
    ("[world]\ntemperature_k = 0.0\n" + GOOD_VEHICLE, "world.temperature_k"),
    ("[world]\npressure_pa = -1.0\n" + GOOD_VEHICLE, "world.pressure_pa"),
    ('[network]\nconnect = ["http://x"]\n' + GOOD_VEHICLE, "network.connect[0]"),
    ("[gateway]\ngcs_port = 70000\n" + GOOD_VEHICLE, "gateway.gcs_port"),
    (
        '[failsafe]\ndatalink_loss_action = "explode"\n' + GOOD_VEHICLE,
        "failsafe.datalink_loss_action",
    ),
    ("[unknown_section]\nx = 1\n" + GOOD_VEHICLE, "unknown_section"),
    ("this is = = not toml", ""),
]


@pytest.mark.parametrize(("text", "field"), BROKEN, ids=[f for _, f in BROKEN])
def test_broken_scenario_names_the_field(text: str, field: str) -> None:
    with pytest.raises(ScenarioError) as err:
        parse_scenario(text, "broken.toml")
    assert err.value.field == field
    line = str(err.value)
    assert "\n" not in line
    assert line.startswith("broken.toml: ")


@pytest.mark.parametrize(
    ("text", "value"),
    [
        ('[sensor]\ngas = "unobtainium"\n', "'unobtainium'"),
        ("[sensor]\nnoise_rel = -0.1\n", "-0.1"),
        ("[world]\ntemperature_k = 0.0\n", "0.0"),
        ('[sensor]\npreset = "tgs2620"\n', "'tgs2620'"),
    ],
)
def test_sensor_errors_name_the_bad_value(text: str, value: str) -> None:
    with pytest.raises(ScenarioError) as err:
        parse_scenario(text + GOOD_VEHICLE, "broken.toml")
    assert value in err.value.reason


def test_sensor_v2_fields_are_accepted() -> None:
    sc = parse_scenario(
        '[world]\ntemperature_k = 288.15\npressure_pa = 90000.0\n[sensor]\npreset = "mox-tgs2620"\n'
        'gas = "ethanol"\nresolution_g_m3 = 0.001\nnoise_rel = 0.05\nperiod_ticks = 6\n'
        "[sensor.mox]\nr0_ohm = 2500.0\n" + GOOD_VEHICLE
    )
    cfg = sc.sensor.resolved()
    assert (cfg.rise_s, cfg.decay_s, cfg.resolution_g_m3, cfg.noise_rel) == (
        2.96,
        15.71,
        0.001,
        0.05,
    )
    assert cfg.mox is not None and cfg.mox.r0_ohm == 2500.0 and cfg.mox.clean_air_rs_r0 == 21.0
    assert (sc.world.temperature_k, sc.world.pressure_pa) == (288.15, 90000.0)


def many(n: int, sysids: dict[int, int] | None = None) -> str:
    """``n`` vehicles uav1…uavN; ``sysids`` gives some (by index) an explicit sysid."""
    out = []
    for i in range(n):
        out.append(f'[[vehicles]]\nid = "uav{i + 1}"\n')
        if sysids and i in sysids:
            out.append(f"sysid = {sysids[i]}\n")
    return "".join(out)


def test_more_vehicles_than_mavlink_addresses_load_and_the_rest_have_no_sysid() -> None:
    sc = parse_scenario(many(300, {0: 2, 1: 1}))  # two explicit sysids, swapped
    assert len(sc.vehicles) == 300
    assert [sc.sysid_of(f"uav{k}") for k in (1, 2, 3, 254)] == [2, 1, 3, 254]
    assert sc.sysid_of("uav255") is None and sc.sysid_of("uav300") is None
    assert sc.not_on_mavlink() == [f"uav{k}" for k in range(255, 301)]
    assert sc.not_on_mavlink(["uav1", "uav260", "uav254"]) == ["uav260"]
    assert parse_scenario(many(254)).not_on_mavlink() == []


@pytest.mark.parametrize(
    ("sysids", "field"),
    [
        ({255: 255}, "vehicles[255].sysid"),  # out of range, also past the first 254
        ({255: 0}, "vehicles[255].sysid"),
        ({255: 3}, "vehicles[255].sysid"),  # uav3 has 3 already
        ({0: 254}, "vehicles[253].sysid"),  # uav254's own 254 is taken
    ],
)
def test_sysids_of_a_large_scenario_are_still_unique_and_in_range(
    sysids: dict[int, int], field: str
) -> None:
    with pytest.raises(ScenarioError) as err:
        parse_scenario(many(260, sysids), "big.toml")
    assert err.value.field == field


def test_vehicles_per_scenario_are_bounded() -> None:
    assert len(parse_scenario(many(MAX_VEHICLES)).vehicles) == MAX_VEHICLES
    with pytest.raises(ScenarioError) as err:
        parse_scenario(many(MAX_VEHICLES + 1), "huge.toml")
    assert err.value.field == "vehicles"
    assert f"at most {MAX_VEHICLES} vehicles" in str(err.value)


def test_unknown_section_is_reported_by_name() -> None:
    with pytest.raises(ScenarioError) as err:
        parse_scenario("[unknown_section]\nx = 1\n" + GOOD_VEHICLE, "s.toml")
    assert err.value.field == "unknown_section"
    assert str(err.value).startswith("s.toml: unknown_section: unknown key")


def _valid_list(line: str) -> list[str]:
    """The names after ``; valid: `` of an error line."""
    assert "; valid: " in line, line
    return line.split("; valid: ", 1)[1].split(", ")


def test_a_mistyped_key_gets_the_nearest_key_of_its_section() -> None:
    with pytest.raises(ScenarioError) as err:
        parse_scenario("[wind]\nsped_m_s = 3.0\n" + GOOD_VEHICLE, "w.toml")
    assert err.value.field == "wind.sped_m_s"
    assert "did you mean 'speed_m_s'?" in err.value.reason
    # the valid keys are the [wind] table's, as the docs list them
    assert set(_valid_list(str(err.value))) == {
        "speed_m_s",
        "from_deg",
        "model",
        "meander",
        "field",
        "turbulence",
    }


def test_a_mistyped_section_gets_the_nearest_section() -> None:
    with pytest.raises(ScenarioError) as err:
        parse_scenario("[snesor]\nnoise_rel = 0.1\n" + GOOD_VEHICLE, "s.toml")
    assert err.value.field == "snesor"
    assert "did you mean 'sensor'?" in err.value.reason
    assert {"sensor", "wind", "plume", "vehicles"} <= set(_valid_list(str(err.value)))


@pytest.mark.parametrize(
    ("text", "field", "choices"),
    [
        ('[wind]\nmodel = "turbulent"\n', "wind.model", {"steady", "meander", "field"}),
        ('[plume]\nstability = "G"\n', "plume.stability", set("ABCDEF")),
        ('[sensor]\npreset = "tgs2620"\n', "sensor.preset",
         {"novak2018", "ideal", "mox-tgs2620", "pid", "pid-fast"}),
        ("[sensor]\npreset = 3\n", "sensor.preset",
         {"novak2018", "ideal", "mox-tgs2620", "pid", "pid-fast"}),
        ('[failsafe]\noffboard_loss_action = "explode"\n', "failsafe.offboard_loss_action",
         {"hold", "land", "rtl"}),
        ('[plume]\nsources = [{ model = "gauss" }]\n', "plume.sources[0].model",
         {"gaussian", "filament", "puff"}),
        ('[network]\nmode = "mesh"\n', "network.mode", {"peer", "client", "router"}),
    ],
)  # fmt: skip
def test_a_bad_enum_member_lists_the_choices(text: str, field: str, choices: set[str]) -> None:
    with pytest.raises(ScenarioError) as err:
        parse_scenario(text + GOOD_VEHICLE, "e.toml")
    line = str(err.value)
    assert err.value.field == field
    assert set(_valid_list(line)) == choices, line
    assert "got " in line and line.count("got ") == 1, line


def test_a_near_miss_enum_member_gets_a_did_you_mean() -> None:
    with pytest.raises(ScenarioError) as err:
        parse_scenario('[wind]\nmodel = "meandre"\n' + GOOD_VEHICLE, "e.toml")
    assert "got 'meandre'" in err.value.reason
    assert "did you mean 'meander'?" in err.value.reason


@pytest.mark.parametrize(
    ("text", "field", "expected", "got"),
    [
        ('[wind]\nspeed_m_s = "fast"\n', "wind.speed_m_s", "float", "'fast'"),
        ("[time]\nphysics_hz = 2.5\n", "time.physics_hz", "integer", "2.5"),
        ("[time]\nphysics_hz = true\n", "time.physics_hz", "integer", "true"),
        ('[sensor]\nsaturation_g_m3 = "x"\n', "sensor.saturation_g_m3", "float", "'x'"),
        ("[plume]\nsources = { x_m = 1.0 }\n", "plume.sources", "array", "a table"),
    ],
)
def test_a_wrong_type_says_the_expected_type_and_the_value_once(
    text: str, field: str, expected: str, got: str
) -> None:
    with pytest.raises(ScenarioError) as err:
        parse_scenario(text + GOOD_VEHICLE, "t.toml")
    assert err.value.field == field
    assert err.value.reason == f"expected {expected}, got {got}"


def test_cli_check_accepts_the_default() -> None:
    res = run_cli(["scenario", "check", str(DEFAULT_SCENARIO)])
    assert res.returncode == 0, res.stderr
    assert "3 vehicle(s)" in res.stdout


def test_cli_check_rejects_a_broken_copy_with_one_line(tmp_path: Path) -> None:
    broken = tmp_path / "broken.toml"
    broken.write_text(DEFAULT_SCENARIO.read_text().replace("speed_m_s = 6.0", "speed_m_s = -6.0"))
    res = run_cli(["scenario", "check", str(broken)])
    assert res.returncode != 0
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert "wind.speed_m_s" in lines[0]
    assert "Traceback" not in res.stderr


def test_cli_check_accepts_sensor_v2_and_rejects_a_bad_field_with_one_line(tmp_path: Path) -> None:
    good = tmp_path / "mox.toml"
    good.write_text(
        DEFAULT_SCENARIO.read_text().replace(
            'preset = "novak2018"      # detection', 'preset = "mox-tgs2620"  # detection'
        )
    )
    assert 'preset = "mox-tgs2620"' in good.read_text()
    res = run_cli(["scenario", "check", str(good)])
    assert res.returncode == 0, res.stderr
    bad = tmp_path / "bad.toml"
    bad.write_text(
        good.read_text().replace("period_ticks = 12", "period_ticks = 12\nnoise_rel = -1.0")
    )
    res = run_cli(["scenario", "check", str(bad)])
    assert res.returncode != 0
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert "sensor.noise_rel" in lines[0] and "-1.0" in lines[0]
    assert "Traceback" not in res.stderr


@pytest.mark.parametrize("kind", ["missing", "directory", "binary"])
def test_cli_check_bad_files_one_line(tmp_path: Path, kind: str) -> None:
    target = tmp_path / "x.toml"
    if kind == "directory":
        target.mkdir()
    elif kind == "binary":
        target.write_bytes(b"\xff\xfe\x00garbage")
    res = run_cli(["scenario", "check", str(target)])
    assert res.returncode != 0
    assert len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert "Traceback" not in res.stderr


def test_sensor_snippets_in_the_docs_are_valid_scenarios() -> None:
    docs = (Path(__file__).resolve().parents[2] / "docs" / "agents.md").read_text()
    blocks = [b.split("```")[0] for b in docs.split("```toml\n")[1:]]
    snippets = [b for b in blocks if "[sensor]" in b]
    assert len(snippets) >= 2
    for text in snippets:
        parse_scenario(text + GOOD_VEHICLE, "docs/agents.md")


def _with_old_geofence_key(value: float) -> str:
    text = DEFAULT_SCENARIO.read_text()
    assert "\ngeofence_max_altitude_m = 120.0\n" in text
    return text.replace("\ngeofence_max_altitude_m = 120.0\n", f"\ngeofence_max_alt_m = {value}\n")


def test_a_renamed_key_still_loads_to_the_same_value_with_one_deprecation_line(
    caplog: pytest.LogCaptureFixture,
) -> None:
    text = _with_old_geofence_key(77.0)
    new = parse_scenario(text.replace("geofence_max_alt_m", "geofence_max_altitude_m"), "new")
    assert not caplog.records
    old = parse_scenario(text, "old.toml")
    assert old.failsafe.geofence_max_altitude_m == 77.0
    assert old == new
    lines = [r.getMessage() for r in caplog.records]
    assert lines == [
        "old.toml: failsafe.geofence_max_alt_m is deprecated, read as "
        "failsafe.geofence_max_altitude_m (the old name goes in the next release)"
    ]


def test_a_renamed_key_in_every_vehicle_is_one_line(caplog: pytest.LogCaptureFixture) -> None:
    vehicles = "".join(
        f'[[vehicles]]\nid = "v{i}"\nspawn_enu_m = [{i}.0, 0.0, 0.0]\n'
        f"failsafe = {{ geofence_max_alt_m = {10 + i}.0 }}\n"
        for i in range(3)
    )
    scenario = parse_scenario(vehicles, "fleet.toml")
    assert [scenario.failsafe_for(f"v{i}").geofence_max_altitude_m for i in range(3)] == [
        10.0,
        11.0,
        12.0,
    ]
    assert len(caplog.records) == 1
    assert "vehicles.failsafe.geofence_max_alt_m" in caplog.records[0].getMessage()
    assert "vehicles.failsafe.geofence_max_altitude_m" in caplog.records[0].getMessage()


def test_a_renamed_key_in_a_set_override_is_read_under_its_new_name(
    caplog: pytest.LogCaptureFixture,
) -> None:
    scenario = load_scenario(DEFAULT_SCENARIO, ["failsafe.geofence_max_alt_m=33"])
    assert scenario.failsafe.geofence_max_altitude_m == 33.0
    assert len(caplog.records) == 1
    message = caplog.records[0].getMessage()
    assert "--set failsafe.geofence_max_alt_m" in message
    assert "--set failsafe.geofence_max_altitude_m" in message


def test_both_the_old_and_the_new_name_is_an_error() -> None:
    text = _with_old_geofence_key(77.0).replace(
        "geofence_max_alt_m = 77.0", "geofence_max_alt_m = 77.0\ngeofence_max_altitude_m = 70.0"
    )
    with pytest.raises(ScenarioError) as err:
        parse_scenario(text, "both.toml")
    assert err.value.field == "failsafe.geofence_max_alt_m"
    assert "geofence_max_altitude_m" in err.value.reason


def test_cli_check_prints_the_deprecation_line_and_passes(tmp_path: Path) -> None:
    old = tmp_path / "old.toml"
    old.write_text(_with_old_geofence_key(90.0))
    res = run_cli(["scenario", "check", str(old)])
    assert res.returncode == 0, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert "failsafe.geofence_max_alt_m is deprecated" in lines[0]
    assert "failsafe.geofence_max_altitude_m" in lines[0]
