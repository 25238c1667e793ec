"""deploy — composition: the launcher and supervisor, scenarios, multi-host configuration and
security, the ``plumeswarm`` CLI (:mod:`plumeswarm.cli`) and the tools it calls (demo, status,
benches), the fused runner and the environments."""
