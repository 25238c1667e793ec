"""The one role-option parser (swarmbus.options): values, ranges, errors, unknown options, and a
real role process refusing a bad option with one line."""

from __future__ import annotations

import enum
import os
import subprocess
import sys
from typing import Annotated, Literal, Self

import msgspec
import pytest

from swarmbus.node import NodeContext
from swarmbus.options import OptionError, RoleOptions, parse_options, role_options, split_settings
from swarmbus.scenario import Scenario, load_scenario
from tests.support.procs import REPO


class Mode(enum.StrEnum):
    FAST = "fast"
    SLOW = "slow"


class Sample(RoleOptions, frozen=True, kw_only=True):
    tick_hz: Annotated[float, msgspec.Meta(gt=0.0, le=100.0)] = 10.0
    port: Annotated[int, msgspec.Meta(ge=0, le=65535)] = 0
    enabled: bool = True
    mode: Mode = Mode.FAST
    links: Literal["all", "none"] = "all"
    levels: tuple[Annotated[float, msgspec.Meta(gt=0.0)], ...] = ()
    rate: dict[str, Annotated[float, msgspec.Meta(ge=0.0, le=1000.0)]] = msgspec.field(
        default_factory=dict
    )
    max_ticks: Annotated[int, msgspec.Meta(ge=0)] | None = None
    out: str = ""


def test_defaults_and_good_values() -> None:
    assert parse_options(Sample, []) == Sample()
    opts = parse_options(
        Sample,
        [
            "tick_hz=2.5",
            "port=18570",
            "enabled=off",
            "mode=slow",
            "links=none",
            "levels=0.01, 0.05",
            "rate.ATTITUDE=10",
            "rate.GPS=0",
            "max_ticks=7",
            "out=a=b.mcap",
        ],
    )
    assert opts == Sample(
        tick_hz=2.5,
        port=18570,
        enabled=False,
        mode=Mode.SLOW,
        links="none",
        levels=(0.01, 0.05),
        rate={"ATTITUDE": 10.0, "GPS": 0.0},
        max_ticks=7,
        out="a=b.mcap",
    )
    for word, value in (("yes", True), ("ON", True), ("1", True), ("no", False), ("0", False)):
        assert parse_options(Sample, {"enabled": word}).enabled is value
    assert parse_options(Sample, {"max_ticks": ""}).max_ticks is None


def test_defaults_given_by_the_role_are_kept_unless_set() -> None:
    base = Sample(tick_hz=50.0, rate={"HEARTBEAT": 1.0})
    opts = parse_options(Sample, {"rate.GPS": "2", "port": "1"}, defaults=base)
    assert opts == Sample(tick_hz=50.0, port=1, rate={"HEARTBEAT": 1.0, "GPS": 2.0})


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ("tick_hz=abc", "--set tick_hz=abc: expected a number in (0, 100]"),
        ("tick_hz=0", "--set tick_hz=0: expected a number in (0, 100]"),
        ("tick_hz=100.5", "--set tick_hz=100.5: expected a number in (0, 100]"),
        ("tick_hz=nan", "--set tick_hz=nan: expected a number in (0, 100]"),
        ("tick_hz=inf", "--set tick_hz=inf: expected a number in (0, 100]"),
        ("port=65536", "--set port=65536: expected an integer in [0, 65535]"),
        ("port=1.5", "--set port=1.5: expected an integer in [0, 65535]"),
        ("enabled=maybe", "--set enabled=maybe: expected true or false"),
        ("mode=medium", "--set mode=medium: expected one of fast, slow"),
        ("links=some", "--set links=some: expected one of all, none"),
        (
            "levels=0.1,-1",
            "--set levels=0.1,-1: expected comma-separated values, each a number > 0",
        ),
        ("rate.GPS=-1", "--set rate.GPS=-1: expected a number in [0, 1000]"),
        ("max_ticks=-2", "--set max_ticks=-2: expected an integer >= 0"),
    ],
)
def test_each_bad_value_is_named(item: str, message: str) -> None:
    with pytest.raises(OptionError) as info:
        parse_options(Sample, [item])
    assert str(info.value) == message


