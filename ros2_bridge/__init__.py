"""ros2_bridge — the run as ROS 2 topics over the same Zenoh (rmw_zenoh's wire format)."""
