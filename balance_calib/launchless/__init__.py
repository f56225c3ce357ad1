"""Process-level orchestration of the nodes without ros2 launch (launchless_scripts/)."""
