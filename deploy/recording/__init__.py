"""Recording the bus to MCAP, replaying a recording, and reporting on a flight.

- :mod:`deploy.recording.recorder`: the ``recorder`` role (every message under the world's prefix
  to one chunked, indexed MCAP file; nothing dropped silently).
- :mod:`deploy.recording.reader`: reading a recording back, also one cut short by SIGKILL.
- :mod:`deploy.recording.replay`: publishing a recording back onto the bus with its timing.
- :mod:`deploy.recording.report`: plots, CSV and a one-page report from a recording.

The file format is documented in ``docs/recording.md``.
"""
