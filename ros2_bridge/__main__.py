"""``python -m ros2_bridge [--scenario F] [--connect EP] [--set KEY=VALUE]``: the ``ros2`` role
alone (as ``plumeswarm node ros2``)."""

from __future__ import annotations

import argparse
import logging
import sys

from ros2_bridge.bridge import main
from swarmbus.keys import process_node
from swarmbus.node import NodeContext
from swarmbus.options import OptionError, split_settings
from swarmbus.scenario import ScenarioError, load_scenario, resolve_scenario_path


def cli(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ros2_bridge", description=__doc__)
    parser.add_argument("--scenario", default=None, help="scenario file or bundled name")
    parser.add_argument("--connect", action="append", default=[], help="router endpoint")
    parser.add_argument("--listen", action="append", default=[], help="endpoint to listen on")
    parser.add_argument("--set", dest="options", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        sc = load_scenario(resolve_scenario_path(args.scenario))
        opts = split_settings(args.options)
    except (ScenarioError, OptionError, OSError) as exc:
        sys.stderr.write(f"error: {exc}\n")
        return 2
    net = sc.network.with_overrides(connect=args.connect or None, listen=args.listen or None)
    return main(NodeContext(sc, net, process_node("ros2", ()), (), opts))


if __name__ == "__main__":
    sys.exit(cli())
