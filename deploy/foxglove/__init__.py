"""Foxglove's view of a run: bus messages as Foxglove's well-known messages (foxglove SDK), in a
recording (:mod:`deploy.recording`), a converted recording (``plumeswarm export foxglove``) and
live over the Foxglove WebSocket protocol (the ``foxglove`` role)."""
