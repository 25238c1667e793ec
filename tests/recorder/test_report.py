"""``plumeswarm report``: every PNG drawn (not blank), documented CSV columns, one-line errors."""

from __future__ import annotations

import csv
from pathlib import Path

import msgspec
import numpy as np
import pytest
import zenoh
from matplotlib.image import imread

from recorder.report import READING_COLUMNS, TRACK_COLUMNS
from swarmbus.session import Presence
from tests.support.procs import Network, NodeProcs, keys_for, run_cli
from tests.support.recording import recorded_run, start_recorder
from tests.support.scripted_publisher import PPM_PER_G_M3, RESISTANCE_OHM

PNGS = ("top_view.png", "altitude.png", "concentration.png", "reported_vs_model.png")
DOCS = Path(__file__).resolve().parents[2] / "docs" / "recording.md"


@pytest.fixture(scope="module")
def short_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from tests.support.procs import zenoh_network

    tmp = tmp_path_factory.mktemp("report")
    out = tmp / "flight.mcap"
    with zenoh_network() as (net, _):
        recorded_run(
            net, tmp, out, "--vehicles", "uav1,uav2,uav3", "--steps", "120", "--every", "4"
        )
    return out


def documented_columns(kind: str) -> list[str]:
    """The columns docs/recording.md lists for ``<vehicle>_<kind>.csv`` (a table per file)."""
    lines = DOCS.read_text().splitlines()
    heading = f"### `<vehicle>_{kind}.csv`"
    start = lines.index(heading)
    columns = []
    for line in lines[start + 1 :]:
        if line.startswith("#"):
            break
        if line.startswith("| `"):
            columns.append(line.split("`")[1])
    return columns


def test_report_draws_every_png_and_documented_csvs(short_recording: Path, tmp_path: Path) -> None:
    out = tmp_path / "report"
    result = run_cli(["report", str(short_recording), "--out", str(out)])
    assert result.returncode == 0, result.stderr[-2000:]
    for name in PNGS:
        pixels = imread(out / name)
        assert np.var(pixels[..., :3]) > 1e-3, f"{name} is blank"
    assert documented_columns("track") == list(TRACK_COLUMNS)
    assert documented_columns("readings") == list(READING_COLUMNS)
    for vid in ("uav1", "uav2", "uav3"):
        with open(out / f"{vid}_track.csv") as f:
            rows = list(csv.reader(f))
        assert rows[0] == list(TRACK_COLUMNS) and len(rows) == 1 + 120
        with open(out / f"{vid}_readings.csv") as f:
            rows = list(csv.reader(f))
        assert rows[0] == list(READING_COLUMNS) and len(rows) == 1 + 30
        column = {name: i for i, name in enumerate(rows[0])}
        for row in rows[1:]:
            ppm, ohm = row[column["reported_ppm"]], row[column["resistance_ohm"]]
            if vid == "uav1":  # the scripted publisher's first vehicle reports both
                reported = float(row[column["reported_g_m3"]])
                assert float(ppm) == pytest.approx(reported * PPM_PER_G_M3, rel=1e-12)
                assert float(ohm) == RESISTANCE_OHM
            else:
                assert ppm == "" and ohm == ""
    md = (out / "report.md").read_text()
    for name in PNGS:
        assert f"]({name})" in md
    assert "| uav1 | 30 | 0 |" in md
    assert md.count("data:image/png;base64") == 0
    assert (out / "report.html").read_text().count("data:image/png;base64") == len(PNGS)


@pytest.mark.parametrize(
    ("content", "message"),
    [(None, "no such file"), (b"\x00" * 64, "not an MCAP file")],
)
def test_report_bad_file_is_one_line(tmp_path: Path, content: bytes | None, message: str) -> None:
    path = tmp_path / "bad.mcap"
    if content is not None:
        path.write_bytes(content)
    result = run_cli(["report", str(path), "--out", str(tmp_path / "r")])
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert result.stderr.strip().splitlines()[-1] == f"plumeswarm: error: {path}: {message}"


def test_report_of_a_recording_without_vehicles_is_one_line(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> None:
    net, session = network
    out = tmp_path / "empty.mcap"
    presence = Presence(session, keys_for())
    with NodeProcs(net, log_dir=tmp_path) as procs:
        start_recorder(procs, out)
        assert presence.wait_for(lambda alive: "recorder" in alive, 30.0), "recorder not up"
        procs.stop_all()
    presence.close()
    result = run_cli(["report", str(out), "--out", str(tmp_path / "r")])
    assert result.returncode == 2
    assert "no vehicle states or readings" in result.stderr.strip().splitlines()[-1]


@pytest.mark.parametrize("lid_m", [None, 40.0])
def test_map_field_is_the_plume_services_gaussian(lid_m: float | None) -> None:
    """The report draws the plume the service serves: two sources, a lid or none, with points
    far downwind where σz outgrows the lid (the service sums its images in Fourier form; the
    report's bounded image sum is then within 1e-5 of the map's maximum)."""
    from plume_atmosphere.dispersion import dispersion_curves
    from plume_service import GaussianPlume, PlumeField
    from recorder.plume_map import SteadyPlume

    sources = [(0.0, 0.0, 10.0, 10.0), (30.0, -20.0, 5.0, 2.0)]
    rng = np.random.default_rng(7)
    points = np.column_stack(
        [rng.uniform(-50, 3000, 3000), rng.uniform(-300, 300, 3000), rng.uniform(0, 39, 3000)]
    )
    for family, stability in [("mcmullen", "A"), ("mcmullen", "D"), ("briggs-urban", "B")]:
        service = PlumeField(
            [
                GaussianPlume(q, 4.0, h, stability, family, (x, y), 250.0, lid_m)
                for x, y, q, h in sources
            ]
        )
        report = SteadyPlume(dispersion_curves(family, stability), 4.0, 250.0, lid_m, sources)
        expected = service.concentration(points)
        atol = 1e-5 * float(expected.max())
        assert np.allclose(report.concentration(points), expected, rtol=1e-9, atol=atol)


def test_map_only_for_a_steady_plume() -> None:
    """A Gaussian plume (from plume/info, else from the scenario) has a map; a filament plume's
    value changes with time and has none; without either there is none."""
    from recorder.flight_log import FlightLog
    from recorder.plume_map import SteadyPlume, plume_field
    from swarmbus.messages import PlumeInfo
    from swarmbus.scenario import load_scenario, resolve_scenario_path
    from tests.support.messages_samples import SAMPLES

    info = SAMPLES[PlumeInfo]
    assert isinstance(info, PlumeInfo) and info.model == "gaussian"
    steady = load_scenario(resolve_scenario_path("novak2018"))
    filament = load_scenario(resolve_scenario_path("filament"))
    assert isinstance(plume_field(FlightLog("w", plume_info=info)), SteadyPlume)
    assert isinstance(plume_field(FlightLog("w", scenario=steady)), SteadyPlume)
    assert plume_field(FlightLog("w", scenario=filament)) is None
    moving = PlumeInfo(**{**msgspec.structs.asdict(info), "model": "filament"})
    assert plume_field(FlightLog("w", plume_info=moving, scenario=steady)) is None
    assert plume_field(FlightLog("w")) is None
