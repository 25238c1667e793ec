"""agents — one autopilot process per vehicle, and the ``Swarm`` client for swarm algorithms."""
