"""``plumeswarm``'s public face changes only on purpose: the names of ``plumeswarm.__all__``,
each of which resolves, loads on first use and has its entry in the API reference."""

from __future__ import annotations

import json
import re

import plumeswarm
from tests.support.procs import REPO, run_python

# The public surface, written out with where each object is defined (its ``__module__``):
# adding, removing or renaming a name, or pointing one at another object, fails here first.
DEFINED_IN = {
    "Behavior": "agents.behavior",
    "BehaviorContext": "agents.behavior",
    "BusDriver": "plumeswarm.experiments.driver",
    "ClockError": "agents.swarm_clients",
    "CommandRejected": "agents.swarm_clients",
    "CommandTimeout": "agents.swarm_clients",
    "Driver": "plumeswarm.experiments.driver",
    "FilamentPlume": "plume_service.filament",
    "FusedRunner": "plumeswarm.experiments.fused",
    "GaussianPlume": "plume_service.gaussian",
    "InProcessDriver": "plumeswarm.experiments.driver",
    "PlumeError": "agents.swarm_clients",
    "PlumeswarmError": "swarmbus.errors",
    "PuffPlume": "plume_service.puff",
    "RadioReadError": "agents.swarm_radio",
    "RadioSent": "agents.swarm_radio",
    "RadioUnavailable": "agents.swarm_radio",
    "Recording": "recorder.reader",
    "Scenario": "swarmbus.scenario_spec",
    "ScenarioError": "swarmbus.scenario",
    "SeekingBehavior": "agents.behaviors.seeking",
    "Swarm": "agents.swarm",
    "SwarmError": "agents.swarm_clients",
    "VehicleCommander": "agents.swarm_clients",
    "WaitTimeout": "agents.swarm_clients",
    "load_scenario": "swarmbus.scenario",
}
PUBLIC = sorted([*DEFINED_IN, "__version__"])


def test_all_is_the_locked_list() -> None:
    assert list(plumeswarm.__all__) == PUBLIC
    assert sorted(dir(plumeswarm)) == sorted(PUBLIC)


def test_every_public_name_resolves_to_the_object_it_names() -> None:
    assert isinstance(plumeswarm.__version__, str) and plumeswarm.__version__
    for name in PUBLIC:
        if name == "__version__":
            continue
        value = getattr(plumeswarm, name)
        assert value.__name__ == name, name
        assert value.__module__ == DEFINED_IN[name], (name, value.__module__)


def test_an_unknown_name_is_an_attribute_error() -> None:
    try:
        plumeswarm.Swarmm  # noqa: B018
    except AttributeError as err:
        assert "Swarmm" in str(err)
    else:
        raise AssertionError("plumeswarm.Swarmm resolved")


def test_import_plumeswarm_loads_no_public_object_until_it_is_used() -> None:
    """A fresh interpreter: ``import plumeswarm`` imports none of the packages below it; the
    first use of a name imports its module."""
    code = (
        "import json, sys\n"
        "import plumeswarm\n"
        "ours = ('agents', 'plume_service', 'recorder', 'swarmbus', 'sim_world', 'deploy',\n"
        "        'plumeswarm.experiments', 'plumeswarm.envs')\n"
        "before = sorted(m for m in sys.modules if m.split('.')[0] in ours\n"
        "                or any(m.startswith(p) for p in ours))\n"
        "plumeswarm.GaussianPlume\n"
        "print(json.dumps([before, 'plume_service.gaussian' in sys.modules]))\n"
    )
    res = run_python(code, 120.0)
    assert res.returncode == 0, res.stderr
    before, loaded = json.loads(res.stdout.strip().splitlines()[-1])
    assert before == [] and loaded is True


def test_the_api_reference_documents_every_public_object() -> None:
    text = (REPO / "docs" / "api.md").read_text()
    documented = set(re.findall(r"^::: plumeswarm\.(\w+)$", text, re.MULTILINE))
    assert documented == set(PUBLIC) - {"__version__"}
