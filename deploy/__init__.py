"""deploy — the ``plumeswarm`` CLI, the launcher, scenarios and multi-host configuration."""
