"""ROS 2 interface of vjm_ros: the simulator node and the example controllers. The only package
that imports rclpy.

The logic the node relies on is plain Python in :mod:`vjm_ros.realtime` (tick loop, pacing,
commands, gate, monitor, parameters), tested without ROS; :mod:`~vjm_ros.ros.conversions` turns
arrays into messages (message types only, rclpy is not started). The measurements of a live
node are developer benchmarks, outside the package (``benchmarks/`` in a checkout).
"""
