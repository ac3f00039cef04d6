"""The live node's machinery in plain Python (no rclpy): tick loop, pacing, commands, the
callback gate, health monitor and the node's parameter table. Tested without ROS."""
