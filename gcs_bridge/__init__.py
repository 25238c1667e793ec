"""gcs_bridge — the MAVLink v2 gateway to QGroundControl, MAVSDK and MAVProxy."""
