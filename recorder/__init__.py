"""The recorder: recording the bus to MCAP, replaying a recording, reporting on a flight, and
Foxglove's view of a run. A process package: it meets the others only through ``swarmbus``.

- :mod:`recorder.node`: the ``recorder`` role (every message under the world's prefix
  to one chunked, indexed MCAP file; nothing dropped silently).
- :mod:`recorder.reader`: reading a recording back, also one cut short by SIGKILL.
- :mod:`recorder.replay`: publishing a recording back onto the bus with its timing.
- :mod:`recorder.report`: plots, CSV and a one-page report from a recording.
- :mod:`recorder.foxglove`: a run as Foxglove messages, in a recording, converted from one
  (``plumeswarm export foxglove``) and live (the ``foxglove`` role).

The file format is documented in ``docs/recording.md``.
"""
