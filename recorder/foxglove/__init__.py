"""Foxglove's view of a run: bus messages as Foxglove's well-known messages (foxglove SDK), in a
recording (:mod:`recorder.node`), a converted recording (``plumeswarm export foxglove``) and
live over the Foxglove WebSocket protocol (the ``foxglove`` role)."""
