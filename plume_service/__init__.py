"""plume_service — the concentration field model and the process that serves it on the bus."""
