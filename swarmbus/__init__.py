"""swarmbus — the one shared contract of plumeswarm: keys, messages, codec, sessions, scenarios.

Process packages (sim_world, agents, plume_service, gcs_bridge, recorder) meet only here and on
the bus; deploy composes them.
"""

from swarmbus.codec import MessageError, decode, encode
from swarmbus.keys import Keys

__all__ = ["Keys", "MessageError", "decode", "encode"]
