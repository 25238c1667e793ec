"""A process that joins the bus, announces ``node/<name>``, prints READY and waits to be killed."""

from __future__ import annotations

import sys
import time

from swarmbus.keys import Keys
from swarmbus.session import NetworkConfig, announce, open_session


def main() -> None:
    endpoint, name = sys.argv[1], sys.argv[2]
    net = NetworkConfig(connect=[endpoint], listen=["tcp/127.0.0.1:0"])
    with open_session(net) as session:
        token = announce(session, Keys("default"), name)
        print("READY", flush=True)
        time.sleep(120)
        token.undeclare()


if __name__ == "__main__":
    main()
