"""ROS 2 interface of vjm_ros: the simulator node, the example controller and the probe node the
measurements use (:mod:`~vjm_ros.ros.probes`). The only package that imports rclpy.

The logic the node relies on is plain Python in :mod:`vjm_ros.realtime` (tick loop, pacing,
commands, gate, monitor, parameters), tested without ROS; :mod:`~vjm_ros.ros.conversions` turns
arrays into messages (message types only, rclpy is not started). The latency and flood
measurements of a live node live in :mod:`vjm_ros.studies`.
"""
