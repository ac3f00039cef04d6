"""Running a scene without ROS: the simulator (control ticks, sampling, stiffness check,
divergence guard) and the trajectory with its measures. Imports ``scene`` and ``core``."""