KNOWN = "enabled, levels, links, max_ticks, mode, out, port, rate.<KEY>, tick_hz"


@pytest.mark.parametrize(
    ("item", "meant"),
    [
        ("tick=5", "tick_hz"),
        ("rate=5", "rate.<KEY>"),
        ("rate.=5", "rate.<KEY>"),
        ("port.x=1", "port"),
    ],
)
def test_unknown_options_are_refused_naming_the_nearest_and_the_known_ones(
    item: str, meant: str
) -> None:
    with pytest.raises(OptionError) as info:
        parse_options(Sample, [item])
    hint = f" (did you mean {meant!r}?)"
    assert str(info.value) == f"--set {item}: unknown option{hint}; known: {KNOWN}"


def test_an_unknown_option_far_from_every_known_one_gets_no_guess() -> None:
    with pytest.raises(OptionError) as info:
        parse_options(Sample, ["zzzz=1"])
    assert str(info.value) == f"--set zzzz=1: unknown option; known: {KNOWN}"


def test_malformed_settings() -> None:
    with pytest.raises(OptionError, match="--set expects KEY=VALUE, got 'tick_hz'"):
        split_settings(["tick_hz"])
    with pytest.raises(OptionError, match="expects KEY=VALUE, got '=3'"):
        split_settings(["=3"])
    assert split_settings(["a=1", "a=2"]) == {"a": "2"}


def test_a_role_without_options_refuses_any() -> None:
    class Nothing(RoleOptions, frozen=True, kw_only=True):
        pass

    with pytest.raises(OptionError, match=r"--set x=1: unknown option; known: none$"):
        parse_options(Nothing, {"x": "1"})


@pytest.mark.parametrize(
    ("role", "extra", "item", "named"),
    [
        ("physics", [], "clock_period_s=abc", "--set clock_period_s=abc: expected a number"),
        ("plume", [], "tick_hz=5", "--set tick_hz=5: unknown option; known: none"),
        ("autopilot", ["--vehicle", "uav1"], "status_period_s=-1", "--set status_period_s=-1"),
        ("gateway", [], "rate.NOPE=1", "--set rate.NOPE=1: unknown MAVLink message 'NOPE'"),
    ],
)
def test_a_role_process_refuses_a_bad_option_in_one_line(
    role: str, extra: list[str], item: str, named: str
) -> None:
    """The real CLI and role entry point: exit status 2 and one line naming the option, before
    the process joins any bus (so no network is needed and nothing is left running)."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run(
        [sys.executable, "-m", "plumeswarm", "node", role, *extra, "--set", item],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
        cwd=REPO,
    )
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    # pybullet prints its build time on import; every other line is the process's own
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip() and "pybullet build" not in ln]
    assert len(lines) == 1, proc.stderr
    assert named in lines[0], lines[0]
    assert "Traceback" not in proc.stderr + proc.stdout


class FromScenario(RoleOptions, frozen=True, kw_only=True):
    speed_factor: Annotated[float, msgspec.Meta(gt=0.0)] = 1.0
    port: int = 0

    @classmethod
    def defaults(cls, scenario: Scenario) -> Self:
        return cls(speed_factor=scenario.time.speed_factor)


def test_role_options_are_the_settings_over_the_scenarios_defaults() -> None:
    base = load_scenario()
    sc = msgspec.structs.replace(base, time=msgspec.structs.replace(base.time, speed_factor=3.0))

    def ctx(options: dict[str, str]) -> NodeContext:
        return NodeContext(sc, sc.network, "x", (), options)

    assert role_options(FromScenario, ctx({})) == FromScenario(speed_factor=3.0)
    assert role_options(FromScenario, ctx({"port": "7"})) == FromScenario(speed_factor=3.0, port=7)
    assert role_options(FromScenario, ctx({"speed_factor": "5"})).speed_factor == 5.0
    assert role_options(Sample, ctx({"port": "7"})) == Sample(port=7)  # no override: declared
    with pytest.raises(OptionError, match="speed_factor"):
        role_options(FromScenario, ctx({"speed_factor": "0"}))
