"""The real plume service process answers batch, info and mesh queries over Zenoh."""

from __future__ import annotations

import numpy as np
import pytest
import zenoh

from plume_service import GaussianPlume
from swarmbus.codec import decode, encode
from swarmbus.messages import (
    ErrorReply,
    PlumeInfo,
    PlumeInfoQuery,
    PlumeMesh,
    PlumeMeshQuery,
    PlumeQuery,
    PlumeValues,
)
from swarmbus.reqrep import request
from swarmbus.session import Presence, open_session
from tests.support.procs import Network, NodeProcs, keys_for, run_cli, wait_for_queryable


def _raw_get(session: zenoh.Session, key: str, payload: bytes) -> zenoh.Reply:
    """The wire as it is, not through reqrep: for the requests that must get an ErrorReply."""
    replies = list(session.get(key, payload=payload, timeout=10.0))
    assert len(replies) == 1, f"expected one reply from {key}, got {len(replies)}"
    return replies[0]


@pytest.fixture(scope="module")
def plume_service() -> object:
    from tests.support.procs import zenoh_network

    with zenoh_network() as (net, _router), NodeProcs(net) as procs:
        procs.start("plume", name="plume")
        with open_session(net.client) as session:
            presence = Presence(session, keys_for())
            assert presence.wait_for(lambda a: "plume" in a, 30.0), "plume service never came up"
            presence.close()
            wait_for_queryable(
                session, keys_for().plume_info(), PlumeInfoQuery(), PlumeInfo, 30.0, "plume/info"
            )
            yield net, session


def test_batch_of_1000_points_in_one_reply(plume_service: tuple[Network, zenoh.Session]) -> None:
    _, session = plume_service
    rng = np.random.default_rng(7)
    points = np.column_stack(
        [rng.uniform(-20, 120, 1000), rng.uniform(-30, 30, 1000), rng.uniform(0, 30, 1000)]
    )
    query = PlumeQuery(points_enu_m=[tuple(p) for p in points.tolist()], sim_time_s=3.0)
    values = request(session, keys_for().plume_concentration(), query, PlumeValues, 10.0)
    expected = GaussianPlume.preset("novak2018").concentration(points)
    assert len(values.values_g_m3) == 1000
    np.testing.assert_allclose(values.values_g_m3, expected, rtol=1e-12, atol=0)
    assert values.sim_time_s == 3.0
    assert sum(v > 0 for v in values.values_g_m3) > 100  # the batch really crosses the plume


def test_malformed_query_gets_an_error_and_service_keeps_serving(
    plume_service: tuple[Network, zenoh.Session],
) -> None:
    _, session = plume_service
    key = keys_for().plume_concentration()
    bad = encode(PlumeInfoQuery())  # right encoding, wrong message for this key
    err = _raw_get(session, key, bad).err
    assert err is not None
    error = decode(err.payload.to_bytes(), ErrorReply)
    assert error.field == "schema"
    garbage = _raw_get(session, key, b"\xc1\xff\x00").err
    assert garbage is not None
    assert decode(garbage.payload.to_bytes(), ErrorReply).reason
    # still serving
    query = PlumeQuery(points_enu_m=[(20.0, 0.0, 10.0)])
    (value,) = request(session, key, query, PlumeValues, 10.0).values_g_m3
    assert value == pytest.approx(
        float(GaussianPlume.preset("novak2018").concentration([[20.0, 0.0, 10.0]])[0]), rel=1e-12
    )


def test_info_describes_the_scenario_plume(plume_service: tuple[Network, zenoh.Session]) -> None:
    _, session = plume_service
    info = request(session, keys_for().plume_info(), PlumeInfoQuery(), PlumeInfo, 10.0)
    assert (info.stability, info.coefficients, info.wind_speed_m_s) == ("D", "novak2018", 6.0)
    (src,) = info.sources
    assert (src.release_rate_g_s, src.release_height_m) == (10.0, 10.0)


def test_mesh_over_the_bus(plume_service: tuple[Network, zenoh.Session]) -> None:
    _, session = plume_service
    query = PlumeMeshQuery(level_g_m3=0.05, resolution_m=0.5)
    mesh = request(session, keys_for().plume_mesh(), query, PlumeMesh, 60.0)
    vertices = np.frombuffer(mesh.vertices_f32, dtype="<f4").reshape(-1, 3)
    faces = np.frombuffer(mesh.faces_i32, dtype="<i4").reshape(-1, 3)
    assert len(faces) > 100
    assert faces.max() < len(vertices)
    # vertices lie on the requested level (within the grid's interpolation error)
    values = GaussianPlume.preset("novak2018").concentration(vertices.astype(np.float64))
    assert np.median(np.abs(values - 0.05)) < 0.01


def test_cli_sample_matches_the_model() -> None:
    res = run_cli(["plume", "sample", "--preset", "novak2018", "--format", "json", "30", "-2", "9"])
    assert res.returncode == 0, res.stderr
    import json

    (row,) = json.loads(res.stdout)
    assert row["concentration_g_m3"] == pytest.approx(
        float(GaussianPlume.preset("novak2018").concentration([[30.0, -2.0, 9.0]])[0]), rel=1e-12
    )


@pytest.mark.parametrize(
    "args",
    [
        ["plume", "sample", "1", "2"],
        ["plume", "sample", "--preset", "nope", "1", "2", "3"],
        ["plume", "sample", "--scenario", "/no/such.toml", "1", "2", "3"],
        ["plume", "mesh", "--level", "0.05", "--out", "x.ply"],
        ["plume", "mesh", "--level", "-1", "--out", "x.stl"],
    ],
)
def test_cli_bad_input_is_one_line(args: list[str]) -> None:
    res = run_cli(args)
    assert res.returncode != 0
    assert "Traceback" not in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1, res.stderr
