"""ROS 2 interface of vjm_ros: the simulator node and an example controller.

Only :mod:`vjm_ros.ros.node`, :mod:`vjm_ros.ros.runtime`, :mod:`vjm_ros.ros.controller` and
:mod:`vjm_ros.ros.latency` import rclpy. The logic they rely on is plain Python, testable without ROS:

* :mod:`~vjm_ros.ros.commands`: effort command validation, hold, timeout and lockstep hand-over;
* :mod:`~vjm_ros.ros.pacing`: the realtime deadline loop and its late/missed tick counts;
* :mod:`~vjm_ros.ros.monitor`: the figures published on ``/diagnostics``;
* :mod:`~vjm_ros.ros.settings`: the node's parameters, their ranges and validation;
* :mod:`~vjm_ros.ros.loop`: the tick loop (commands, stepping, outputs, pause/step/reset);
* :mod:`~vjm_ros.ros.conversions`: message <-> array conversions (message types, no rclpy).
"""
